"""emu.arm26 and the arm26 dataset: the VTP reader, arm26's elbow and muscle
paths read from its model file, the pose, the muscles' attachments, and the
whole path (fetched by hash from tests/data/opensim-models, meshed, solved:
EMU against strict FEM on the example scene)."""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import emu
from emu.build import arm26, datasets
from emu.build.author import read_parts, read_surface, surface_defects, surface_volume, winding_numbers
from emu.io.vtk import read_polydata
from conftest import OPENSIM_FILES

FILES = {rel: str(OPENSIM_FILES / rel) for rel in list(arm26.SURFACE_FILES.values()) + [arm26.MODEL_FILE]}
EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "arm26_flex_extend.toml"


# ----------------------------------------------------------------------------- the VTP reader

def test_read_polydata_reads_opensim_geometry():
    V, F = read_polydata(FILES["Geometry/arm_r_ulna.vtp"])
    # the file's header: NumberOfPoints="211" NumberOfPolys="398" (all triangles); its first point
    assert V.shape == (211, 3) and F.shape == (398, 3)
    np.testing.assert_array_equal(V[0], [-0.009357, -0.010036, 0.007856])
    assert F.min() == 0 and F.max() == 210
    V2, F2 = read_surface(FILES["Geometry/arm_r_ulna.vtp"])       # emu mesh takes .vtp surfaces
    np.testing.assert_array_equal(V2, V)
    np.testing.assert_array_equal(F2, F)


def _vtp(path, points, conn, offsets, fmt="ascii"):
    pts = " ".join(str(v) for v in np.ravel(points))
    Path(path).write_text(
        '<?xml version="1.0"?><VTKFile type="PolyData" version="0.1"><PolyData>'
        f'<Piece NumberOfPoints="{len(points)}" NumberOfPolys="{len(offsets)}"><Points>'
        f'<DataArray type="Float32" NumberOfComponents="3" format="{fmt}">{pts}</DataArray></Points><Polys>'
        f'<DataArray type="Int32" Name="connectivity" format="ascii">{" ".join(map(str, conn))}</DataArray>'
        f'<DataArray type="Int32" Name="offsets" format="ascii">{" ".join(map(str, offsets))}</DataArray>'
        '</Polys></Piece></PolyData></VTKFile>')


def test_read_polydata_splits_polygons_and_names_bad_files(tmp_path):
    square = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]]
    p = tmp_path / "s.vtp"
    _vtp(p, square, [0, 1, 2, 3, 1, 4, 2], [4, 7])          # a quad, then a triangle
    V, F = read_polydata(p)
    np.testing.assert_array_equal(F, [[0, 1, 2], [0, 2, 3], [1, 4, 2]])
    _vtp(p, square, [0, 1, 2, 3], [4], fmt="binary")
    with pytest.raises(ValueError, match="only ascii is read"):
        read_polydata(p)
    _vtp(p, square, [0, 1, 9], [3])
    with pytest.raises(ValueError, match="out of range"):
        read_polydata(p)
    _vtp(p, square, [0, 1, 2, 3], [2, 4])
    with pytest.raises(ValueError, match="3 or more corners"):
        read_polydata(p)
    p.write_text("<VTKFile type='UnstructuredGrid'><UnstructuredGrid/></VTKFile>")
    with pytest.raises(ValueError, match="not a VTK PolyData file"):
        read_polydata(p)


# ----------------------------------------------------------------------------- the model file

def test_elbow_and_muscle_paths_as_arm26_writes_them():
    centre, axis = arm26.elbow_joint(FILES[arm26.MODEL_FILE])
    # arm26.osim: r_humerus_offset translation and r_elbow's rotation1 axis, as written there
    np.testing.assert_array_equal(centre, [0.0061000000000000004, -0.29039999999999999, -0.0123])
    a = np.array([0.049400010000000001, 0.036600010000000002, 0.99810825000000003])
    np.testing.assert_allclose(axis, a / np.linalg.norm(a), rtol=1e-15)
    bic = arm26.path_points(FILES[arm26.MODEL_FILE], "BIClong")
    assert list(bic) == [f"BIClong-P{k}" for k in range(1, 10)]
    body, loc = bic["BIClong-P9"]
    assert body == "r_ulna_radius_hand"
    np.testing.assert_array_equal(loc, [0.0075100000000000002, -0.048390000000000002, 0.02179])
    assert arm26.path_points(FILES[arm26.MODEL_FILE], "TRIlong")["TRIlong-P2"][0] == "r_humerus"
    with pytest.raises(ValueError, match="no muscle 'NOPE'"):
        arm26.path_points(FILES[arm26.MODEL_FILE], "NOPE")


def test_forearm_is_turned_90_degrees_about_arm26s_elbow():
    s = arm26.surfaces(FILES)
    centre, axis = arm26.elbow_joint(FILES[arm26.MODEL_FILE])
    R = Rotation.from_rotvec(axis * np.pi / 2)               # independent of emu's Rodrigues formula
    for name in ("ulna", "radius"):
        raw, _ = read_polydata(FILES[arm26.SURFACE_FILES[name]])
        np.testing.assert_allclose(s[name][0], R.apply(raw) + centre, atol=1e-15)
    np.testing.assert_array_equal(s["humerus"][0], read_polydata(FILES[arm26.SURFACE_FILES["humerus"]])[0])
    # flexed: the hand end of the forearm points forward (+x), level with the elbow
    ulna = s["ulna"][0]
    assert ulna[:, 0].max() > 0.2 and abs(ulna[np.argmax(ulna[:, 0]), 1] - centre[1]) < 0.05


def test_each_muscle_reaches_into_both_bones():
    s = arm26.surfaces(FILES)
    forearm = arm26._joined(s["ulna"], s["radius"])
    for m in arm26.MUSCLES:
        V, F = s[m]
        assert surface_defects(F) == {"open_edges": 0, "nonmanifold_edges": 0}
        assert surface_volume(V, F) > 0                                     # closed, facing outward
        in_humerus = winding_numbers(*s["humerus"], V) > 0.5
        in_forearm = winding_numbers(*forearm, V) > 0.5
        assert in_humerus.any() and in_forearm.any(), m


# ----------------------------------------------------------------------------- the dataset

def _opensim_copy(tmp_path, corrupt=None):
    copy = tmp_path / "opensim"
    shutil.copytree(OPENSIM_FILES, copy)
    if corrupt:
        p = copy / corrupt
        data = bytearray(p.read_bytes())
        data[-1] ^= 0x01
        p.write_bytes(bytes(data))
    return copy


def test_arm26_files_are_checked_by_hash(tmp_path, monkeypatch):
    monkeypatch.setenv("EMU_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("EMU_OPENSIM_DIR", str(_opensim_copy(tmp_path, "Geometry/arm_r_radius.vtp")))
    with pytest.raises(datasets.HashMismatchError, match="arm_r_radius.vtp.*opensim-org/opensim-models"):
        datasets.path("arm26")
    monkeypatch.setenv("EMU_OPENSIM_DIR", str(tmp_path))
    with pytest.raises(datasets.DownloadError, match="EMU_OPENSIM_DIR=.* has no Geometry/arm_r_humerus.vtp"):
        datasets.path("arm26")
    assert not (tmp_path / "cache" / "arm26" / "mesh.vtu").exists()


def test_arm26_downloads_through_a_base_url(tmp_path, monkeypatch):
    pytest.importorskip("pooch")
    monkeypatch.delenv("EMU_OPENSIM_DIR")
    monkeypatch.setenv("EMU_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("EMU_OPENSIM_URL", _opensim_copy(tmp_path, "Models/Arm26/arm26.osim").as_uri())
    with pytest.raises(datasets.HashMismatchError, match="arm26.osim"):
        datasets.path("arm26")
    monkeypatch.setenv("EMU_OPENSIM_URL", (tmp_path / "nowhere").as_uri())
    with pytest.raises(datasets.DownloadError, match="EMU_OPENSIM_DIR"):
        datasets.path("arm26")


@pytest.fixture(scope="module")
def built():
    """datasets.path("arm26") in the session's cache (meshed once, about 40 s)."""
    msgs = []
    vtu = datasets.path("arm26", progress=msgs.append)
    return Path(vtu), msgs


def test_arm26_builds_with_credit_attachments_and_one_elbow(built):
    vtu, _ = built
    d = vtu.parent
    credits = (d / "CREDITS.txt").read_text()
    assert "CC BY 3.0" in credits and "Holzbaur" in credits and "OpenSim Development Team" in credits
    report = json.loads((d / "report.json").read_text())
    on = {(a["part"], a["bone"]) for a in report["attachments"]}
    assert on == {("biceps_tendon", "humerus"), ("biceps_tendon", "forearm"),
                  ("triceps", "humerus"), ("triceps", "forearm")}
    [joint] = report["joints"]
    assert joint["bones"] == ["humerus", "forearm"] and not joint["detected"]
    assert any("not closed" in x for x in report["defects"])     # real shells: reported, meshed anyway
    # the surfaces and a parts file that remeshes them
    spec = read_parts(d / "surfaces" / "parts.toml")
    assert [p.name for p in spec.parts] == ["humerus", "forearm", "biceps", "triceps"]
    assert os.path.isfile(spec.parts[1].surface)
    # a second use builds nothing
    msgs = []
    assert datasets.path("arm26", progress=msgs.append) == str(vtu) and msgs == []


def test_arm26_example_flexes_and_emu_agrees_with_strict_fem(built):
    from emu.app.scenefile import load_scene_file

    spec = load_scene_file(EXAMPLE)
    k = spec.frames // 2                    # the biceps at its peak, 0.5 of its maximum
    act = spec.activation(k)
    ours = emu.Solver(spec.scene, **spec.solver)
    strict = emu.Solver(spec.scene, "fem", rtol_grad=1e-9)
    e, f = ours.solve(act), strict.solve(act)
    assert f.converged and e.converged and e.accuracy_reached
    assert emu.vertex_error(e, f) < 0.01
    flex = emu.bones.bone_angle(spec.scene, f.positions, "forearm")
    assert flex > 10.0, flex                 # the biceps flexes the elbow (about 27 degrees)
    assert abs(emu.bones.bone_angle(spec.scene, e.positions, "forearm") - flex) < 1.0


def test_emu_data_arm26_says_where_and_whose(built):
    vtu, _ = built
    lines = []
    assert datasets.fetch_main(["arm26"], progress=lines.append) == 0
    assert lines[-1] == f"arm26: {vtu}"
    assert any("opensim-org/opensim-models at 20a888b9655e" in s and "CC BY 3.0" in s for s in lines)


def test_source_files_are_the_opensim_files_checked(monkeypatch):
    # datasets.source_files: arm26's OpenSim files from EMU_OPENSIM_DIR, each
    # path under it (hash-checked as a build reads them); a scene that is not
    # built from sources is named
    monkeypatch.setenv("EMU_OPENSIM_DIR", str(OPENSIM_FILES))
    files = datasets.source_files("arm26")
    assert set(FILES) <= set(files)
    for rel, local in files.items():
        assert Path(local) == OPENSIM_FILES / rel and Path(local).is_file()
    with pytest.raises(ValueError, match="'biceps' is not built from source files.*arm26"):
        datasets.source_files("biceps")
