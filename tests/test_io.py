"""Mesh input/output through emu.io (meshio underneath)."""
import warnings

import numpy as np
import pytest

import emu
from emu.build.procedural import fusiform

from conftest import small_scene


@pytest.fixture
def mesh():
    m = fusiform(2)
    part = np.where(m.is_tendon, 1, 0).astype(np.int32)
    return m, part


@pytest.mark.parametrize("ext", ["vtu", "msh", "mesh"])
def test_round_trip(tmp_path, mesh, ext):
    m, part = mesh
    path = tmp_path / f"fusiform.{ext}"
    emu.io.write(path, m.points, m.tets, cell_data={"part": part})
    back = emu.io.read(path)
    np.testing.assert_allclose(back.points, m.points, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(back.tets, m.tets)
    assert back.part is not None, f"part labels lost in .{ext}: cell data {list(back.cell_data)}"
    np.testing.assert_array_equal(back.part, part)


def test_msh_is_written_as_gmsh(tmp_path, mesh):
    """.msh means gmsh to emu's users (io's docs: gmsh physical groups), not ANSYS."""
    m, part = mesh
    path = tmp_path / "fusiform.msh"
    emu.io.write(path, m.points, m.tets, cell_data={"part": part})
    with open(path, "rb") as f:
        head = f.read(11)
    assert head == b"$MeshFormat", head


def test_vtu_round_trip_keeps_fibers_and_loads_as_scene(tmp_path, mesh):
    m, part = mesh
    path = tmp_path / "fusiform.vtu"
    emu.io.write(path, m.points, m.tets, cell_data={"part": part, "fiber": m.fibers})
    back = emu.io.read(path)
    np.testing.assert_allclose(back.fiber, m.fibers, atol=1e-12)
    scene = emu.io.load_scene(path)  # no scene.json: parts named part<id>, kind muscle
    assert sorted(scene.parts) == ["part0", "part1"]
    np.testing.assert_array_equal(np.sort(scene.parts["part1"].tets), np.flatnonzero(m.is_tendon))
    np.testing.assert_allclose(scene.parts["part0"].fibers, m.fibers[~m.is_tendon], atol=1e-12)


def test_load_scene_needs_part_labels(tmp_path, mesh):
    m, _ = mesh
    path = tmp_path / "nolabels.vtu"
    emu.io.write(path, m.points, m.tets)
    with pytest.raises(ValueError, match="no part labels"):
        emu.io.load_scene(path)


def test_unlabelled_tets_join_the_part_holding_their_vertices(tmp_path, mesh):
    """Tets labelled -1 (as 7 of the authors' realistic_biceps are) join the part
    that holds most of their vertices, taking its neighbours' mean fibre, with a
    warning; one that touches no labelled tet is an error."""
    m, part = mesh
    part = part.copy()
    fib = m.fibers.copy()
    z = m.points[m.tets].mean(axis=1)[:, 2]
    lost = np.flatnonzero((part == 0) & (np.abs(z - 0.5 * m.length) < 0.4))[:6]
    assert len(lost) == 6
    part[lost] = -1
    fib[lost] = 0.0
    path = tmp_path / "holes.vtu"
    emu.io.write(path, m.points, m.tets, cell_data={"part": part, "fiber": fib})
    with pytest.warns(emu.MeshWarning, match="6 tet\\(s\\) had no part label"):
        scene = emu.io.load_scene(path)
    assert sorted(scene.parts) == ["part0", "part1"]
    assert set(lost) <= set(scene.parts["part0"].tets)
    got = scene.parts["part0"].fibers[np.searchsorted(scene.parts["part0"].tets, lost)]
    np.testing.assert_allclose(np.linalg.norm(got, axis=1), 1.0)
    assert np.all(np.einsum("ij,ij->i", got, m.fibers[lost]) > 0.95)   # close to the true meridian fibre
    # everything unlabelled: nothing to join
    emu.io.write(path, m.points, m.tets, cell_data={"part": np.full(len(m.tets), -1, np.int32), "fiber": fib})
    with pytest.raises(ValueError, match="share no vertex with a labelled tet"):
        emu.io.load_scene(path)


def test_realistic_biceps_loads(tmp_path):
    from conftest import shared_path

    with pytest.warns(emu.MeshWarning, match="7 tet\\(s\\) had no part label"):
        scene = emu.io.load_scene(shared_path("realistic_biceps"), free_bones=["forearm"])
    assert sorted(scene.parts) == ["biceps", "forearm", "humerus", "scapula"]
    assert len(scene.parts["biceps"].tets) == 11995 + 7
    assert sorted(j.kind for j in scene.joints()) == ["ball", "hinge"]


def solved_scene():
    s, m = small_scene(2)
    sol = emu.solve(s, {"belly": 5e4}, "fem")
    assert sol.converged
    return s, m, sol


def test_write_solution(tmp_path):
    import meshio

    s, m, sol = solved_scene()
    path = tmp_path / "frame.vtu"
    emu.io.write_solution(path, s, sol)
    out = meshio.read(path)
    np.testing.assert_allclose(out.points, sol.positions, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(out.cells_dict["tetra"], s.tets)
    np.testing.assert_allclose(out.point_data["displacement"], sol.positions - s.points, rtol=0, atol=1e-12)
    cd = {k: np.asarray(v[0]) for k, v in out.cell_data.items()}
    assert {"part", "J", "fiber"} <= set(cd)
    # part: index of the part in scene.parts
    expected_part = np.where(m.is_tendon, list(s.parts).index("tendons"), list(s.parts).index("belly"))
    np.testing.assert_array_equal(cd["part"].ravel(), expected_part)
    # J: volume ratio, computed here from the positions
    def vols(x):
        p = x[s.tets]
        return np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]))
    np.testing.assert_allclose(cd["J"].ravel(), vols(sol.positions) / vols(s.points), rtol=1e-10)
    assert np.ptp(cd["J"]) > 1e-3  # not trivially 1
    # fibre: unit deformed direction F u on muscle tets, zero on tendons
    fib = cd["fiber"].reshape(-1, 3)
    belly = ~m.is_tendon
    np.testing.assert_allclose(np.linalg.norm(fib[belly], axis=1), 1.0, atol=1e-10)
    np.testing.assert_array_equal(fib[m.is_tendon], 0.0)
    p, q = s.points[s.tets], sol.positions[s.tets]
    Dm = np.stack([p[:, k] - p[:, 0] for k in (1, 2, 3)], axis=2)
    Ds = np.stack([q[:, k] - q[:, 0] for k in (1, 2, 3)], axis=2)
    F = Ds @ np.linalg.inv(Dm)
    fu = np.einsum("tij,tj->ti", F[belly], m.fibers[belly])
    np.testing.assert_allclose(fib[belly], fu / np.linalg.norm(fu, axis=1, keepdims=True), atol=1e-10)


def test_write_solution_records_the_activation_it_is_given(tmp_path):
    import meshio

    s, m, sol = solved_scene()
    path = tmp_path / "frame.vtu"
    emu.io.write_solution(path, s, sol, activation={"belly": 5e4})
    act = np.asarray(meshio.read(path).cell_data["activation"][0]).ravel()
    np.testing.assert_allclose(act[~m.is_tendon], 5e4)
    np.testing.assert_allclose(act[m.is_tendon], 0.0)
    per_tet = np.linspace(0.0, 1.0, len(s.tets))
    emu.io.write_solution(path, s, sol.positions, activation=per_tet)
    np.testing.assert_allclose(np.asarray(meshio.read(path).cell_data["activation"][0]).ravel(), per_tet)
    # the writer does not look into the solution for it: without one, no activation field
    emu.io.write_solution(path, s, sol)
    assert "activation" not in meshio.read(path).cell_data
    with pytest.raises(ValueError, match="no muscle named 'tendons'"):
        emu.io.write_solution(path, s, sol, activation={"tendons": 1.0})
    with pytest.raises(ValueError, match=r"one value per tet"):
        emu.io.write_solution(path, s, sol, activation=np.zeros(3))


def test_write_solution_fibres_without_changing_the_scene(tmp_path):
    """A muscle without fibres: the frame shows its Laplace field (as the solver
    used it), and the scene keeps fibers=None."""
    import meshio

    s = emu.scenes.arm(1)
    ref = {n: s.parts[n].fibers.copy() for n in s.muscles}
    for n in s.muscles:
        s.parts[n].fibers = None
    path = tmp_path / "rest.vtu"
    emu.io.write_solution(path, s, s.points)
    fib = np.asarray(meshio.read(path).cell_data["fiber"][0])
    for n in s.muscles:
        np.testing.assert_allclose(fib[s.parts[n].tets], ref[n], atol=1e-8)
        assert s.parts[n].fibers is None


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="not found"):
        emu.io.read(tmp_path / "nope.vtu")
    with pytest.raises(FileNotFoundError):
        emu.io.load_scene(tmp_path / "nope.vtu")


def test_file_without_tets(tmp_path):
    import meshio

    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    tris = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])
    path = tmp_path / "surface.vtu"
    meshio.write_points_cells(path, pts, [("triangle", tris)])
    with pytest.raises(ValueError, match="no tetrahedra"):
        emu.io.read(path)


def test_unreadable_file(tmp_path):
    path = tmp_path / "garbage.vtu"
    path.write_text("this is not a mesh")
    with pytest.raises(ValueError, match="could not read"):
        emu.io.read(path)


def test_boundary_surface_is_closed_and_outward():
    m = emu.procedural.fusiform(3)
    f = emu.io.boundary_faces(m.tets)
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)  # closed, manifold
    p = m.points
    vol = np.einsum("ij,ij->i", p[f[:, 0]], np.cross(p[f[:, 1]], p[f[:, 2]])).sum() / 6.0
    assert vol == pytest.approx(emu.checks.signed_volumes(p, m.tets).sum(), rel=1e-10)  # outward normals


def test_gmsh_physical_names_name_the_parts(tmp_path, mesh):
    """A gmsh mesh with physical groups "belly" and "tendons" (gmsh's own
    format 2.2 as meshio writes it): the parts carry those names."""
    import meshio

    m, part = mesh
    path = tmp_path / "named.msh"
    tag = part + 1   # gmsh tags start at 1
    meshio.write(path, meshio.Mesh(m.points, [("tetra", m.tets)],
                                   cell_data={"gmsh:physical": [tag], "gmsh:geometrical": [tag]},
                                   field_data={"belly": np.array([1, 3]), "tendons": np.array([2, 3]),
                                               "skin": np.array([7, 2])}),
                 file_format="gmsh22")
    back = emu.io.read(path)
    assert back.part_names == {1: "belly", 2: "tendons"}   # the surface group "skin" names no part
    np.testing.assert_array_equal(back.part, tag)


def _three_parts(m):
    """The fusiform's belly (0) and its two tendon caps as parts 1 (proximal)
    and 2 (distal), to be declared bones."""
    z = m.points[m.tets].mean(axis=1)[:, 2]
    return np.where(m.is_tendon, np.where(z < 0.5 * m.length, 1, 2), 0).astype(np.int32)


def test_kinds_and_fibres_per_part(tmp_path, mesh):
    """A mesh from another tool, labelled but with no scene.json: kinds= makes
    the caps bones, fibers= gives the belly a Laplace field between them (the
    fusiform's meridian fibres, which the mesh module makes independently) or a
    direction; a name the mesh does not have is an error listing the parts."""
    m, _ = mesh
    part = _three_parts(m)
    path = tmp_path / "three.vtu"
    emu.io.write(path, m.points, m.tets, cell_data={"part": part})
    kinds = {"part1": "bone", "part2": "bone"}
    scene = emu.io.load_scene(path, kinds=kinds, fibers={"part0": "laplace"})
    assert [p.kind for p in scene.parts.values()] == ["muscle", "bone", "bone"]
    f = scene.parts["part0"].fibers
    cos = np.abs(np.einsum("ij,ij->i", f, m.fibers[part == 0]))
    assert np.median(cos) > 0.95
    scene = emu.io.load_scene(path, kinds=kinds, fibers={"part0": [0, 0, 2.0]})
    np.testing.assert_allclose(scene.parts["part0"].fibers, np.tile([0, 0, 1.0], (np.sum(part == 0), 1)))
    with pytest.raises(ValueError, match="has no part named 'belly'.*parts: part0, part1, part2"):
        emu.io.load_scene(path, kinds={"belly": "bone"})
    with pytest.raises(ValueError, match="needs fibres and the mesh has no 'fiber' cell data.*--fibers part0=laplace"):
        emu.io.load_scene(path, kinds=kinds)   # no fibres in the file, none asked for


def test_scene_file_and_cli_set_kinds_and_fibres(tmp_path, mesh, capsys):
    from emu.app.cli import main
    from emu.app.scenefile import load_scene_file

    m, _ = mesh
    path = tmp_path / "three.vtu"
    emu.io.write(path, m.points, m.tets, cell_data={"part": _three_parts(m)})
    (tmp_path / "scene.toml").write_text('[mesh]\npath = "three.vtu"\n[parts.part1]\nkind = "bone"\n'
                                         '[parts.part2]\nkind = "bone"\n[parts.part0]\nfibers = [0.0, 0.0, 1.0]\n')
    spec = load_scene_file(tmp_path / "scene.toml")
    assert spec.scene.parts["part2"].kind == "bone"
    np.testing.assert_allclose(spec.scene.parts["part0"].fibers[:, 2], 1.0)
    assert main(["info", str(path), "--kind", "part1=bone", "part2=bone", "--fibers", "part0=laplace"]) == 0
    out = capsys.readouterr().out
    assert "part part1: bone" in out and "attachments: part1" in out
    # no muscle, nothing scripted, no gravity: nothing would move; an error naming the fixes
    (tmp_path / "still.toml").write_text('[mesh]\npath = "three.vtu"\n[parts.part1]\nkind = "bone"\n'
                                         '[parts.part2]\nkind = "bone"\n[parts.part0]\nkind = "tendon"\n')
    with pytest.raises(ValueError, match="no muscle, no scripted bone and no gravity: nothing moves it.*kind = "
                                         "\"muscle\".*script a bone.*gravity"):
        load_scene_file(tmp_path / "still.toml")
    assert main(["run", str(tmp_path / "still.toml"), "--out", str(tmp_path / "out")]) != 0
    assert "nothing moves it" in capsys.readouterr().err and not (tmp_path / "out").exists()


def _box(lo, hi, n):
    """A structured tet mesh of the box [lo, hi] (3,), n cells per side, six
    tets per cell: (points, tets)."""
    g = np.stack(np.meshgrid(*[np.linspace(a, b, n + 1) for a, b in zip(lo, hi)], indexing="ij"), -1).reshape(-1, 3)
    vid = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    tets = []
    for i, j, k in np.ndindex(n, n, n):
        c = [vid[i + a, j + b, k + d] for a, b, d in [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0),
                                                      (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]]
        for a, b in [(1, 2), (2, 3), (3, 7), (7, 4), (4, 5), (5, 1)]:
            tets.append([c[0], c[a], c[b], c[6]])
    return g, np.asarray(tets)


@pytest.mark.parametrize("case", ["loose", "conforming", "apart"])
def test_a_muscle_lying_on_a_bone_without_sharing_vertices_is_named(tmp_path, case, capsys):
    """A muscle block meshed with the bone it hangs from (shared vertices) and
    apart from the bone below it (4 cells per side against 3: its vertices lie
    on the bone's top face, none shared but the corners): the loose contact
    is named with its area, the unit face; meshed with both bones, or lifted
    a tenth of an edge off the bone, nothing is named."""
    lift = 0.1 / 4 if case == "apart" else 0.0
    muscle_points, muscle_tets = _box([0, 0, lift], [1, 1, 3 + lift], 4)   # muscle z < 2, top bone z > 2
    top = muscle_points[muscle_tets].mean(axis=1)[:, 2] > 2 + lift
    if case == "conforming":
        points, tets = _box([0, 0, -1], [1, 1, 3], 4)
        z = points[tets].mean(axis=1)[:, 2]
        part = np.where(z < 0, 1, np.where(z > 2, 2, 0))
    else:
        bone_points, bone_tets = _box([0, 0, -1], [1, 1, 0], 3)
        points = np.vstack([muscle_points, bone_points])
        tets = np.vstack([muscle_tets, bone_tets + len(muscle_points)])
        part = np.concatenate([np.where(top, 2, 0), np.ones(len(bone_tets), int)])
    path = tmp_path / "blocks.vtu"
    emu.io.write(path, points, tets, cell_data={"part": part})
    kinds = {"part1": "bone", "part2": "bone"}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = emu.io.load_scene(path, kinds=kinds, fibers={"part0": [0, 0, 1.0]})
    said = [str(w.message) for w in caught if "lies on bone" in str(w.message)]
    assert "part2" in scene.attachments("part0")
    if case == "loose":
        assert "part1" not in scene.attachments("part0")
        [(soft, bone, faces, area)] = scene.loose_contacts()
        assert (soft, bone) == ("part0", "part1") and faces == 2 * 4 * 4
        assert area == pytest.approx(1.0, rel=1e-12)
        assert len(said) == 1 and "muscle 'part0' lies on bone 'part1' over an area of 1 " in said[0]
        from emu.app.cli import main
        assert main(["info", str(path), "--kind", "part1=bone", "part2=bone", "--fibers", "part0=0,0,1"]) == 0
        assert "loose: part0 lies on part1 over 32 surface triangle(s), area 1," in capsys.readouterr().out
    else:
        assert scene.loose_contacts() == [] and said == []


def test_cracks_are_named_and_welded(tmp_path, mesh):
    """The proximal cap meshed apart from the belly (its vertices duplicated):
    the belly and the cap touch without sharing a vertex, which load_scene names;
    weld=True joins them again, with the attachment of the shared mesh."""
    m, _ = mesh
    part = _three_parts(m)
    cap = part == 1
    cap_vertices = np.unique(m.tets[cap])
    copy = np.full(len(m.points), -1)
    copy[cap_vertices] = len(m.points) + np.arange(len(cap_vertices))
    points = np.vstack([m.points, m.points[cap_vertices]])
    tets = m.tets.copy()
    tets[cap] = copy[m.tets[cap]]
    path = tmp_path / "cracked.vtu"
    emu.io.write(path, points, tets, cell_data={"part": part})
    kinds = {"part1": "bone", "part2": "bone"}
    with pytest.warns(emu.MeshWarning, match="muscle 'part0' and bone 'part1' touch at [0-9]+ vertex pair"):
        scene = emu.io.load_scene(path, kinds=kinds, fibers={"part0": [0, 0, 1.0]})
    assert "part1" not in scene.attachments("part0")
    assert [(a, b) for a, b, _ in scene.cracks()] == [("part0", "part1")]
    welded = emu.io.load_scene(path, kinds=kinds, fibers={"part0": "laplace"}, weld=True)
    emu.io.write(tmp_path / "whole.vtu", m.points, m.tets, cell_data={"part": part})
    whole = emu.io.load_scene(tmp_path / "whole.vtu", kinds=kinds, fibers={"part0": "laplace"})
    assert welded.cracks() == [] and len(welded.points) == len(m.points)
    assert len(welded.attachments("part0")["part1"]) == len(whole.attachments("part0")["part1"])


def test_outputs_name_the_parts(tmp_path):
    """A solved frame's VTU names each part in its field data (read back by
    meshio and by emu.io.read, so a reload keeps the names), and an OBJ with
    part groups holds one object per part with exactly that part's faces."""
    import meshio

    scene = emu.scenes.arm(1)
    sol = emu.Solver(scene, "fem").solve({"flexor": 0.1}, normalized=True)
    emu.io.write_solution(tmp_path / "f.vtu", scene, sol)
    fd = meshio.read(tmp_path / "f.vtu").field_data
    assert {k: int(v[0]) for k, v in fd.items()} == {f"part:{n}": k for k, n in enumerate(scene.parts)}
    assert emu.io.read(tmp_path / "f.vtu").part_names == dict(enumerate(scene.parts))
    faces, faces_tet = emu.io.boundary_faces(scene.tets, return_tets=True)
    emu.io.write_obj(tmp_path / "f.obj", sol.positions, faces, emu.io.part_groups(scene, faces_tet))
    objects, current = {}, None
    for line in (tmp_path / "f.obj").read_text().splitlines():
        if line.startswith("o "):
            current = line[2:]
            objects[current] = 0
        elif line.startswith("f "):
            objects[current] += 1
    assert list(objects) == list(scene.parts)
    for name, count in objects.items():
        assert count == np.isin(faces_tet, scene.parts[name].tets).sum() > 0


def test_emu_info_names_a_part_held_by_nothing(tmp_path, capsys):
    """A muscle on a fixed bone and a second muscle apart from everything:
    emu info says, before any solve, which part nothing holds and how to fix
    it (and exits 1); emu solve refuses it with the same words."""
    from emu.app.cli import main

    points, tets = _box([0, 0, -1], [1, 1, 2], 3)
    part = np.where(points[tets].mean(axis=1)[:, 2] < 0, 1, 0)
    stray_points, stray_tets = _box([3, 0, 0], [4, 1, 1], 2)
    points = np.vstack([points, stray_points])
    tets = np.vstack([tets, stray_tets + len(points) - len(stray_points)])
    part = np.concatenate([part, np.full(len(stray_tets), 2)])
    path = tmp_path / "stray.vtu"
    emu.io.write(path, points, tets, cell_data={"part": part}, part_names={0: "belly", 1: "bone", 2: "stray"})
    args = [str(path), "--kind", "bone=bone", "--fibers", "belly=0,0,1", "stray=0,0,1"]
    assert main(["info", *args]) == 1
    out = capsys.readouterr().out
    assert "part stray: muscle" in out     # the names come from the file's field data
    assert "cannot be solved as it is: 'stray' is held by nothing" in out and 'pins = ["stray"]' in out, out
    with pytest.raises(ValueError, match="'stray' is held by nothing"):
        emu.io.load_scene(path, kinds={"bone": "bone"}, fibers={"belly": [0, 0, 1.0], "stray": [0, 0, 1.0]}).validate()


def test_emu_info_names_a_loop_tendon_attachments_and_the_mesher_defects(tmp_path, capsys):
    """emu info, before any solve: a loop of joints (movable b and c hinged
    to each other and each to the fixed a) named with the fixes; a muscle
    attached only through its tendons listed with those attachments (not
    "none"); the surface defects emu mesh recorded in report.json beside the
    mesh, where that report describes this mesh."""
    import json
    from emu.app.cli import main
    pts, tets, lab = emu.procedural.block_mesh({"a": [(0, 0), (3, 1)], "b": [(1, 1)], "c": [(2, 2)],
                                           "m": [(0, 1)]}, 1)
    path = tmp_path / "loop.vtu"
    emu.io.write(path, pts, tets, cell_data={"part": lab}, part_names={0: "a", 1: "b", 2: "c", 3: "m"})
    scene_file = tmp_path / "loop.toml"
    scene_file.write_text('[mesh]\npath = "loop.vtu"\n[parts.a]\nkind = "bone"\n[parts.b]\nkind = "bone"\n'
                          '[parts.c]\nkind = "bone"\n[parts.m]\nfibers = [1.0, 1.0, 0.0]\n'
                          '[bones.b]\nfixed = false\n[bones.c]\nfixed = false\n'
                          '[activation.m]\nkeys = [[0.0, 0.0], [1.0, 0.3]]\nnormalized = true\n')
    (tmp_path / "report.json").write_text(json.dumps({"tets": len(tets), "defects": ["part 'a': a test defect"]}))
    main(["info", str(scene_file)])
    out = capsys.readouterr().out
    assert "loop: bones 'b' and 'c' close a loop of joints: FEM and EMU's accuracy mode" in out, out
    assert "surface defect (found by emu mesh): part 'a': a test defect" in out
    (tmp_path / "report.json").write_text(json.dumps({"tets": len(tets) + 1, "defects": ["stale"]}))
    main(["info", str(scene_file)])
    assert "stale" not in capsys.readouterr().out   # a report of another mesh is not this one's
    # emu run refuses the loop (EMU's accuracy mode needs FEM's estimate) and leaves no empty folder
    assert main(["run", str(scene_file), "--out", str(tmp_path / "run")]) != 0
    assert "close a loop of joints" in capsys.readouterr().err and not (tmp_path / "run").exists()
    # a muscle attached only through its tendons (emu mesh's tendon_length)
    from conftest import bone_muscle_bone
    s, m, _ = bone_muscle_bone(0.2, r=2)
    s.split_tendons("belly", 0.1 * m.length)
    via = s.tendon_attachments("belly")
    assert set(via) == {"proximal", "distal"} and {t for t, _ in via.values()} == {"belly_tendon"}
    for bone, (tendon, ids) in via.items():
        bone_verts = set(s.tets[s.parts[bone].tets].ravel().tolist())
        tendon_verts = set(s.tets[s.parts[tendon].tets].ravel().tolist())
        assert len(ids) > 0 and set(ids.tolist()) == bone_verts & tendon_verts
