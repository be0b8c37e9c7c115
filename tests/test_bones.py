"""Bones moved by the muscles: rigid bodies on joints, in both solvers."""
import numpy as np
import pytest

import emu
from emu._core import testing
from emu.model.bones import bone_motion, signed_angle
from emu.build.scenes import arm
from conftest import bone_chain_scene, bone_loop_scene, gap_scene, shared_path


def hinge_vertices(scene, a, b):
    (j,) = [j for j in scene.joints() if set(j.bones) == {a, b}]
    return j


@pytest.fixture(scope="module")
def small_arm():
    return arm(1)


def test_arm_joint_is_detected_as_a_hinge(small_arm):
    j = hinge_vertices(small_arm, "humerus", "forearm")
    assert j.kind == "hinge" and len(j.vertices) >= 2
    np.testing.assert_allclose(np.abs(j.axis), [0, 0, 1], atol=1e-12)


@pytest.mark.parametrize("method", ["fem", "emu"])
def test_flexor_bends_and_extensor_straightens_the_elbow(small_arm, method):
    s = small_arm
    j = hinge_vertices(s, "humerus", "forearm")
    solver = emu.Solver(s, method)
    turns = {}
    for muscle in ("flexor", "extensor"):
        sol = solver.solve({muscle: 0.3}, normalized=True)
        assert sol.converged, sol.status
        bm = bone_motion(s, sol, "forearm")
        turns[muscle] = signed_angle(bm.R, [0, 0, 1])
        # the hinge vertices stay put, the forearm turns about them and stays rigid
        np.testing.assert_allclose(sol.positions[j.vertices], s.points[j.vertices], atol=1e-9)
        assert bm.rigidity < 1e-6
        hum = np.unique(s.tets[s.parts["humerus"].tets].ravel())
        np.testing.assert_array_equal(sol.positions[hum], s.points[hum])
    assert turns["flexor"] > 5.0 and turns["extensor"] < -1.0, turns


def test_fem_rigid_bone_equilibrium_is_the_minimum_over_scripted_angles(small_arm):
    """Independent check of the rigid-bone Newton: the same scene with the
    forearm scripted (fixed, posed by pins) at angles around FEM's answer has
    its lowest energy there."""
    s = small_arm
    act = {"flexor": 0.3}
    free = emu.Solver(s, "fem", rtol_grad=1e-9).solve(act, normalized=True)
    theta = signed_angle(bone_motion(s, free, "forearm").R, [0, 0, 1])
    scripted = arm(1, forearm_fixed=True)
    solver = emu.Solver(scripted, "fem", rtol_grad=1e-9)

    def energy(deg):
        sol = solver.solve(act, normalized=True, bone_poses={"forearm": emu.pose_about([0, 0, 1], deg, [0, 0, 0])})
        assert sol.converged, sol.status
        return sol.energy, sol

    E0, sol0 = energy(theta)
    # the scripted solve at FEM's angle lands on FEM's positions and energy
    np.testing.assert_allclose(sol0.positions, free.positions, atol=1e-7)
    np.testing.assert_allclose(E0, free.energy, rtol=1e-9)
    for d in (-0.5, 0.5):
        assert energy(theta + d)[0] > E0


def test_emu_bone_derivatives_match_finite_differences(small_arm):
    s = small_arm
    solver = emu.Solver(s, "emu", alpha=100)
    core = solver._core
    load = solver.load_case({"flexor": 0.5, "extensor": 0.2}, normalized=True, gravity=[0, -9.81, 0])
    nu = core.num_unknowns
    assert nu == (core.tet_unknown.max() + 1)
    rng = np.random.default_rng(3)
    F = np.tile(np.eye(3).ravel(), (nu, 1)) + 0.02 * rng.standard_normal((nu, 9))
    for only_bone in (False, True):
        D = rng.standard_normal((nu, 9))
        if only_bone:
            D[:-1] = 0.0  # the bone is the last unknown
        g = testing.gradient(core, load, F)
        h = 1e-6
        fd = (testing.energy(core, load, F + h * D) - testing.energy(core, load, F - h * D)) / (2 * h)
        assert abs(fd - np.sum(g * D)) <= 1e-6 * abs(fd) + 1e-9
        Hd = testing.hessian_product(core, load, F, D, True)
        fdH = (testing.gradient(core, load, F + h * D) - testing.gradient(core, load, F - h * D)) / (2 * h)
        assert np.abs(fdH - Hd).max() <= 1e-5 * np.abs(fdH).max()


@pytest.mark.parametrize("which", ["arm", "chain"])
def test_bone_coarse_turn_matches_a_fit_of_the_turn(small_arm, which):
    """The coarse space's turn of a bone by M (from the unit turn's fits, no
    fit per turn) against the construction it stands for: the displacement fit
    of the bone's field M (the difference of two affine fits), the soft F_t
    of it, and the generic Hessian product of that Z (which fits again); one
    bone, and two bones joined by a hinge (the joint rows in the fit)."""
    from emu.core.geometry import deformation_gradients
    s = small_arm if which == "arm" else bone_chain_scene()
    act = {"flexor": 0.5} if which == "arm" else {"m1": 0.2, "m2": 0.2}
    solver = emu.Solver(s, "emu", alpha=100)
    core = solver._core
    load = solver.load_case(act, normalized=True)
    nu, tu = core.num_unknowns, np.asarray(core.tet_unknown)
    nb = len(s.movable_bones)
    ns = nu - nb
    tets = s.tets   # tu is per scene tet
    rng = np.random.default_rng(5)
    F = np.tile(np.eye(3).ravel(), (nu, 1)) + 0.02 * rng.standard_normal((nu, 9))
    for b in range(nb):   # bones at rotations
        q, _ = np.linalg.qr(np.eye(3) + 0.3 * rng.standard_normal((3, 3)))
        F[ns + b] = (q * np.sign(np.linalg.det(q))).ravel(order="F")
    soft = np.flatnonzero((tu >= 0) & (tu < ns))
    for b in range(nb):
        R = F[ns + b].reshape(3, 3, order="F")
        for k in range(3):
            W = np.zeros((3, 3))
            W[(k + 2) % 3, (k + 1) % 3], W[(k + 1) % 3, (k + 2) % 3] = 1.0, -1.0
            M = W @ R
            Z, HZ = testing.bone_turn(core, load, F, b, M, True)
            # the coarse space takes every turn as M times the unit turn's field (bone_coarse_space.h)
            Zunit, _ = testing.bone_turn(core, load, F, b, np.eye(3), True)
            ZM = (M @ Zunit.reshape(-1, 3, 3, order="C").transpose(0, 2, 1)).transpose(0, 2, 1).reshape(-1, 9)
            np.testing.assert_allclose(Z, ZM, rtol=0, atol=1e-12 * np.abs(Z).max())
            E = np.zeros((nu, 9))
            E[ns + b] = M.ravel(order="F")
            dx = testing.fit_positions(core, load, F + E) - testing.fit_positions(core, load, F)
            expected = E.copy()
            expected[tu[soft]] = deformation_gradients(s.points, tets, dx)[soft].transpose(0, 2, 1).reshape(-1, 9)
            np.testing.assert_allclose(Z, expected, rtol=0, atol=1e-10 * np.abs(expected).max())
            HZe = testing.hessian_product(core, load, F, expected, True)
            np.testing.assert_allclose(HZ, HZe, rtol=0, atol=1e-10 * np.abs(HZe).max())
    with pytest.raises(ValueError, match="not a movable bone"):
        testing.bone_turn(core, load, F, nb, np.eye(3))


def test_emu_and_fem_agree_on_the_arm_as_alpha_grows(small_arm):
    s = small_arm
    fem = emu.Solver(s, "fem").solve({"flexor": 0.3}, normalized=True)
    theta = signed_angle(bone_motion(s, fem, "forearm").R, [0, 0, 1])
    errs = []
    for alpha in (30, 300, 3000):
        sol = emu.Solver(s, "emu", alpha=alpha).solve({"flexor": 0.3}, normalized=True)
        assert sol.converged, sol.status
        errs.append(abs(signed_angle(bone_motion(s, sol, "forearm").R, [0, 0, 1]) - theta))
    assert errs[2] < errs[0] and errs[2] < 0.1, errs


def test_simple_joint_free_bone_emu_vs_fem():
    """The shared scene: contracting the muscle turns the free bottom bone about
    the hinge edge; EMU's angle is within 2 degrees of FEM's (README)."""
    path = shared_path("simple_joint")
    s = emu.io.load_scene(path, free_bones=["bottom_bone"], warn=False)
    hinge = [2450, 2451]
    angles = {}
    for method in ("fem", "emu"):
        sol = emu.Solver(s, method).solve({"muscle": 1e4})
        assert sol.converged, sol.status
        bm = bone_motion(s, sol, "bottom_bone")
        np.testing.assert_allclose(sol.positions[hinge], s.points[hinge], atol=1e-9)
        assert bm.rigidity < 1e-6, bm.rigidity
        angles[method] = bm.angle_deg
    assert 40 < angles["fem"] < 80, angles      # it really swings (about 60 degrees)
    assert abs(angles["emu"] - angles["fem"]) < 2.0, angles


def test_movable_bone_errors(small_arm):
    s = small_arm
    with pytest.raises(ValueError, match="Schur-complement preconditioner does not handle movable bones"):
        emu.Solver(s, "emu", preconditioner="schur")
    with pytest.raises(ValueError, match="moved by the muscles"):
        emu.solve(s, {}, "fem", bone_poses={"forearm": (np.eye(3), np.zeros(3))})
    # a movable bone welded to the fixed one by a face
    m = emu.procedural.block_mesh({"a": [(0, 0)], "b": [(1, 0)], "m": [(0, 1), (1, 1)]}, 1)
    pts, tets, lab = m
    w = emu.Scene(pts, tets)
    w.add_bone("a", lab == 0)
    w.add_bone("b", lab == 1, fixed=False)
    w.add_muscle("m", lab == 2, [1, 0, 0])
    with pytest.raises(ValueError, match="weld"):
        emu.Solver(w, "fem")
    with pytest.raises(ValueError, match="a weld"):   # EMU refuses what FEM refuses
        emu.Solver(w, "emu")


def test_joint_between_two_movable_bones(small_arm):
    """A chain (fixed a, b hinged to a, c hinged to b): both solvers hold both
    hinges, and EMU at accuracy 0.01 is within 1% of the converged FEM answer."""
    s = bone_chain_scene()
    kinds = {tuple(sorted(j.bones)): j.kind for j in s.joints()}
    assert kinds[("a", "b")] == "hinge" and kinds[("b", "c")] == "hinge"
    act = {"m1": 0.2, "m2": 0.2}
    fem = emu.Solver(s, "fem", rtol_grad=1e-9).solve(act, normalized=True)
    ours = emu.Solver(s, "emu", accuracy=0.01).solve(act, normalized=True)
    jb = [j for j in s.joints() if set(j.bones) == {"b", "c"}][0].vertices
    for sol in (fem, ours):
        assert sol.converged, sol.status
        for bone in ("b", "c"):
            bm = bone_motion(s, sol, bone)
            assert bm.rigidity < 1e-5
            # the shared hinge vertices sit where both bones put them
            np.testing.assert_allclose(s.points[jb] @ bm.R.T + bm.t, sol.positions[jb], atol=1e-5)
    turns = [signed_angle(bone_motion(s, fem, b).R, [0, 0, 1]) for b in ("b", "c")]
    assert abs(turns[0]) > 1 and abs(turns[1] - turns[0]) > 1, turns   # both hinges turned
    err = np.abs(ours.positions - fem.positions).max() / np.linalg.norm(np.ptp(s.points, axis=0))
    assert err < 0.01, (err, ours.error_estimate)


def _chain(movable=True):
    """emu.scenes.chain(1) with b and c movable, or fixed for scripting."""
    s = bone_chain_scene()
    if movable:
        return s
    pts, tets = s.points, s.tets
    t = emu.Scene(pts, tets)
    t.add_bone("a", s.parts["a"].tets)
    for b in ("b", "c"):
        t.add_bone(b, s.parts[b].tets)
    for m in ("m1", "m2", "m3"):
        t.add_muscle(m, s.parts[m].tets, [1.0, 1.0, 0.0])
    return t


def test_fem_chain_equilibrium_is_the_minimum_over_scripted_angles():
    """Independent check of the chain's Newton: the same scene with b and c
    scripted (fixed, posed) at angles around FEM's answer has its lowest
    energy at FEM's angles, and lands on FEM's positions there."""
    s = _chain()
    act = {"m1": 0.2, "m2": 0.3}
    free = emu.Solver(s, "fem", rtol_grad=1e-9).solve(act, normalized=True)
    hinge = {k: [j for j in s.joints() if set(j.bones) == set(k)][0] for k in (("a", "b"), ("b", "c"))}
    pivot = {b: s.points[hinge[k].vertices].mean(axis=0) for b, k in (("b", ("a", "b")), ("c", ("b", "c")))}
    tb = signed_angle(bone_motion(s, free, "b").R, [0, 0, 1])
    tc = signed_angle(bone_motion(s, free, "c").R, [0, 0, 1]) - tb
    solver = emu.Solver(_chain(movable=False), "fem", rtol_grad=1e-9)

    def energy(db, dc):
        Rb, t_b = emu.pose_about([0, 0, 1], tb + db, pivot["b"])
        Rc, t_c = emu.pose_about([0, 0, 1], tc + dc, pivot["c"])
        poses = {"b": (Rb, t_b), "c": (Rb @ Rc, Rb @ t_c + t_b)}   # c turns about its hinge, then with b
        sol = solver.solve(act, normalized=True, bone_poses=poses)
        assert sol.converged, sol.status
        return sol.energy, sol

    E0, sol0 = energy(0, 0)
    np.testing.assert_allclose(sol0.positions, free.positions, atol=1e-6)
    np.testing.assert_allclose(E0, free.energy, rtol=1e-8)
    for d in ((-0.5, 0), (0.5, 0), (0, -0.5), (0, 0.5), (0.4, -0.4), (0.4, 0.4)):
        assert energy(*d)[0] > E0, d


def test_chain_loop_is_refused_by_fem():
    """b hinged to the fixed a, c hinged to b and to a: a closed loop, which
    reduced joint coordinates cannot take; FEM says so, naming the fix."""
    with pytest.raises(ValueError, match="movable bones 'b' and 'c' close a loop of joints"):
        emu.Solver(bone_loop_scene(), "fem")


def test_a_chain_bone_nothing_turns_is_reported_as_a_neutral_mode():
    """c on a ball joint at the end of the chain a -> b -> c with no muscle on
    c: its turns are free. Both solvers converge, turn b and name c; FEM
    leaves c's turn relative to b alone (EMU's world orientation: either is an
    equilibrium), and both keep c on its joint."""
    pts, tets, lab = emu.procedural.block_mesh(
        {"a": [(0, 0, 0)], "b": [(1, 1, 0)], "c": [(2, 2, 1)], "m": [(1, 0, 0)]}, 1)
    s = emu.Scene(pts, tets)
    s.add_bone("a", lab == 0)
    s.add_bone("b", lab == 1, fixed=False)
    s.add_bone("c", lab == 2, fixed=False)
    s.add_muscle("m", lab == 3, [1, 1, 0])
    assert sorted(j.kind for j in s.joints()) == ["ball", "hinge"]
    for method in ("fem", "emu"):
        with pytest.warns(emu.NeutralModeWarning, match="bone 'c' can turn"):
            sol = emu.Solver(s, method).solve({"m": 0.5}, normalized=True)
        assert sol.converged, sol.status
        assert {b for b, _ in sol.neutral_modes} == {"c"}
        b, c = bone_motion(s, sol, "b"), bone_motion(s, sol, "c")
        assert b.angle_deg > 1 and c.rigidity < 1e-6
        (j,) = [j for j in s.joints() if set(j.bones) == {"b", "c"}]
        np.testing.assert_allclose(s.points[j.vertices] @ b.R.T + b.t, sol.positions[j.vertices], atol=1e-9)
        if method == "fem":   # c turns only with b
            assert np.degrees(np.arccos(np.clip((np.trace(b.R.T @ c.R) - 1) / 2, -1, 1))) < 1e-3


# ------------------------------------------------------------- ball joint
def test_head_on_a_ball_joint_emu_vs_fem():
    s = emu.scenes.neck(1)
    (j,) = s.joints()
    assert j.kind == "ball" and len(j.vertices) == 1
    res = {}
    for method in ("fem", "emu"):
        sol = emu.Solver(s, method).solve({"left_front": 0.4}, normalized=True)
        assert sol.converged, sol.status
        np.testing.assert_allclose(sol.positions[j.vertices], s.points[j.vertices], atol=1e-12)
        bm = bone_motion(s, sol, "head")
        assert bm.rigidity < 1e-6
        w = np.array([bm.R[2, 1] - bm.R[1, 2], bm.R[0, 2] - bm.R[2, 0], bm.R[1, 0] - bm.R[0, 1]])
        res[method] = (bm.angle_deg, w / np.linalg.norm(w))
    # the left-front muscle tips the head down towards the left front: about the axis (-1, -1, .)/sqrt 2
    angle, axis = res["fem"]
    assert angle > 3 and axis @ np.array([-1, -1, 0]) / np.sqrt(2) > 0.9, res
    assert abs(res["emu"][0] - angle) < 1.5 and res["emu"][1] @ axis > 0.99, res


# ------------------------------------------------------------- declared joints
def test_declared_hinge_between_bones_that_do_not_touch():
    s = gap_scene()
    assert s.joints() == []
    # without the joint the lower bone is free, held by the muscle alone: it slides
    free = emu.Solver(s, "fem").solve({"muscle": 0.5}, normalized=True)
    c = np.array([1.5, 1.5, 0.5])
    bm = bone_motion(s, free, "lower")
    assert np.linalg.norm(bm.R @ c + bm.t - c) > 0.05
    s.add_joint("lower", "upper", centre=[1.5, 1.5, 0.5], axis=[0, 0, 1])
    (j,) = s.joints()
    assert j.declared and j.kind == "hinge"
    angles = {}
    for method, alpha in (("fem", None), ("emu", 100), ("emu", 1000), ("emu", 10000)):
        sol = emu.Solver(s, method, **({"alpha": alpha} if alpha else {})).solve({"muscle": 0.5}, normalized=True)
        assert sol.converged, sol.status
        bm = bone_motion(s, sol, "lower")
        # points on the declared axis stay where they were
        for z in (0.0, 0.5, 1.0):
            c = np.array([1.5, 1.5, z])
            np.testing.assert_allclose(bm.R @ c + bm.t, c, atol=1e-9 if method == "fem" else 1e-5)
        angles[alpha] = signed_angle(bm.R, [0, 0, 1])
    # a large turn (about 35 degrees) on a coarse mesh: EMU's error shrinks with alpha
    # (measured 4.3, 0.55, 0.06 degrees)
    diff = [abs(angles[a] - angles[None]) for a in (100, 1000, 10000)]
    assert angles[None] > 20 and diff[0] > diff[1] > diff[2] and diff[2] < 0.15, angles


def test_declared_joint_errors():
    s = gap_scene()
    with pytest.raises(ValueError, match="no bone named 'femur'"):
        s.add_joint("lower", "femur", centre=[0, 0, 0])
    with pytest.raises(ValueError, match="axis must be a non-zero"):
        s.add_joint("lower", "upper", centre=[0, 0, 0], axis=[0, 0, 0])
    s.parts["lower"].fixed = True
    s.add_joint("lower", "upper", centre=[1.5, 1.5, 0.5])
    with pytest.raises(ValueError, match="both bones are fixed"):
        emu.Solver(s, "fem")


def test_big_muscle_free_bone_is_pulled_toward_the_fixed_one():
    path = shared_path("big_muscle")
    s = emu.io.load_scene(path, free_bones=["bone_2"], warn=False)
    assert s.joints() == []              # no joint: bone_2 is held by the muscle alone
    c1 = s.points[np.unique(s.tets[s.parts["bone_1"].tets])].mean(axis=0)
    c2 = s.points[np.unique(s.tets[s.parts["bone_2"].tets])].mean(axis=0)
    gap = np.linalg.norm(c1 - c2)
    moved = {}
    for method in ("fem", "emu"):
        sol = emu.Solver(s, method).solve({"muscle": 1e4})
        assert sol.converged, sol.status
        assert sol.neutral_modes == []   # the muscle's torsion holds the twist about its axis
        bm = bone_motion(s, sol, "bone_2")
        assert bm.rigidity < 1e-6
        new_c2 = bm.R @ c2 + bm.t
        moved[method] = gap - np.linalg.norm(c1 - new_c2)
        fixed = np.unique(s.tets[s.parts["bone_1"].tets].ravel())
        np.testing.assert_array_equal(sol.positions[fixed], s.points[fixed])
    # FEM: about 1.5 of the 10.4 units between the centres; EMU within 5% of that
    assert 0.05 * gap < moved["fem"] < 0.5 * gap, moved
    assert abs(moved["emu"] - moved["fem"]) < 0.05 * moved["fem"], moved


# ------------------------------------------------------------- passive joint stiffness
def test_joint_stiffness_derivatives_and_agreement():
    k = 1.0   # N m / rad: holds the flexed forearm back from 24 to about 20 degrees
    s = arm(1)
    s.parts["forearm"].joint_stiffness = k
    solver = emu.Solver(s, "emu")
    core = solver._core
    load = solver.load_case({"flexor": 0.3}, normalized=True)
    nu = core.num_unknowns
    rng = np.random.default_rng(5)
    F = np.tile(np.eye(3).ravel(), (nu, 1)) + 0.02 * rng.standard_normal((nu, 9))
    D = np.zeros((nu, 9))
    D[-1] = rng.standard_normal(9)
    h = 1e-6
    fd = (testing.energy(core, load, F + h * D) - testing.energy(core, load, F - h * D)) / (2 * h)
    assert abs(fd - np.sum(testing.gradient(core, load, F) * D)) <= 1e-6 * abs(fd)
    free = signed_angle(bone_motion(s, emu.Solver(arm(1), "fem").solve({"flexor": 0.3}, normalized=True),
                                    "forearm").R, [0, 0, 1])
    angles = {}
    for method in ("fem", "emu"):
        sol = emu.Solver(s, method).solve({"flexor": 0.3}, normalized=True)
        assert sol.converged, sol.status
        angles[method] = signed_angle(bone_motion(s, sol, "forearm").R, [0, 0, 1])
    assert 1.0 < angles["fem"] < free - 1.0, (angles, free)     # the spring holds it back
    assert abs(angles["emu"] - angles["fem"]) < 1.5, angles
    # FEM's answer is the minimum of (scripted-bone energy + spring) over the angle
    scripted = emu.Solver(arm(1, forearm_fixed=True), "fem", rtol_grad=1e-9)

    def total(deg):
        sol = scripted.solve({"flexor": 0.3}, normalized=True,
                             bone_poses={"forearm": emu.pose_about([0, 0, 1], deg, [0, 0, 0])})
        return sol.energy + k * (1 - np.cos(np.radians(deg)))

    e0 = total(angles["fem"])
    assert total(angles["fem"] - 0.5) > e0 and total(angles["fem"] + 0.5) > e0


def test_a_stiff_shoulder_spring_converges_in_filtered_steps():
    """The upper limb's humerus on a 1 N m / rad shoulder spring, the biceps at
    0.3. Bone by bone, EMU takes filtered steps there (the chain's exact
    Hessian is indefinite), and the spring's only curvature is SO(3)'s term,
    which the filtered Hessian keeps (clamped): without it EMU ran out of 500
    iterations; with it, it converges and lands as near FEM as with a soft
    spring. In joint coordinates (the default) it converges in a few tens of
    full steps, to the same answer."""
    from emu.build.anatomy import upper_limb

    errors = {}
    for k in (0.05, 1.0):
        s = upper_limb(resolution=1, shoulder_stiffness=k)
        act = {"biceps": 0.3}
        sol = emu.Solver(s, "emu", alpha=100, joint_coordinates=False).solve(act, normalized=True)
        assert sol.converged and sol.iterations < 150, (k, sol.iterations, sol.status)
        assert sol.filtered_steps > 0
        fem = emu.Solver(s, "fem").solve(act, normalized=True)
        errors[k] = emu.vertex_error(sol, fem)
        joint = emu.Solver(s, "emu", alpha=100).solve(act, normalized=True)
        assert joint.converged and joint.iterations < 40, (k, joint.iterations, joint.status)
        assert emu.vertex_error(joint, sol) < 1e-3
    assert errors[1.0] < 1.5 * errors[0.05] and errors[1.0] < 0.03, errors


# ------------------------------------------------------------- the constrained fit, independently
def test_bone_fit_matches_a_dense_constrained_least_squares():
    """EMU's fit x*(F) with a movable bone and a hinge (bordered factor, null-space
    joint solve) against a dense KKT solve built here from G, volumes and weights:
    minimise sum_t w_t V_t |F_t(x) - F_t|^2 over soft vertices and the bone's
    affine map, the hinge vertices at their pinned positions."""
    from conftest import gradient_operator

    s = arm(1)
    solver = emu.Solver(s, "emu", preconditioner="woodbury", modes=6)  # its modes are checked below
    core = solver._core
    model = core.model   # its tets in the solver's order
    keep = np.asarray(model.scene_tet)
    T = s.tets[keep]
    G, vol = gradient_operator(s.points, T)
    G = G.toarray()
    w = np.asarray(model.acap_weight) * vol
    n = len(s.points)
    pinned = np.asarray(model.pinned)
    bone_tets = np.flatnonzero(np.asarray(model.bone) >= 0)
    bone_verts = np.setdiff1d(np.unique(T[bone_tets]), pinned)
    soft = np.setdiff1d(np.arange(n), np.union1d(pinned, bone_verts))
    # x (3n) = S z + x0, z = [soft vertex coordinates, A (9, row-major), c (3)]
    nz = 3 * len(soft) + 12
    S = np.zeros((3 * n, nz))
    for i, v in enumerate(soft):
        S[3 * v:3 * v + 3, 3 * i:3 * i + 3] = np.eye(3)
    Xbar = s.points[np.unique(T[bone_tets])].mean(axis=0)   # any reference point: the fit does not depend on it
    o = 3 * len(soft)
    for v in bone_verts:
        for c in range(3):
            S[3 * v + c, o + 3 * c:o + 3 * c + 3] = s.points[v] - Xbar
            S[3 * v + c, o + 9 + c] = 1.0
    x0 = np.zeros(3 * n)
    x0[(3 * pinned[:, None] + np.arange(3)).ravel()] = s.points[pinned].ravel()
    # joint rows: every pinned vertex of the bone sits where it is pinned
    joint = np.intersect1d(np.unique(T[bone_tets]), pinned)
    assert len(joint) >= 2
    J = np.zeros((3 * len(joint), nz))
    h = np.zeros(3 * len(joint))
    for k, v in enumerate(joint):
        for c in range(3):
            J[3 * k + c, o + 3 * c:o + 3 * c + 3] = s.points[v] - Xbar
            J[3 * k + c, o + 9 + c] = 1.0
            h[3 * k + c] = s.points[v, c]
    rng = np.random.default_rng(11)
    nu = core.num_unknowns
    Fu = np.tile(np.eye(3).ravel(), (nu, 1)) + 0.05 * rng.standard_normal((nu, 9))
    Ft = Fu[np.asarray(core.tet_unknown)[keep]]      # per tet of T, vec column-major
    D = np.repeat(w, 9)
    M = G @ S
    rhs = Ft.ravel() - G @ x0
    K = M.T @ (D[:, None] * M)
    b = M.T @ (D * rhs)
    # KKT with possibly redundant joint rows: least squares on the bordered system
    Kkt = np.block([[K, J.T], [J, np.zeros((len(h), len(h)))]])
    sol = np.linalg.lstsq(Kkt, np.concatenate([b, h]), rcond=1e-13)[0]
    x_ref = (S @ sol[:nz] + x0).reshape(-1, 3)
    load = solver.load_case({}, normalized=True)
    x = testing.fit_positions(core, load, Fu)
    scale = np.abs(s.points).max()
    np.testing.assert_allclose(x, x_ref, atol=1e-9 * scale)
    # the Woodbury modes are the constrained operator's lowest eigenpairs (joint rows
    # included): eigenvalues of K on the null space of J, each once per coordinate
    _, sv, vt = np.linalg.svd(J)
    N = vt[np.sum(sv > 1e-9 * sv[0]):].T
    ev = np.linalg.eigvalsh(N.T @ K @ N)
    k = core.modes
    assert k == 6
    np.testing.assert_allclose(np.sort(testing.mode_values(core)), ev[:k], rtol=1e-8)


# ------------------------------------------------------------- neutral modes
def test_a_bone_nothing_turns_is_reported_as_a_neutral_mode():
    """A bone on a ball joint with no muscle on it: every turn about the joint
    is free. Both solvers converge (the soft tissue elsewhere settles), leave the
    bone alone and name it."""
    pts, tets, lab = emu.procedural.block_mesh(
        {"base": [(0, 0, 0), (0, 0, 1)], "loose": [(1, 1, 2)], "m": [(-1, 0, 0), (-1, 0, 1), (-2, 0, 0)]}, 1)
    s = emu.Scene(pts, tets)
    s.add_bone("base", lab == 0)
    s.add_bone("loose", lab == 1, fixed=False)
    s.add_muscle("m", lab == 2, [1, 0, 0])
    assert [j.kind for j in s.joints()] == ["ball"]
    for method in ("fem", "emu"):
        with pytest.warns(emu.NeutralModeWarning, match="bone 'loose' can turn"):
            sol = emu.Solver(s, method).solve({"m": 0.5}, normalized=True)
        assert sol.converged, sol.status
        assert {b for b, _ in sol.neutral_modes} == {"loose"}
        assert bone_motion(s, sol, "loose").angle_deg < 1e-4   # left alone (drift of round-off size)
        m = np.unique(s.tets[s.parts["m"].tets].ravel())
        assert np.abs(sol.positions[m] - s.points[m]).max() > 1e-3   # the muscle did contract


def test_no_neutral_mode_where_muscles_hold_the_bone(small_arm):
    import warnings as w

    with w.catch_warnings():
        w.simplefilter("error", emu.NeutralModeWarning)
        for method in ("fem", "emu"):
            sol = emu.Solver(small_arm, method).solve({"flexor": 0.3}, normalized=True)
            # a finished solve that turned the forearm, not an aborted one with nothing to report
            assert sol.converged and sol.iterations > 0, sol.status
            assert bone_motion(small_arm, sol, "forearm").angle_deg > 1.0
            assert sol.neutral_modes == []


@pytest.mark.parametrize("method", ["fem", "emu"])
def test_movable_bone_follows_a_scripted_parent(small_arm, method):
    """Scripting the humerus (turning the whole upper arm about its top) carries
    the elbow hinge with it; with the muscles relaxed the rest pose is the
    equilibrium, so the forearm turns rigidly with it."""
    s = small_arm
    top = s.points[:, 1].max()
    R, t = emu.pose_about([0, 0, 1], 20, [0, top, 0])
    strict = {"alpha": 100.0} if method == "emu" else {}   # fixed alpha: the strict tolerance
    sol = emu.Solver(s, method, **strict).solve({}, bone_poses={"humerus": (R, t)})
    assert sol.converged, sol.status
    bm = bone_motion(s, sol, "forearm")
    np.testing.assert_allclose(bm.R, R, atol=1e-6)
    np.testing.assert_allclose(sol.positions, s.points @ R.T + t, atol=1e-6 * top)


def test_gravity_on_a_movable_bone():
    """The relaxed arm under gravity: the forearm droops (turns down about the
    elbow) until the muscles hold it; FEM and EMU agree."""
    s = arm(1)
    s.gravity = np.array([0.0, -9.81, 0.0])
    angles = {}
    for method in ("fem", "emu"):
        sol = emu.Solver(s, method).solve({})
        assert sol.converged, sol.status
        angles[method] = signed_angle(bone_motion(s, sol, "forearm").R, [0, 0, 1])
    assert angles["fem"] < -1.0 and abs(angles["emu"] - angles["fem"]) < 0.5, angles


def test_rigid_fit_recovers_a_rigid_motion():
    from emu.model.bones import rigid_fit

    rng = np.random.default_rng(4)
    X = rng.standard_normal((20, 3))
    R = emu.rotation([1.0, -2.0, 0.5], 140.0)
    t = np.array([0.3, -1.0, 2.0])
    Rf, tf = rigid_fit(X, X @ R.T + t)
    np.testing.assert_allclose(Rf, R, atol=1e-12)
    np.testing.assert_allclose(tf, t, atol=1e-12)
    # a mirror image is fitted by the nearest proper rotation, never a reflection
    Rm, _ = rigid_fit(X, X * [-1.0, 1.0, 1.0])
    assert np.linalg.det(Rm) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="equal shape"):
        rigid_fit(X, X[:5])


def test_recycled_directions_change_cg_not_the_answer():
    """big_muscle with bone_2 free: a CG solve that stalls (134 iterations after
    one of 20 without recycling) is cut and recycled into the coarse space of
    the later steps; the answer is the same equilibrium (the preconditioner
    changes CG's path, not the answer)."""
    s = emu.io.load_scene(shared_path("big_muscle"), free_bones=["bone_2"], warn=False)
    plain = emu.Solver(s, "emu", alpha=100, recycled_directions=0).solve({"muscle": 1e4})
    recycled = emu.Solver(s, "emu", alpha=100).solve({"muscle": 1e4})   # the default: 4
    assert plain.converged and recycled.converged, (plain.status, recycled.status)
    assert recycled.cg_iterations != plain.cg_iterations   # the option reached the solver
    # The bone's twist about the muscle is a soft mode: solves stop at the
    # gradient's round-off floor (|g|/|g0| ~ 1e-7, a tighter rtol_grad changes
    # nothing) up to 1.3e-5 apart along it (the constant-Schur preconditioner
    # without recycling; 3e-7 with the Woodbury one), against an alpha error of 5.6e-3.
    assert emu.vertex_error(recycled, plain) < 3e-5
    with pytest.raises(ValueError, match="recycled_directions"):
        emu.Solver(s, "emu", recycled_directions=-1)


def test_a_stalled_cg_solve_is_cut_and_its_direction_learned():
    """simple_joint with its bone free: CG is cut at max(30, 2x the step
    before) iterations (StepSolver::kCgStallMin, kCgStallRatio), where without
    recycling (no coarse space to learn in: no cut) a step takes more; the
    solve does not stop on a cut step, and the answer is within the accuracy
    of strict FEM."""
    s = emu.io.load_scene(shared_path("simple_joint"), free_bones=["bottom_bone"], warn=False)
    load = {"muscle": 1e4}

    def steps(sol):   # CG per Newton step of the first solve, and each step's limit
        it, cg = sol.history["iteration"], sol.history["cg_iterations"]
        end = next((k for k in range(1, len(it)) if it[k] == 0), len(it))
        cg = [int(c) for c in cg[1:end]]
        return cg, [max(30, 2 * b) for b in [0] + cg[:-1]]

    cut = emu.Solver(s, "emu", accuracy=0.01).solve(load)
    cg, limits = steps(cut)
    assert all(c <= m for c, m in zip(cg, limits)), (cg, limits)
    assert any(c == m for c, m in zip(cg, limits)), (cg, limits)   # a step was cut
    assert cg[-1] < limits[-1] and "step_tol" in cut.status, (cg, cut.status)   # not stopped on a cut step
    plain_cg, plain_limits = steps(emu.Solver(s, "emu", accuracy=0.01, recycled_directions=0).solve(load))
    assert any(c > m for c, m in zip(plain_cg, plain_limits)), (plain_cg, plain_limits)
    strict = emu.Solver(s, "fem", rtol_grad=1e-9).solve(load)
    assert emu.vertex_error(cut, strict) < 0.01


def test_emu_at_rest_with_bones_converges_at_once():
    """No load, the rest pose: an exact equilibrium whose gradient is the fit's
    round-off, lifted by the bones' ACAP weight (1e4) above the scale-based
    floor; it reported "stalled" after 21 iterations on elbow_wrap r=3 before
    the measured start floor (EmuSolver::rest_gradient_per_alpha_)."""
    scene = emu.scenes.elbow_wrap(3)
    sol = emu.Solver(scene, "emu").solve({"flexor": 0.0})
    assert sol.converged and sol.iterations == 0, sol.status
    assert sol.status == "converged: initial state is in equilibrium"
    assert emu.vertex_error(sol.positions, scene.points) < 1e-12


# ------------------------------------------------------------- EMU in joint coordinates
def _unknowns(solver, sol):
    """EMU's unknowns (#unknowns by 9, vec(F) column-major) from a Solution's F per scene tet."""
    core = solver._core
    tu = np.asarray(core.tet_unknown)
    F = np.zeros((core.num_unknowns, 9))
    for t in np.flatnonzero(tu >= 0):
        F[tu[t]] = sol.F[t].reshape(3, 3).ravel(order="F")
    return F


@pytest.mark.parametrize("scene", ["chain", "upper_limb"])
def test_emu_joint_coordinates_hessian_matches_the_tree_retraction(scene):
    """EMU's bones in joint coordinates: the retraction turns the tree and keeps
    every hinge between moving bones (the fit's bones stay rigid); its tangent
    at 0 is the direction; the Newton-Krylov Hessian (SO(3)'s and the chain's
    curvature) is the second derivative of the energy along it, and symmetric."""
    s = bone_chain_scene() if scene == "chain" else emu.anatomy.upper_limb(1)
    act = {m: 0.3 for m in s.muscles}
    solver = emu.Solver(s, "emu", alpha=100, max_iterations=4)
    assert solver.bone_coordinates == "joint coordinates"
    core = solver._core
    sol = solver.solve(act, normalized=True)
    load = solver.load_case(act, normalized=True)
    F = _unknowns(solver, sol)
    nu, nb = core.num_unknowns, len(s.movable_bones)
    rng = np.random.default_rng(11)
    for only_bones in (True, False):
        D = 1e-2 * rng.standard_normal((nu, 9))
        if only_bones:
            D[:-nb] = 0.0
        D = testing.project_tangent(core, F, D)
        np.testing.assert_allclose(testing.project_tangent(core, F, D), D, atol=1e-14 * np.abs(D).max())
        h = 1e-3
        Fp, Fm = testing.retract(core, F, D, h), testing.retract(core, F, D, -h)
        np.testing.assert_allclose((Fp - Fm) / (2 * h), D, atol=1e-7 * np.abs(D).max())
        E0, Ep, Em = (testing.energy(core, load, X) for X in (F, Fp, Fm))
        g = testing.gradient(core, load, F)
        # (the bones' Euclidean gradient carries the rigidity's large normal reaction: its round-off)
        assert abs((Ep - Em) / (2 * h) - np.sum(g * D)) <= 1e-5 * abs(np.sum(g * D)) + 1e-9 * np.abs(g).max()
        second = (Ep - 2 * E0 + Em) / h**2
        HD = testing.riemannian_hessian_product(core, load, F, D, True)
        assert abs(np.sum(D * HD) - second) <= 1e-5 * abs(second), (np.sum(D * HD), second)
        D2 = testing.project_tangent(core, F, rng.standard_normal((nu, 9)))
        a = np.sum(D2 * HD)
        b = np.sum(D * testing.riemannian_hessian_product(core, load, F, D2, True))
        assert abs(a - b) <= 1e-9 * (abs(a) + abs(b))
    if scene != "chain":   # the upper limb's joints are declared ones, not shared vertices
        return
    # a long step keeps every hinge between moving bones: both turn its axis alike
    F30 = testing.retract(core, F, D, 30.0)
    R = {b: F30[nu - nb + i].reshape(3, 3, order="F") for i, b in enumerate(s.movable_bones)}
    hinges = [j for j in s.joints() if len(j.vertices) == 2 and all(b in R for b in j.bones)]
    assert hinges
    for j in hinges:
        e = np.subtract(*s.points[j.vertices])
        a, c = (R[b] @ e for b in j.bones)
        assert np.linalg.norm(a - c) < 1e-12 * np.linalg.norm(e), j
    assert max(np.linalg.norm(R[b] - F[nu - nb + i].reshape(3, 3, order="F")) for i, b in enumerate(R)) > 0.1


def test_emu_chain_converges_like_fem_in_joint_coordinates():
    """The upper limb's chain without springs (issue 41's case: 114 Newton
    steps bone by bone): in joint coordinates EMU converges in a few tens, to
    the same answer as bone by bone, and the filtered fallback's rotation term
    is clamped (no step without it)."""
    s = emu.anatomy.upper_limb(1)
    for name in s.movable_bones:
        s.parts[name].joint_stiffness = 0.0
    act = {"biceps": 0.3}
    joint = emu.Solver(s, "emu", alpha=100).solve(act, normalized=True)
    per_bone_solver = emu.Solver(s, "emu", alpha=100, joint_coordinates=False)
    assert per_bone_solver.bone_coordinates == "per bone: joint_coordinates is off"
    per_bone = per_bone_solver.solve(act, normalized=True)
    assert joint.converged and per_bone.converged
    assert joint.iterations <= 40 < per_bone.iterations, (joint.iterations, per_bone.iterations)
    assert emu.vertex_error(joint, per_bone) < 2e-4


def test_emu_loop_of_joints_keeps_per_bone_rotations_and_says_so():
    s = bone_loop_scene()
    solver = emu.Solver(s, "emu", alpha=100)
    assert solver.bone_coordinates.startswith("per bone: ") and "loop" in solver.bone_coordinates
    sol = solver.solve({"m": 0.3}, normalized=True)
    assert sol.converged and sol.settings["bone_coordinates"] == solver.bone_coordinates


def test_fem_at_its_iteration_cap_names_a_weakly_resisted_turn():
    """The authors' biceps as a chain with a weak shoulder spring: strict FEM
    crawls along the humerus' nearly free turn; a solve that runs out of
    iterations says which bone's turn is nearly neutral, how weakly it is
    resisted, and what settles it. With a firm spring it converges and says
    nothing of the kind."""
    from conftest import shared_raw

    shared_raw()
    s = emu.io.load_scene(emu.datasets.path("realistic_biceps"), free_bones=["humerus", "forearm"], warn=False)
    s.parts["humerus"].joint_stiffness = 1.0
    sol = emu.solve(s, {"biceps": 2e3}, "fem", rtol_grad=1e-10, max_iterations=40)
    assert not sol.converged
    assert "the turn of movable bone 'humerus'" in sol.status and "near-neutral" in sol.status, sol.status
    assert "joint_stiffness" in sol.status
    s.parts["humerus"].joint_stiffness = 1e4
    firm = emu.solve(s, {"biceps": 2e3}, "fem", rtol_grad=1e-10, max_iterations=40)
    assert "near-neutral" not in firm.status, firm.status


def _two_shell_scene(with_shell: bool):
    """A fusiform muscle from a fixed bone to a movable one; with_shell: the
    movable bone has a second shell touching nothing (ulna + radius as one
    forearm), a copy of the first set beside the muscle."""
    from emu.build.procedural import fusiform
    m = fusiform(2, tendon_fraction=0.0)
    z = m.points[m.tets].mean(axis=1)[:, 2]
    lo, hi = 0.2 * m.length, 0.8 * m.length
    points, tets = m.points, m.tets
    distal = z > hi
    if with_shell:
        verts, local = np.unique(m.tets[distal], return_inverse=True)
        width = np.ptp(m.points[:, 0])
        points = np.vstack([m.points, m.points[verts] + [2.0 * width, 0.0, 0.0]])
        tets = np.vstack([m.tets, len(m.points) + local.reshape(-1, 4)])
    s = emu.Scene(points, tets, warn=False)
    pad = np.zeros(len(tets) - len(m.tets), bool)
    s.add_bone("proximal", np.concatenate([z < lo, pad]))
    s.add_bone("distal", np.concatenate([distal, ~pad]), fixed=False)
    s.add_muscle("belly", np.concatenate([(z >= lo) & (z <= hi), pad]))
    return s, len(m.points)


@pytest.mark.parametrize("method", ["fem", "emu"])
def test_a_bone_of_two_shells_moves_as_one(method):
    """A movable bone may be several shells (arm26's forearm: ulna + radius):
    a shell touching nothing is held by the bone it belongs to, not 'held by
    nothing'; it moves rigidly with the rest of the bone, and the answer on
    the rest of the mesh is the one without it (a rigid shell stores no
    energy)."""
    one, n = _two_shell_scene(False)
    two, _ = _two_shell_scene(True)
    act = {"belly": 0.5}
    ref = emu.solve(one, act, "fem", normalized=True, rtol_grad=1e-10)
    sol = emu.solve(two, act, method, normalized=True, **({"rtol_grad": 1e-10} if method == "fem" else {}))
    assert sol.converged, sol.status
    motion = bone_motion(two, sol, "distal")
    moved = np.linalg.norm(sol.positions[n:] - two.points[n:], axis=1)
    assert motion.rigidity < 1e-6 and moved.min() > 0.05 * emu.bbox_diagonal(one.points)   # one body, pulled
    tol = 1e-6 if method == "fem" else 0.01
    assert emu.vertex_error(sol.positions[:n], ref.positions) * emu.bbox_diagonal(two.points) \
        <= tol * emu.bbox_diagonal(one.points)


def test_a_joint_the_mesh_made_beside_a_declared_one_is_an_error(small_arm):
    """Bones that share vertices (the mesh fused them where they touch) and
    also have a declared joint: never a second joint beside the declared one
    (arm26 at its straight pose fused humerus and forearm at two vertices);
    the error names both bones, where, and the gap the mesh needs."""
    import copy
    s = copy.deepcopy(small_arm)
    (j,) = [j for j in s.joints() if set(j.bones) == {"humerus", "forearm"}]
    s.add_joint("forearm", "humerus", centre=j.centre + [0.0, 0.0, 0.1], axis=[1.0, 0.0, 0.0])
    for method in ("fem", "emu"):
        with pytest.raises(ValueError, match=r"bones 'humerus' and 'forearm' share \d+ vertex/vertices near "
                                             r"\[.*\] beside their declared hinge joint.*second hinge.*at least "
                                             r"[0-9.e-]+ apart"):
            emu.Solver(s, method)


def test_emu_refuses_a_loop_of_joints_in_accuracy_mode():
    """A loop of joints: FEM refuses it, so EMU's error estimate cannot exist
    and accuracy mode (EMU's default) refuses it too, naming the loop, FEM's
    fix and the way to solve it without an estimate (alpha=)."""
    s = bone_loop_scene()
    # joint_coordinates=False: the loop is still named (the bone forest's own reason, not the
    # coordinates' description)
    for kw in ({}, {"accuracy": 0.01}, {"joint_coordinates": False}):
        with pytest.raises(ValueError, match=r"accuracy mode needs FEM's error estimate.*'b' and 'c' close a "
                                             r"loop of joints.*give alpha= without accuracy"):
            emu.Solver(s, "emu", **kw)


def test_a_chained_bones_angle_is_about_its_own_joint():
    """The humerus of the upper limb hangs on the shoulder's ball joint and
    carries the elbow hinge: its angle is its whole turn (the deltoid raises
    it about 12 degrees at half activation), not its turn about the elbow's
    axis (0.2 degrees), which is the forearm's own joint."""
    s = emu.anatomy.upper_limb(1)
    assert emu.bones.own_joint(s, "humerus").kind == "ball"
    assert emu.bones.own_joint(s, "forearm").kind == "hinge"
    assert set(emu.bones.own_joint(s, "forearm").bones) == {"humerus", "forearm"}
    f = emu.Solver(s, "fem", rtol_grad=1e-9).solve({"deltoid": 0.5}, normalized=True)
    whole = emu.bone_motion(s, f.positions, "humerus").angle_deg
    assert whole > 5.0 and emu.bone_angle(s, f.positions, "humerus") == pytest.approx(whole)
    elbow = emu.bones.own_joint(s, "forearm")
    assert emu.bone_angle(s, f.positions, "forearm") == pytest.approx(
        emu.signed_angle(emu.bone_motion(s, f.positions, "forearm").R, elbow.axis))
