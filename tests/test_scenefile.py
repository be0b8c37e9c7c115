"""Scene files (emu.load_scene_file, code in emu.app.scenefile): the schema, the
typed loader and its errors. Running a scene file: test_run.py; the `emu`
command: test_cli.py."""
import json

import numpy as np
import pytest

import emu
from emu import SceneFileError, load_scene_file

from conftest import bone_muscle_bone, gap_scene, shared_path, shared_raw

GOOD = """
pins = ["proximal"]

[mesh.fusiform]
tets = 800

[materials.belly]
youngs = 5e4

[solver]
method = "emu"
alpha = 100.0

[frames]
count = 3
dt = 0.5

[activation.belly]
keys = [[0.0, 0.0], [1.0, 0.4]]
normalized = true
"""


def write(tmp_path, text, name="scene.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_scene_file_loads(tmp_path):
    spec = load_scene_file(write(tmp_path, GOOD))
    assert spec.frames == 3 and spec.dt == 0.5
    assert spec.scene.parts["belly"].youngs == 5e4
    assert len(spec.scene.pinned) > 0
    assert spec.activation(0)["belly"] == 0.0
    assert spec.activation(1)["belly"] == pytest.approx(0.2 * spec.scene.parts["belly"].max_activation)
    js = tmp_path / "scene.json"
    import tomllib
    js.write_text(json.dumps(tomllib.loads(GOOD)))
    assert load_scene_file(js).frames == 3


def test_scene_file_solver_options_reach_the_solver(tmp_path):
    """The [solver] options added with the stress suite and accuracy mode's
    corrections are accepted and passed on to emu.Solver."""
    text = GOOD.replace('alpha = 100.0', 'accuracy = 0.01\nfem_correction = false\neigen_filter = "abs"\n'
                        'recycled_directions = 2')
    spec = load_scene_file(write(tmp_path, text))
    solver = emu.Solver(spec.scene, **spec.solver)
    assert solver.settings["fem_correction"] is False and solver.settings["eigen_filter"] == "abs"
    # an option of the other method is an error naming it
    with pytest.raises(ValueError, match="fem_correction is an option of EMU only; leave it out for method='fem'"):
        emu.Solver(spec.scene, **{**spec.solver, "method": "fem"})
    fem_text = GOOD.replace('method = "emu"\nalpha = 100.0', 'method = "fem"\nnegative_curvature = false')
    fem_spec = load_scene_file(write(tmp_path, fem_text, "fem.toml"))
    assert emu.Solver(fem_spec.scene, **fem_spec.solver).method == "fem"
    with pytest.raises(SceneFileError, match="solver.fem_correction"):
        load_scene_file(write(tmp_path, GOOD.replace('alpha = 100.0', 'fem_correction = "yes"'), "bad.toml"))
    # the stopping and CG options of later stops too
    text = GOOD.replace('alpha = 100.0', 'alpha = 100.0\nnoise_factor = 0\nposition_tol = 1e-6\n'
                        'cg_model_decrease = 0.25')
    solver = emu.Solver(load_scene_file(write(tmp_path, text, "late.toml")).scene,
                        **load_scene_file(write(tmp_path, text, "late.toml")).solver)
    assert (solver.settings["noise_factor"], solver.settings["position_tol"]) == (0.0, 1e-6)


def test_fusiform_mesh_is_the_built_in_scene(tmp_path):
    """[mesh.fusiform] is emu.scenes.fusiform: same mesh, parts and fibres, and
    the pins named in the file are its vertex sets."""
    spec = load_scene_file(write(tmp_path, GOOD))
    ref = emu.scenes.fusiform(tets=800)
    np.testing.assert_array_equal(spec.scene.points, ref.points)
    np.testing.assert_array_equal(spec.scene.tets, ref.tets)
    assert list(spec.scene.parts) == ["belly", "tendons"]
    np.testing.assert_array_equal(spec.scene.parts["belly"].fibers, ref.parts["belly"].fibers)
    np.testing.assert_array_equal(spec.scene.pinned, np.sort(ref.vertex_sets["proximal"]))
    both = load_scene_file(write(tmp_path, GOOD.replace('pins = ["proximal"]', 'pins = ["proximal", "distal"]')))
    assert len(both.scene.pinned) == len(ref.vertex_sets["proximal"]) + len(ref.vertex_sets["distal"])


@pytest.mark.parametrize("edit,exc,match", [
    (lambda s: s.replace("[frames]", "[frames]\nspeed = 2"), SceneFileError, r"unknown key 'frames.speed'"),
    (lambda s: s.replace("count = 3", 'count = "three"'), SceneFileError, r"'frames.count' must be int"),
    (lambda s: s.replace("alpha = 100.0", "alpha = [1]"), SceneFileError, r"'solver.alpha' must be float"),
    (lambda s: s.replace("[mesh.fusiform]\ntets = 800", '[mesh]\npath = "nope.vtu"'), FileNotFoundError,
     "nope.vtu"),
    (lambda s: s.replace("[activation.belly]", "[activation.biceps]"), SceneFileError, "no muscle named 'biceps'"),
    (lambda s: s.replace('pins = ["proximal"]', 'pins = ["elbow"]'), SceneFileError, "unknown pin set 'elbow'"),
    (lambda s: s.replace("[materials.belly]", "[materials.bone]"), SceneFileError, "no part named 'bone'"),
    (lambda s: s.replace("youngs = 5e4", "stiffness = 5e4"), SceneFileError, "unknown key 'materials.belly.stiffness'"),
    (lambda s: s.replace("[mesh.fusiform]\ntets = 800", ""), SceneFileError, r"missing \[mesh\]"),
    (lambda s: s.replace("keys = [[0.0, 0.0], [1.0, 0.4]]", "keys = [[0.0, 3.0]]"), SceneFileError,
     r"activation.belly: .*\[0, 1\]"),
    (lambda s: s + "\n[output]\nvtu = 1\n", SceneFileError, "'output.vtu' must be bool"),
    (lambda s: s.replace("[frames]", "[frames\n"), SceneFileError, "not valid TOML"),
    (lambda s: s.replace("[mesh.fusiform]\ntets = 800", '[mesh]\ndataset = "big_biceps"'), SceneFileError,
     "unknown research scene 'big_biceps' .*simple_joint"),
    (lambda s: s.replace("[mesh.fusiform]\ntets = 800", '[mesh]\ndataset = "simple_joint"\npath = "a.vtu"'),
     SceneFileError, "exactly one of"),
    (lambda s: s.replace("[mesh.fusiform]\ntets = 800", '[mesh]\nfibers = "laplace"\n[mesh.fusiform]\ntets = 800'),
     SceneFileError, "mesh.fibers applies to mesh.path or mesh.dataset only"),
])
def test_scene_file_errors(tmp_path, edit, exc, match):
    with pytest.raises(exc, match=match):
        load_scene_file(write(tmp_path, edit(GOOD)))


def test_scene_file_names_a_research_scene(tmp_path):
    """mesh.dataset loads the authors' scene through emu.datasets (here from the
    shared offline copy, see conftest): the same scene as the converted file."""
    shared_raw()
    text = GOOD.replace("[mesh.fusiform]\ntets = 800", '[mesh]\ndataset = "simple_joint"').replace(
        'pins = ["proximal"]', "").replace("[materials.belly]\nyoungs = 5e4", "").replace(
        "[activation.belly]", "[activation.muscle]")
    spec = load_scene_file(write(tmp_path, text))
    ref = emu.io.load_scene(shared_path("simple_joint"), warn=False)
    np.testing.assert_array_equal(spec.scene.points, ref.points)
    np.testing.assert_array_equal(spec.scene.tets, ref.tets)
    assert list(spec.scene.parts) == list(ref.parts)
    np.testing.assert_array_equal(spec.scene.parts["muscle"].fibers, ref.parts["muscle"].fibers)


def test_missing_scene_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="scene file not found"):
        load_scene_file(tmp_path / "absent.toml")


ARM = "[mesh.arm]\nresolution = 1\n[frames]\ncount = 2\n[activation.flexor]\nkeys = [[0.0, 0.0], [1.0, 0.3]]\n"


def test_scene_file_movable_bones(tmp_path):
    p = tmp_path / "arm.toml"
    p.write_text(ARM)
    spec = load_scene_file(p)
    assert spec.scene.movable_bones == ["forearm"]
    p.write_text(ARM + "[bones.forearm]\nfixed = true\n")
    assert load_scene_file(p).scene.movable_bones == []
    p.write_text(ARM + "[bones.forearm]\nacap_weight = 50.0\n")
    assert load_scene_file(p).scene.parts["forearm"].acap_weight == 50.0
    for extra, match in [
        ("[bones.forearm]\nangle = [[0.0, 10.0]]\naxis = [0, 0, 1]\ncentre = [0, 0, 0]\n", "cannot be scripted"),
        ("[bones.forearm]\nacap_weight = -1.0\n", "acap_weight must be positive"),
        ("[bones.forearm]\nfixed = 1\n", "'bones.forearm.fixed' must be bool"),
        ("[bones.humerus]\nangle = [[0.0, 10.0]]\n", "missing 'axis'"),
        ("[bones.humerus]\nangle = [[0.0, 10.0]]\naxis = [0, 0, 1]\n", "missing 'centre'"),
        ("[bones.ulna]\nfixed = false\n", "no bone named 'ulna'"),
    ]:
        p.write_text(ARM + extra)
        with pytest.raises(SceneFileError, match=match):
            load_scene_file(p)
    p.write_text(ARM.replace("resolution = 1", "resolution = 0"))
    with pytest.raises(SceneFileError, match="resolution must be >= 1"):
        load_scene_file(p)
    p.write_text(ARM.replace("[mesh.arm]", "[mesh.neck]").replace("flexor", "left_back"))
    assert load_scene_file(p).scene.movable_bones == ["head"]


def test_scripted_bone_keys(tmp_path):
    """A scripted bone: axis, centre and angle keyframes give its pose per frame."""
    p = tmp_path / "arm.toml"
    p.write_text(ARM + "[bones.humerus]\naxis = [0, 0, 1]\ncentre = [1.0, 2.0, 0.0]\n"
                       "angle = [[0.0, 0.0], [1.0, 30.0]]\n")
    spec = load_scene_file(p)
    R, t = spec.bone_poses(1)["humerus"]
    ref_R, ref_t = emu.pose_about([0, 0, 1], 30.0, [1.0, 2.0, 0.0])
    np.testing.assert_allclose(R, ref_R, atol=1e-15)
    np.testing.assert_allclose(t, ref_t, atol=1e-15)
    np.testing.assert_allclose(R @ [1.0, 2.0, 0.0] + t, [1.0, 2.0, 0.0], atol=1e-15)  # the centre stays


@pytest.mark.parametrize("table,rest", [
    ("[bones.humerus]", "axis = [0, 0, 1]\ncenter = [0, 0, 0]\nangle = [[0.0, 10.0]]\n"),
    ("[joints.elbow]", 'bones = ["forearm", "humerus"]\ncenter = [0, 0, 0]\n'),
])
def test_center_is_spelled_centre(tmp_path, table, rest):
    """One spelling: a scene file with `center` is told to write `centre`."""
    p = tmp_path / "arm.toml"
    p.write_text(ARM + table + "\n" + rest)
    where = table.strip("[]")
    with pytest.raises(SceneFileError, match=rf"'{where}.center': spell it 'centre'"):
        load_scene_file(p)


def test_scene_file_declared_joint(tmp_path):
    s = gap_scene()
    mesh = tmp_path / "gap.vtu"
    part = np.zeros(len(s.tets), np.int32)
    for i, name in enumerate(("upper", "lower", "muscle")):
        part[s.parts[name].tets] = i
    emu.io.write(mesh, s.points, s.tets, cell_data={"part": part})
    (tmp_path / "scene.json").write_text(
        '{"parts": [{"id": 0, "name": "upper", "kind": "bone"}, {"id": 1, "name": "lower", "kind": "bone"}, '
        '{"id": 2, "name": "muscle", "kind": "muscle"}]}')
    base = ('[mesh]\npath = "gap.vtu"\nfibers = "laplace"\n[bones.lower]\nfixed = false\n'
            '[joints.elbow]\nbones = ["lower", "upper"]\ncentre = [1.5, 1.5, 0.5]\n')
    p = tmp_path / "s.toml"
    p.write_text(base + "axis = [0, 0, 1]\n")
    spec = load_scene_file(p)
    (j,) = spec.scene.joints()
    assert isinstance(j, emu.Joint)
    assert j.kind == "hinge" and j.declared and j.bones == ("lower", "upper")
    np.testing.assert_allclose(j.centre, [1.5, 1.5, 0.5])
    p.write_text(base)
    assert load_scene_file(p).scene.joints()[0].kind == "ball"
    for text, match in [(base.replace('"upper"]', '"ulna"]'), "no bone named 'ulna'"),
                        (base + "axis = [0, 1]\n", "axis must be three numbers"),
                        (base.replace('centre = [1.5, 1.5, 0.5]\n', ''), "missing 'centre'"),
                        (base + "angle = 3.0\n", "unknown key 'joints.elbow.angle'")]:
        p.write_text(text)
        with pytest.raises(SceneFileError, match=match):
            load_scene_file(p)


def test_scripted_bone_must_be_a_bone(tmp_path):
    s, m, _ = bone_muscle_bone(0.15)
    part = np.zeros(len(m.tets), np.int32)
    for i, name in enumerate(["belly", "proximal", "distal"]):
        part[s.parts[name].tets] = i
    emu.io.write(tmp_path / "arm.vtu", m.points, m.tets, cell_data={"part": part})
    (tmp_path / "scene.json").write_text(json.dumps({"parts": [
        {"id": 0, "name": "belly", "kind": "muscle"}, {"id": 1, "name": "proximal", "kind": "bone"},
        {"id": 2, "name": "distal", "kind": "bone"}]}))
    p = write(tmp_path, '[mesh]\npath = "arm.vtu"\nfibers = "laplace"\n[bones.belly]\naxis = [1.0, 0.0, 0.0]\n'
                        'centre = [0.0, 0.0, 9.0]\nangle = [[0.0, 0.0], [1.0, 20.0]]\n')
    with pytest.raises(SceneFileError, match="no bone named 'belly'"):
        load_scene_file(p)
