"""emu.author / `emu mesh`: surfaces -> one labelled conforming tet mesh -> a
scene that runs. Small generated surfaces (emu.shapes); labels are checked
against the shapes' own analytic inside tests, not the mesher's markers."""
import os

import meshio
import numpy as np
import pytest

import emu
from emu.build.author import AuthoringError, author, read_parts, surface_defects, surface_volume, winding_numbers
from emu.build.shapes import capsule, spindle

import pytetwild  # noqa: F401  (a dependency: a missing mesher fails here, never skips)

HUMERUS = dict(p0=[0, 0, 0], p1=[0, 0, 4], r=0.35)
FOREARM = dict(p0=[0, 0, 4.5], p1=[0, 0, 8.5], r=0.3)
BICEPS = dict(p0=[0.45, 0, 0.8], p1=[0.3, 0, 5.2], r=0.55)


def _cap(p0, p1, r):
    """Coarse surfaces for the meshing cases: fTetWild's time follows the input triangles."""
    return capsule(p0, p1, r, rings=12, segments=16)


def _spin(p0, p1, r):
    return spindle(p0, p1, r, rings=12, segments=16)


def _write(folder, name, surface):
    V, F = surface
    meshio.write_points_cells(os.path.join(folder, f"{name}.obj"), V, [("triangle", F)])


def _parts_file(folder, body: str, surfaces: dict) -> str:
    for name, s in surfaces.items():
        _write(folder, name, s)
    path = os.path.join(folder, "parts.toml")
    with open(path, "w") as f:
        f.write(body)
    return path


def _in_capsule(x, p0, p1, r):
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    a = p1 - p0
    L = np.linalg.norm(a)
    # the capsule's ends are its poles: the segment runs r inside each
    s = np.clip(((x - p0) @ a) / L, r, L - r)
    return np.linalg.norm(x - (p0 + np.outer(s / L, a)), axis=1) < r


ARM = '''
[mesh]
tets = 2500
[[part]]
name = "humerus"
surface = "humerus.obj"
kind = "bone"
[[part]]
name = "forearm"
surface = "forearm.obj"
kind = "bone"
fixed = false
[[part]]
name = "biceps"
surface = "biceps.obj"
kind = "muscle"
[[joint]]
bones = ["humerus", "forearm"]
centre = [0.0, 0.0, 4.25]
axis = [0.0, 1.0, 0.0]
'''


SMALL = ARM.replace("tets = 2500", "tets = 800")   # the cases that test one rule each


@pytest.fixture(scope="module")
def arm_parts(tmp_path_factory):
    folder = str(tmp_path_factory.mktemp("arm_parts"))
    surfaces = {"humerus": _cap(HUMERUS["p0"], HUMERUS["p1"], HUMERUS["r"]),
                "forearm": _cap(FOREARM["p0"], FOREARM["p1"], FOREARM["r"]),
                "biceps": _spin(BICEPS["p0"], BICEPS["p1"], BICEPS["r"])}
    return _parts_file(folder, ARM, surfaces)


@pytest.fixture(scope="module")
def arm(arm_parts):
    return author(arm_parts)


def test_shapes_are_closed_outward_surfaces():
    for V, F in (capsule([0, 0, 0], [0, 0, 3], 0.5), spindle([0, 0, 0], [1, 2, 3], 0.7)):
        assert surface_defects(F) == {"open_edges": 0, "nonmanifold_edges": 0}
        assert surface_volume(V, F) > 0
    V, F = capsule([0, 0, 0], [0, 0, 3], 0.5, rings=48, segments=64)
    exact = np.pi * 0.5 ** 2 * 2.0 + 4 / 3 * np.pi * 0.5 ** 3
    assert surface_volume(V, F) == pytest.approx(exact, rel=0.01)


def test_winding_numbers_inside_outside_and_with_holes():
    V, F = spindle([0, 0, 0], [0, 0, 4], 1.0)
    q = np.array([[0, 0, 2.0], [0.3, 0.2, 1.5], [3, 0, 2.0], [0, 0, -1.0]])
    w = winding_numbers(V, F, q)
    np.testing.assert_allclose(w, [1, 1, 0, 0], atol=1e-6)
    holed = F[np.arange(len(F)) % 37 != 0]   # small holes
    assert surface_defects(holed)["open_edges"] > 0
    w = winding_numbers(V, holed, q)
    assert w[0] > 0.8 and w[1] > 0.8 and w[2] < 0.2 and w[3] < 0.2


def test_arm_labels_attachments_fibres(arm):
    s = arm.scene
    x = s.points[s.tets].mean(axis=1)
    part = np.asarray(arm.part_names)[arm.part]
    in_hum = _in_capsule(x, HUMERUS["p0"], HUMERUS["p1"], HUMERUS["r"])
    in_fore = _in_capsule(x, FOREARM["p0"], FOREARM["p1"], FOREARM["r"])
    # overlap goes to the bone: a tet clearly inside a bone is that bone's
    assert np.mean(part[in_hum] == "humerus") > 0.95
    assert np.mean(part[in_fore] == "forearm") > 0.95
    assert np.mean(part[~in_hum & ~in_fore] == "biceps") > 0.95
    # attachments: the muscle shares vertices with both bones
    atts = s.attachments("biceps")
    assert set(atts) == {"humerus", "forearm"} and all(len(v) >= 3 for v in atts.values())
    assert {(a["part"], a["bone"]) for a in arm.report["attachments"]} == {("biceps", "humerus"),
                                                                          ("biceps", "forearm")}
    f = arm.fiber[part == "biceps"]
    np.testing.assert_allclose(np.linalg.norm(f, axis=1), 1.0, atol=1e-9)
    assert np.all(arm.fiber[part != "biceps"] == 0)
    assert 1000 < len(s.tets) < 7500   # about the 2500 asked for
    assert arm.joints[0]["how"] == "declared" and arm.report["free_bones"] == []


def test_fibres_run_from_one_attachment_to_the_other(tmp_path):
    # a belly between two coaxial bones: the Laplace field runs along the axis
    body = SMALL.split("[[joint]]")[0].replace("fixed = false\n", "")
    path = _parts_file(str(tmp_path), body, {"humerus": _cap([0, 0, 0], [0, 0, 4], 0.35),
                                             "forearm": _cap([0, 0, 8], [0, 0, 12], 0.35),
                                             "biceps": _spin([0, 0, 3.4], [0, 0, 8.6], 0.7)})
    a = author(path)
    s = a.scene
    m = np.asarray(a.part_names)[a.part] == "biceps"
    z = s.points[s.tets[m]].mean(axis=1)[:, 2]
    middle = (z > 4.6) & (z < 7.4)   # clear of the bones' caps
    assert middle.sum() > 50
    assert np.median(a.fiber[m][middle, 2]) > 0.95 and np.all(a.fiber[m][middle, 2] > 0.5)
    assert a.report["fibers"]["biceps"] == "Laplace field from 'humerus' to 'forearm'"


def test_arm_scene_file_runs_and_the_forearm_turns(arm, tmp_path):
    from emu.app.scenefile import load_scene_file
    from emu.build.author import write_authored

    paths = write_authored(arm, tmp_path / "out", frames=3)
    spec = load_scene_file(paths["scene"])
    assert set(spec.scene.parts) == {"humerus", "forearm", "biceps"}
    assert spec.scene.parts["biceps"].kind == "muscle" and not spec.scene.parts["forearm"].fixed
    np.testing.assert_allclose(spec.scene.parts["biceps"].fibers, arm.fiber[arm.part == 2], atol=1e-6)
    sols = {}
    for method in ("emu", "fem"):
        sols[method] = emu.Solver(spec.scene, method, accuracy=0.01).solve({"biceps": 0.3}, normalized=True)
        assert sols[method].converged
    fore = np.unique(spec.scene.tets[spec.scene.parts["forearm"].tets])
    moved = np.abs(sols["fem"].positions - spec.scene.points)[fore].max()
    assert moved > 1e-3   # the muscle turns the forearm about the elbow
    err = np.abs(sols["emu"].positions - sols["fem"].positions).max() / np.linalg.norm(np.ptp(spec.scene.points, 0))
    assert err < 0.015


def test_cli_mesh_writes_a_scene_emu_info_reads(arm_parts, tmp_path, capsys):
    from emu.app.cli import main

    out = tmp_path / "cli"
    assert main(["mesh", arm_parts, "--out", str(out), "--threads", "1"]) == 0
    text = capsys.readouterr().out
    assert "attachment: biceps on humerus" in text and "hinge humerus - forearm" in text
    for f in ("mesh.vtu", "scene.json", "scene.toml", "report.json", "mesh.png"):
        assert (out / f).exists()
    assert (out / "mesh.png").stat().st_size > 10000 and "mesh.png (the parts, joints and attachments)" in text
    assert main(["info", str(out / "scene.toml")]) == 0
    assert "joint humerus - forearm: hinge" in capsys.readouterr().out


def test_detected_joint_between_near_bones(tmp_path):
    body = SMALL.split("[[joint]]")[0]
    path = _parts_file(str(tmp_path), body, {"humerus": _cap([0, 0, 0], [0, 0, 4], 0.35),
                                             "forearm": _cap([0, 0, 4.25], [0, 0, 8.25], 0.3),
                                             "biceps": _spin(BICEPS["p0"], BICEPS["p1"], BICEPS["r"])})
    a = author(path)
    (j,) = a.joints
    assert j["detected"] and j["axis"] is None and set(j["bones"]) == {"humerus", "forearm"}
    assert abs(j["centre"][2] - 4.125) < 0.3 and abs(j["centre"][0]) < 0.3
    assert any(jj.declared for jj in a.scene.joints())


def test_muscle_attached_to_nothing_is_named(tmp_path):
    body = SMALL.split("[[joint]]")[0] + '''[[part]]
name = "stray"
surface = "stray.obj"
kind = "muscle"
'''
    path = _parts_file(str(tmp_path), body, {"humerus": _cap(HUMERUS["p0"], HUMERUS["p1"], HUMERUS["r"]),
                                             "forearm": _cap([0, 0, 4.3], [0, 0, 8.3], 0.3),
                                             "biceps": _spin(BICEPS["p0"], BICEPS["p1"], BICEPS["r"]),
                                             "stray": _spin([3, 0, 1], [3, 0, 4], 0.5)})
    with pytest.raises(AuthoringError, match="muscle 'stray' is attached to nothing"):
        author(path)


def test_touching_bones_are_refused(tmp_path):
    body = SMALL.split("[[joint]]")[0]
    path = _parts_file(str(tmp_path), body, {"humerus": _cap([0, 0, 0], [0, 0, 4], 0.35),
                                             "forearm": _cap([0, 0, 3.6], [0, 0, 7.6], 0.3),
                                             "biceps": _spin(BICEPS["p0"], BICEPS["p1"], BICEPS["r"])})
    with pytest.raises(AuthoringError, match="bones 'humerus' and 'forearm' touch in the mesh"):
        author(path)


def test_surface_with_holes_still_meshes_and_is_reported(tmp_path):
    V, F = _spin(BICEPS["p0"], BICEPS["p1"], BICEPS["r"])
    holed = (V, F[np.arange(len(F)) % 41 != 5])
    path = _parts_file(str(tmp_path), SMALL, {"humerus": _cap(HUMERUS["p0"], HUMERUS["p1"], HUMERUS["r"]),
                                            "forearm": _cap(FOREARM["p0"], FOREARM["p1"], FOREARM["r"]),
                                            "biceps": holed})
    a = author(path)
    assert any("biceps" in d and "not closed" in d for d in a.report["defects"])
    assert np.sum(np.asarray(a.part_names)[a.part] == "biceps") > 100


@pytest.mark.parametrize("body, match", [
    ('[mesh]\ntets = 10\n', "at least 100"),
    ('[[part]]\nname = "a"\nsurface = "a.obj"\nkind = "nerve"\n', "kind must be muscle, tendon or bone"),
    ('[[part]]\nname = "a"\nsurface = "a.obj"\nkind = "muscle"\n', "no part is a bone"),
    ('[[part]]\nname = "a"\nsurface = "a.obj"\nkind = "muscle"\ncolour = 1\n', "unknown key 'colour'"),
    ('[[part]]\nname = "a"\nsurface = "a.obj"\nkind = "muscle"\nfixed = false\n', "'fixed' applies to bones"),
    ('[[part]]\nname = "a"\nsurface = "a.obj"\nkind = "muscle"\n[[part]]\nname = "b"\nsurface = "a.obj"\n'
     'kind = "bone"\n[[joint]]\nbones = ["a", "b"]\ncentre = [0, 0, 0]\n', "bones must name two different bones"),
])
def test_parts_file_errors_name_the_key(tmp_path, body, match):
    _write(str(tmp_path), "a", _spin([0, 0, 0], [0, 0, 1], 0.2))
    p = tmp_path / "parts.toml"
    p.write_text(body + ('' if "[[part]]" in body else '[[part]]\nname = "a"\nsurface = "a.obj"\nkind = "muscle"\n'))
    with pytest.raises(AuthoringError, match=match):
        read_parts(p)


def test_example_pipeline_surfaces_to_picture(tmp_path):
    """examples/authoring: the committed surfaces -> emu mesh -> emu run (3
    frames, its preview picture); the forearm flexes (the elbow's angle grows)."""
    import json

    from emu.app.cli import main

    here = os.path.join(os.path.dirname(__file__), "..", "examples", "authoring")
    out, run = tmp_path / "elbow", tmp_path / "elbow_run"
    assert main(["mesh", os.path.join(here, "parts.toml"), "--out", str(out)]) == 0
    text = (out / "scene.toml").read_text().replace("count = 20", "count = 3").replace("0.3]]", "1.0]]")
    (out / "scene.toml").write_text(text)
    assert main(["run", str(out / "scene.toml"), "--out", str(run)]) == 0
    angles = [f["bone_angles_deg"]["forearm"] for f in json.loads((run / "log.json").read_text())["frames"]]
    assert abs(angles[0]) < 1e-3 and angles[2] > angles[1] > 0.1
    assert os.path.getsize(run / "preview.png") > 10_000


def test_overlapping_muscles_are_reported(tmp_path):
    body = SMALL + '''[[part]]
name = "brachialis"
surface = "brachialis.obj"
kind = "muscle"
'''
    path = _parts_file(str(tmp_path), body, {"humerus": _cap(HUMERUS["p0"], HUMERUS["p1"], HUMERUS["r"]),
                                             "forearm": _cap(FOREARM["p0"], FOREARM["p1"], FOREARM["r"]),
                                             "biceps": _spin(BICEPS["p0"], BICEPS["p1"], BICEPS["r"]),
                                             "brachialis": _spin([0.55, 0, 1.5], [0.35, 0, 5.0], 0.45)})
    a = author(path)
    assert any("'biceps' and 'brachialis' overlap" in d for d in a.report["defects"]), a.report["defects"]


def test_self_intersections_found_and_reported(tmp_path):
    from emu.build.author import self_intersections

    for V, F in (capsule([0, 0, 0], [0, 0, 3], 0.5), spindle([0, 0, 0], [1, 2, 3], 0.7)):
        assert len(self_intersections(V, F)) == 0
    # two overlapping spheres given as one surface: their triangles cross along a circle
    V1, F1 = spindle([0, 0, 0], [0, 0, 2], 1.0)
    V2, F2 = spindle([0, 0, 1], [0, 0, 3], 1.0)
    V, F = np.vstack([V1, V2]), np.vstack([F1, F2 + len(V1)])
    pairs = self_intersections(V, F)
    assert len(pairs) > 10
    assert np.all((pairs[:, 0] < len(F1)) != (pairs[:, 1] < len(F1)))   # each pair: one from each sphere
    # a bone surface folded through itself is meshed and reported
    path = _parts_file(str(tmp_path), SMALL, {"humerus": (V * [0.35, 0.35, 1.0], F),
                                              "forearm": _cap(FOREARM["p0"], FOREARM["p1"], FOREARM["r"]),
                                              "biceps": _spin(BICEPS["p0"], BICEPS["p1"], BICEPS["r"])})
    a = author(path)
    assert any("'humerus': its surface intersects itself" in d for d in a.report["defects"]), a.report["defects"]
