"""Contact (emu.contact, Scene.enable_contact): IPC barriers from ipctk in the
FEM solver. Each physical test has its twin without contact, which must
interpenetrate (so the test can fail); the derivatives are checked by
finite differences, in Python and through the C++ Newton system."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import emu
from emu._core import testing
from emu.model.contact import ContactSettings, ContactTerm
from emu.core.geometry import boundary_faces

ipctk = pytest.importorskip("ipctk", reason="contact needs ipctk (pip install emu[contact])")

GRAVITY = np.array([0.0, 0.0, -100.0])


def muscle_vertices(scene, name):
    return np.unique(scene.tets[scene.parts[name].tets])


def test_boundary_faces_of_a_cube_are_outward_and_closed():
    points, tets, _ = emu.procedural.block_mesh({"a": [(0, 0)]}, 2)
    faces, face_tet = boundary_faces(tets, return_tets=True)
    assert len(faces) == 6 * 2 * 2 * 2          # 2 x 2 squares of 2 triangles per side
    p = points[faces]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    outward = ((p.mean(axis=1) - points.mean(axis=0)) * n).sum(axis=1)
    assert np.all(outward > 0)
    # closed: the divergence theorem gives the volume
    volume = (p.mean(axis=1) * n).sum() / 6.0
    assert volume == pytest.approx(1.0)
    assert np.all(np.isin(face_tet, np.arange(len(tets))))


def test_beam_stops_on_the_bone_and_passes_through_without_contact():
    scene = emu.scenes.beam_on_bone()
    muscle = muscle_vertices(scene, "muscle")
    bone_top = scene.points[muscle_vertices(scene, "bone"), 2].max()
    free = emu.solve(scene, method="fem", gravity=GRAVITY)
    assert free.converged and free.contact is None
    assert free.positions[muscle, 2].min() < bone_top - 0.3 * 0.01       # sags well into the bone
    settings = scene.enable_contact()
    checker = ContactTerm(scene, settings)
    assert checker.intersecting(free.positions)                           # the check sees it
    sol = emu.solve(scene, method="fem", gravity=GRAVITY)
    assert sol.converged, sol.status
    z = sol.positions[muscle, 2]
    assert z.min() > bone_top                                             # no muscle vertex inside the bone
    dhat = checker.distance
    assert sol.contact["intersecting"] is False and sol.contact["pairs"] > 0
    assert 0 < sol.contact["min_distance"] < dhat                         # resting within the barrier's reach
    assert sol.contact["min_distance"] == pytest.approx(z.min() - bone_top, rel=1e-6)
    assert not checker.intersecting(sol.positions)


def test_side_by_side_muscles_do_not_interpenetrate():
    scene = emu.scenes.side_by_side()
    checker = ContactTerm(scene, ContactSettings())
    act = {"left": 1.0, "right": 1.0}
    free = emu.solve(scene, act, method="fem", normalized=True)
    assert free.converged and checker.intersecting(free.positions)
    scene.enable_contact([("left", "right")])
    sol = emu.solve(scene, act, method="fem", normalized=True)
    assert sol.converged, sol.status
    assert not checker.intersecting(sol.positions)
    assert 0 < sol.contact["min_distance"] < checker.distance


def test_sequence_never_intersects():
    scene = emu.scenes.side_by_side()
    scene.enable_contact()
    solver = emu.Solver(scene, "fem")
    prev = None
    for a in np.linspace(0.1, 1.0, 6).tolist() + [0.5, 0.0]:
        prev = solver.solve({"left": a, "right": 0.6 * a}, normalized=True, initial=prev)
        assert prev.converged, (a, prev.status)
        assert not solver.contact.intersecting(prev.positions)
        assert prev.contact["min_distance"] > 0


def _active_state(scene):
    """Positions of the beam pressed onto the bone (pairs within reach)."""
    scene.enable_contact()
    return emu.solve(scene, method="fem", gravity=GRAVITY).positions


def test_contact_gradient_and_hessian_match_finite_differences():
    scene = emu.scenes.beam_on_bone()
    x = _active_state(scene)
    term = ContactTerm(scene, scene.contact)
    term.project = ipctk.PSDProjectionMethod.NONE
    assert term.active_pairs(x) > 0
    rng = np.random.default_rng(3)
    moving = muscle_vertices(scene, "muscle")
    d = np.zeros_like(x)
    d[moving] = rng.standard_normal((len(moving), 3))
    d *= 1e-3 * term.distance / np.abs(d).max()     # stays within the barrier's smooth range
    h = 1.0
    g = term.gradient(x)
    fd = (term.energy(x + h * d) - term.energy(x - h * d)) / (2 * h)
    assert fd == pytest.approx((g * d).sum(), rel=1e-5)
    H = term.hessian(x)
    Hd = (H @ d.ravel()).reshape(-1, 3)
    fd_g = (term.gradient(x + h * d) - term.gradient(x - h * d)) / (2 * h)
    assert np.abs(fd_g - Hd).max() <= 1e-5 * np.abs(Hd).max()
    # the projected Hessian is PSD
    term.project = ipctk.PSDProjectionMethod.CLAMP
    Hp = term.hessian(x).toarray()
    assert np.linalg.eigvalsh(0.5 * (Hp + Hp.T)).min() >= -1e-9 * np.abs(Hp).max()


@pytest.mark.parametrize("scene_name", ["beam", "arm"])
def test_fem_newton_system_includes_contact(scene_name):
    """The C++ reduced system (free vertices, bone turns) against finite
    differences of its reduced energy, contact on and active: the gradient and
    the Hessian (contact projection off, so the Hessian is exact)."""
    if scene_name == "beam":
        scene = emu.scenes.beam_on_bone()
        x = _active_state(scene)
        act = None
    else:
        # a reach beyond the rest gap (one mesh edge from the attachments): pairs
        # on the forearm's vertices, whose rows are its hinge turn
        scene = emu.scenes.arm(2)
        scene.enable_contact(distance=0.008)
        act = {"flexor": 0.4}
        with pytest.warns(emu.contact.ContactWarning, match="exceeds the smallest rest gap"):
            solver = emu.Solver(scene, "fem")
        x = solver.solve(act, normalized=True).positions
        forearm = muscle_vertices(scene, "forearm")
        assert np.abs(solver.contact.gradient(x)[forearm]).max() > 0
    if scene_name == "beam":
        solver = emu.Solver(scene, "fem")
    solver.contact.project = ipctk.PSDProjectionMethod.NONE
    assert solver.contact.active_pairs(x) > 0
    load = solver.load_case(act, normalized=True, gravity=GRAVITY if scene_name == "beam" else None)
    core = solver._core
    g, H = testing.reduced_system(core, load, x, True)
    n = len(g)
    rng = np.random.default_rng(1)
    d = rng.standard_normal(n)
    d *= 1e-4 * solver.contact.distance / np.abs(d).max()
    E = lambda z: testing.reduced_energy(core, load, x, z)  # noqa: E731
    fd = (E(d) - E(-d)) / 2
    assert fd == pytest.approx(g @ d, rel=1e-4)
    # curvature along d: E(d) + E(-d) - 2 E(0) = d' H d
    curv = E(d) + E(-d) - 2 * E(np.zeros(n))
    assert curv == pytest.approx(d @ H @ d, rel=1e-3)


def test_default_distance_stays_below_the_rest_gap():
    wide = emu.scenes.beam_on_bone()               # 2 mm gap: the default reach (5e-3 diagonal) fits
    wide.enable_contact()
    term = ContactTerm(wide, wide.contact)
    assert term.distance == pytest.approx(emu.contact.DEFAULT_DISTANCE * emu.bbox_diagonal(wide.points))
    assert term.rest_gap == np.inf                 # nothing within reach at rest
    narrow = emu.scenes.beam_on_bone(gap=0.02)     # 0.2 mm, below that reach
    narrow.enable_contact()
    term = ContactTerm(narrow, narrow.contact)
    assert term.rest_gap == pytest.approx(0.02 * 0.01, rel=1e-6)
    assert term.distance == pytest.approx(0.5 * term.rest_gap)
    assert term.active_pairs(narrow.points) == 0   # nothing pushes at rest


def ipctk_zero(n):
    import scipy.sparse as sp
    return sp.csc_matrix((n, n))


def _emu_rows(solver, sol):
    """EMU's unknowns (#unknowns by 9, vec(F) column-major) from a Solution."""
    F = sol.F.transpose(0, 2, 1).reshape(-1, 9)   # per scene tet
    first = {}
    for t, u in enumerate(np.asarray(solver._core.tet_unknown)):
        if u >= 0:
            first.setdefault(int(u), t)
    return F[[first[u] for u in range(len(first))]]


@pytest.mark.parametrize("scene_name", ["beam", "elbow"])
def test_emu_contact_gradient_and_hessian_through_the_fit(scene_name):
    """E_c(x*(F)) in EMU's energy: its gradient (one back-substitution through
    the ACAP factor) and Hessian product J^T H_c J v against finite differences,
    at an iterate with contact pairs (the contact projection off; the material
    blocks exact)."""
    if scene_name == "beam":
        scene, act, gravity = emu.scenes.beam_on_bone(), None, GRAVITY
    else:   # a movable forearm: bone unknowns carry contact forces too
        scene, act, gravity = emu.scenes.elbow_wrap(2, max_activation=2e6), {"flexor": 0.6}, None
    scene.enable_contact()
    solver = emu.Solver(scene, "emu", alpha=100.0, error_estimate=False)
    sol = solver.solve(act, normalized=True, gravity=gravity)
    assert sol.converged and sol.contact["pairs"] > 0
    solver.contact.project = ipctk.PSDProjectionMethod.NONE
    load = solver.load_case(act, normalized=True, gravity=gravity)
    core = solver._core
    F = _emu_rows(solver, sol)
    rng = np.random.default_rng(2)
    V = rng.standard_normal(F.shape)          # every unknown, the forearm's F too
    V *= 1e-6 / np.abs(V).max()
    g = testing.gradient(core, load, F)
    fd = (testing.energy(core, load, F + V) - testing.energy(core, load, F - V)) / 2
    assert fd == pytest.approx((g * V).sum(), rel=1e-4)
    Hv = testing.hessian_product(core, load, F, V, True)
    fd_H = (testing.gradient(core, load, F + V) - testing.gradient(core, load, F - V)) / 2
    # the soft rows (a bone's gradient row sums its tets' ACAP terms at weight 1e4:
    # its differences cancel to 1e-10 with contact or without)
    soft = len(scene.model_tets) - sum(len(scene.parts[b].tets) for b in scene.movable_bones)
    scale = np.abs(Hv[:soft]).max()
    assert np.abs(fd_H - Hv)[:soft].max() <= 1e-6 * scale
    # the contact term is a real share of the product: without it the check fails
    solver.contact.hessian = lambda x: ipctk_zero(3 * len(x))
    Hv0 = testing.hessian_product(core, load, F, V, True)
    assert np.abs(fd_H - Hv0)[:soft].max() > 1e-3 * scale


def test_emu_with_contact_matches_fem():
    scene = emu.scenes.beam_on_bone()
    scene.enable_contact()
    fem = emu.solve(scene, method="fem", gravity=GRAVITY)
    sol = emu.Solver(scene, "emu").solve(gravity=GRAVITY)
    assert sol.converged and not sol.contact["intersecting"]
    muscle = muscle_vertices(scene, "muscle")
    bone_top = scene.points[muscle_vertices(scene, "bone"), 2].max()
    assert sol.positions[muscle, 2].min() > bone_top
    err = emu.vertex_error(sol.positions, fem.positions, scene.points)
    assert err < 0.01                                    # the accuracy asked for (the default)
    assert sol.error_estimate == pytest.approx(err, rel=0.5)


def test_emu_sequence_with_contact_within_its_accuracy_of_fem():
    """The elbow bent far, the extensor pressed against the bones: EMU's answers
    within the accuracy asked for of the FEM equilibrium nearest them (FEM
    warm-started from EMU's answer), and its error estimate tracks that error
    (no FEM correction with contact). The nearest one: frictionless sliding
    leaves a nearly flat valley, and FEM from the previous frame's answer
    stops up to 0.8% away along it at the same energy (docs/DESIGN.md)."""
    scene = emu.scenes.elbow_wrap(2, max_activation=2e6)
    scene.enable_contact()
    fem, em = emu.Solver(scene, "fem"), emu.Solver(scene, "emu", accuracy=0.01)
    assert em.fem_correction is False
    pe = None
    for a in np.linspace(0.25, 1.0, 4):
        pe = em.solve({"flexor": a}, normalized=True, initial=pe)
        pf = fem.solve({"flexor": a}, normalized=True, initial=pe.positions)
        err = emu.vertex_error(pe.positions, pf.positions, scene.points)
        assert pe.converged and pf.converged and not pe.corrected and pe.contact["pairs"] > 0
        assert err < 0.01, (a, err)
        assert 0.5 * err <= pe.error_estimate <= 2 * err, (a, err, pe.error_estimate)


def test_contact_refusals_name_the_fix():
    scene = emu.scenes.beam_on_bone()
    with pytest.raises(ValueError, match="no part named 'femur'"):
        scene.enable_contact([("muscle", "femur")])
    with pytest.raises(ValueError, match="self_contact=True"):
        scene.enable_contact([("muscle", "muscle")])
    with pytest.raises(ValueError, match="distance must be a positive"):
        scene.enable_contact(distance=-1.0)
    scene.enable_contact()
    with pytest.raises(ValueError, match="lagged_factor"):
        emu.Solver(scene, "fem", lagged_factor=True)
    # a start state with surfaces through each other
    solver = emu.Solver(scene, "fem")
    x = scene.points.copy()
    x[muscle_vertices(scene, "muscle"), 2] -= 0.006
    with pytest.raises(ValueError, match="pass through each other at the start"):
        solver.solve(initial=x)
    # EMU: pins moved into the bone in one frame (its fit starts there)
    sunk = scene.points[scene.pinned] - np.array([0.0, 0.0, 0.006])
    with pytest.raises(ValueError, match="pass through each other at the start"):
        emu.Solver(scene, "emu").solve(pin_positions=sunk)
    scene.contact = None
    assert emu.Solver(scene, "emu").contact is None


def test_a_scene_without_contact_builds_nothing_for_it():
    code = ("import sys, emu; s = emu.scenes.beam_on_bone(); sol = emu.solve(s, method='fem'); "
            "print('ipctk' in sys.modules, sol.contact, emu.Solver(s, 'fem').contact)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "None", "None"]


def test_pair_filters_allow_exactly_the_pairs_named():
    from emu.model.contact import _patches
    allowed = np.array([[0, 1, 1, 1], [1, 0, 1, 1], [1, 1, 0, 0], [1, 1, 0, 0]], bool)  # two bones last
    patch = _patches(allowed, np.arange(4))
    assert patch is not None and patch[2] == patch[3] and len({patch[0], patch[1], patch[2]}) == 3
    chain = np.array([[0, 0, 1], [0, 0, 0], [1, 0, 0]], bool)     # a-c only: no patch labelling
    assert _patches(chain, np.arange(3)) is None


@pytest.mark.parametrize("pairs", [None, [("extensor", "humerus"), ("extensor", "forearm"), ("flexor", "extensor")],
                                   [("extensor", "humerus"), ("flexor", "forearm")]])
def test_elbow_wrap_extensor_slides_over_the_bones(pairs):
    """The extensor stretched across the elbow as the flexor bends it far: it
    cuts through the bones without contact, not with it; the last pair list
    needs the Python filter (ipctk on one thread)."""
    scene = emu.scenes.elbow_wrap(2, max_activation=2e6)
    bones = ContactTerm(scene, ContactSettings(pairs=[("extensor", "humerus"), ("extensor", "forearm")]))
    free = emu.solve(scene, {"flexor": 1.0}, method="fem", normalized=True)
    assert free.converged and bones.intersecting(free.positions)
    scene.enable_contact(pairs)
    solver = emu.Solver(scene, "fem")
    assert solver.contact._python_filter == (pairs is not None and len(pairs) == 2)
    prev = None
    for a in np.linspace(0.1, 1.0, 4):
        prev = solver.solve({"flexor": a}, normalized=True, initial=prev)
        assert prev.converged, prev.status
        assert not solver.contact.intersecting(prev.positions)
    if pairs is None or len(pairs) == 3:
        assert not bones.intersecting(prev.positions)
    else:   # forearm not named: the extensor passes through it
        assert prev.contact["pairs"] > 0
    angle = emu.bones.bone_angle(scene, prev.positions, "forearm")
    assert angle > 45.0   # bent far


def test_scene_file_contact_table(tmp_path):
    from emu.app.scenefile import SceneFileError, load_scene_file
    f = tmp_path / "s.toml"
    f.write_text('[mesh.arm]\nresolution = 2\n[contact]\npairs = [["flexor", "humerus"]]\ndistance = 0.001\n'
                 '[solver]\nmethod = "fem"\n')
    spec = load_scene_file(f)
    assert spec.scene.contact.pairs == [("flexor", "humerus")] and spec.scene.contact.distance == 0.001
    f.write_text('[mesh.arm]\nresolution = 2\n[contact]\npairs = [["flexor", "femur"]]\n')
    with pytest.raises(SceneFileError, match="contact: enable_contact: no part named 'femur'"):
        load_scene_file(f)


@pytest.mark.parametrize("method", ["fem", "emu"])
def test_self_contact_stops_a_fold(method):
    """One U-shaped muscle, its right arm and base pinned, pushed sideways
    (gravity +x): the free left arm swings into the right one through itself
    without self-contact, and stops at it with."""
    points, tets, _ = emu.procedural.block_mesh(
        {"u": [(0, 0), (0, 1), (0, 2), (0, 3), (1, 0), (2, 0), (2, 1), (2, 2), (2, 3)]}, 2, 0.01)
    scene = emu.Scene(points, tets)
    scene.add_muscle("u", np.arange(len(tets)), [0.0, 1.0, 0.0])
    scene.pin(np.flatnonzero((points[:, 0] >= 0.02 - 1e-9) | (points[:, 1] <= 1e-9)))
    g = np.array([300.0, 0.0, 0.0])
    fold = ContactTerm(scene, ContactSettings(pairs=[("u", "u")], self_contact=True))
    free = emu.solve(scene, method=method, gravity=g)
    assert free.converged and fold.intersecting(free.positions)
    scene.enable_contact([("u", "u")], self_contact=True)
    sol = emu.solve(scene, method=method, gravity=g)
    assert sol.converged, sol.status
    assert not fold.intersecting(sol.positions)
    assert sol.contact["pairs"] > 0 and 0 < sol.contact["min_distance"] < fold.distance
