"""Implicit time steps (emu.Dynamics, solve_frames(..., dynamics=...)): inertia
as an incremental potential in FEM's Newton solve (energy/inertia.h).

The bar's first vibration against the mesh's own generalised eigenproblem
K v = w^2 M v (K: FEM's Newton matrix at rest, M: lumped masses computed here
from the rest volumes and densities), the quasi-static limit, the integrators'
velocities, and the errors a user meets. The inertia's derivatives with
movable bones are checked by finite differences in test_fem_rigid_bones.py."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

import emu
from emu._core import testing
from emu.build.procedural import block_mesh
from conftest import rest_geometry


def lumped_masses(scene) -> np.ndarray:
    """(n,) a quarter of each tet's mass (density x rest volume) at each of its vertices."""
    vol, _ = rest_geometry(scene.points, scene.tets)
    rho = np.zeros(len(scene.tets))
    for part in scene.parts.values():
        rho[part.tets] = part.density
    m = np.zeros(len(scene.points))
    np.add.at(m, scene.tets.ravel(), np.repeat(0.25 * rho * np.abs(vol), 4))
    return m


@pytest.fixture(scope="module")
def bar():
    """The small fusiform (pinned at one end), its free vertices, lumped mass
    rows M (3 per free vertex) and its first mode (period, M-normalised shape)."""
    scene = emu.scenes.fusiform(2, warn=False)
    solver = emu.Solver(scene, "fem", rtol_grad=1e-10)
    _, K = testing.reduced_system(solver._core, solver.load_case({}), scene.points, True)
    free = np.setdiff1d(np.arange(len(scene.points)), scene.pinned)
    M = np.repeat(lumped_masses(scene)[free], 3)
    w2, V = scipy.linalg.eigh(np.asarray(K), np.diag(M), subset_by_index=[0, 0])
    return scene, solver, free, M, 2 * np.pi / np.sqrt(w2[0]), V[:, 0]


def vibrate(bar, integrator, steps_per_period=100, periods=3):
    """The first mode's coordinate q = v^T M (x - X) over time, from a small
    displacement along it at rest: (q per step, the step)."""
    scene, solver, free, M, period, mode = bar
    amp = 1e-3 * np.abs(scene.points).max() / np.abs(mode).max()
    x0 = scene.points.copy()
    x0[free] += amp * mode.reshape(-1, 3)
    dyn = emu.Dynamics(period / steps_per_period, integrator)
    q = [(x0 - scene.points)[free].ravel() @ (M * mode)]
    for sol in emu.solve_frames(solver, [{}] * (steps_per_period * periods), dynamics=dyn,
                                state=emu.MotionState.at_rest(x0)):
        assert sol.converged and sol.velocities is not None
        q.append((sol.positions - scene.points)[free].ravel() @ (M * mode))
    return np.array(q), dyn.dt


def measured_period(q, dt):
    """Twice the mean spacing of q's zero crossings (linear interpolation)."""
    z = [k + q[k] / (q[k] - q[k + 1]) for k in range(len(q) - 1) if q[k] * q[k + 1] < 0]
    assert len(z) >= 4
    return 2 * np.mean(np.diff(z)) * dt


def test_bdf2_keeps_the_first_vibration_period_and_amplitude(bar):
    period = bar[4]
    q, dt = vibrate(bar, "bdf2")
    assert measured_period(q, dt) == pytest.approx(period, rel=0.02)
    # second order: after three periods at 100 steps each the amplitude is kept within 2%
    assert np.abs(q[-100:]).max() / abs(q[0]) == pytest.approx(1.0, abs=0.02)


def test_backward_euler_damps_the_vibration_at_the_same_period(bar):
    period = bar[4]
    q, dt = vibrate(bar, "backward_euler")
    assert measured_period(q, dt) == pytest.approx(period, rel=0.02)
    decay = np.abs(q[-100:]).max() / abs(q[0])   # first order: numerical damping (docs: about 0.67)
    assert 0.3 < decay < 0.9


def test_velocities_follow_the_integrators_formulas(bar):
    scene, solver = bar[0], bar[1]
    for integrator in ("backward_euler", "bdf2"):
        dyn = emu.Dynamics(0.05, integrator)
        sols = list(emu.solve_frames(solver, [{"belly": 3e4}] * 3, dynamics=dyn))
        x = [scene.points] + [s.positions for s in sols]
        assert np.allclose(sols[0].velocities, (x[1] - x[0]) / dyn.dt)   # the first step: backward Euler's
        expected = (x[2] - x[1]) / dyn.dt if integrator == "backward_euler" else \
            (3 * x[2] - 4 * x[1] + x[0]) / (2 * dyn.dt)
        assert np.allclose(sols[1].velocities, expected)
        assert np.abs(sols[1].velocities).max() > 0


def test_the_quasi_static_limit_gives_the_equilibrium():
    # massless parts: no inertia, each step is the equilibrium to round-off;
    # an enormous step: the inertia's weight 1/h^2 vanishes against the stiffness
    act = {"belly": 5e4}
    massless = emu.scenes.fusiform(2, warn=False)
    for part in massless.parts.values():
        part.density = 0.0
    for scene, dt, tol in ((massless, 0.01, 1e-12), (emu.scenes.fusiform(2, warn=False), 1e6, 1e-6)):
        solver = emu.Solver(scene, "fem", rtol_grad=1e-10)
        static = solver.solve(act)
        step = next(emu.solve_frames(solver, [act], dynamics=emu.Dynamics(dt)))
        assert step.converged
        assert emu.vertex_error(step.positions, static.positions) < tol


def test_mass_damping_lowers_the_vibration_further(bar):
    scene, solver, free, M, period, mode = bar
    amp = 1e-3 * np.abs(scene.points).max() / np.abs(mode).max()
    x0 = scene.points.copy()
    x0[free] += amp * mode.reshape(-1, 3)
    ends = []
    for c in (0.0, 0.2):
        dyn = emu.Dynamics(period / 50, "bdf2", mass_damping=c)
        *_, last = emu.solve_frames(solver, [{}] * 100, dynamics=dyn, state=emu.MotionState.at_rest(x0))
        ends.append(np.abs(last.velocities).max() + np.abs(last.positions - scene.points).max() / period)
    # c = 0.2 / s over two periods of 13.7 s: the amplitude falls by about exp(-c t / 2) = 0.06
    assert ends[1] < 0.2 * ends[0]


def test_bad_dynamics_input_is_named():
    scene = emu.scenes.fusiform(2, warn=False)
    with pytest.raises(ValueError, match="dt must be a positive"):
        emu.Dynamics(0.0)
    with pytest.raises(ValueError, match="integrator must be one of"):
        emu.Dynamics(0.01, "rk4")
    with pytest.raises(ValueError, match="mass_damping must be >= 0"):
        emu.Dynamics(0.01, mass_damping=-1.0)
    fem = emu.Solver(scene, "fem")
    with pytest.raises(ValueError, match=r"predicted positions must be a finite \(81, 3\) array"):
        fem.solve({}, inertia=(1.0, np.zeros((3, 3))))
    with pytest.raises(ValueError, match="weight must be finite and >= 0"):
        fem.solve({}, inertia=(-1.0, scene.points))
    with pytest.raises(ValueError, match="velocities must be a finite array"):
        emu.MotionState.at_rest(scene.points, np.zeros((2, 3)))
    x = scene.points
    with pytest.raises(ValueError, match="both previous_positions and previous_velocities"):
        emu.MotionState(x, 0 * x, previous_positions=x)
    with pytest.raises(ValueError, match="needs dynamics=emu.Dynamics"):
        next(emu.solve_frames(fem, [{}], state=emu.MotionState.at_rest(x)))
    with pytest.raises(TypeError, match="initial must be a Solution"):
        next(emu.solve_frames(fem, [{}], initial=x, dynamics=emu.Dynamics(0.01)))
    with pytest.raises(ValueError, match="dt must be a positive"):
        emu.Dynamics(True)
    assert emu.Dynamics(np.float32(0.5)).dt == np.float32(0.5)
    # a run of time steps with EMU names FEM (measured slower per step), none with FEM
    from emu.solve.advice import method_hint
    assert "method='fem'" in method_hint(scene, "emu", sequence=True, dynamics=True)
    assert method_hint(scene, "fem", sequence=True, dynamics=True) is None


SCENE_FILE = """
pins = ["proximal"]

[mesh.fusiform]
tets = 300

[solver]
method = "{method}"

[frames]
count = 4
dt = 0.1

[dynamics]
integrator = "backward_euler"
mass_damping = 0.5

[activation.belly]
keys = [[0.0, 0.0], [0.3, 1.0]]
normalized = true

[output]
obj = false
preview = false
"""


def test_a_scene_file_runs_time_steps_and_writes_velocities(tmp_path):
    import json
    import meshio
    path = tmp_path / "jiggle.toml"
    path.write_text(SCENE_FILE.format(method="fem"))
    spec = emu.load_scene_file(path)
    assert spec.dynamics == emu.Dynamics(0.1, "backward_euler", 0.5)
    log = emu.run_scene(spec, str(tmp_path / "out"), progress=lambda *_: None)
    x = [spec.scene.points] + [meshio.read(tmp_path / "out" / f"frame_{k:04d}.vtu").points for k in range(4)]
    for k in range(1, 5):
        v = meshio.read(tmp_path / "out" / f"frame_{k - 1:04d}.vtu").point_data["velocity"]
        assert np.allclose(v, (x[k] - x[k - 1]) / 0.1, atol=1e-9 * np.abs(v).max())   # backward Euler's
        assert log["frames"][k - 1]["max_speed"] == pytest.approx(np.linalg.norm(v, axis=1).max())
    assert json.loads((tmp_path / "out" / "log.json").read_text())["frames"][-1]["max_speed"] > 0
    path.write_text(SCENE_FILE.format(method="emu"))   # EMU's steps too
    log = emu.run_scene(emu.load_scene_file(path), str(tmp_path / "emu"), progress=lambda *_: None)
    assert all(f["converged"] for f in log["frames"]) and log["frames"][-1]["max_speed"] > 0
    path.write_text(SCENE_FILE.format(method="fem").replace('"backward_euler"', '"leapfrog"'))
    with pytest.raises(emu.SceneFileError, match="integrator must be one of"):
        emu.load_scene_file(path)


def test_a_forearm_swings_under_gravity_and_energy_never_rises():
    # the arm released from its rest shape under gravity: the forearm (a rigid
    # body on its hinge) swings about the static angle; BDF2 keeps the swing,
    # backward Euler damps it out, and neither gains energy (elastic, gravity's,
    # kinetic with the lumped masses) over its start
    scene = emu.scenes.arm(1)
    scene.gravity = np.array([0.0, -9.81, 0.0])
    m = lumped_masses(scene)
    solver = emu.Solver(scene, "fem", rtol_grad=1e-10)
    load = solver.load_case({})
    static = emu.bone_angle(scene, solver.solve({}).positions, "forearm")
    e0 = testing.energy(solver._core, load, scene.points)
    ranges = {}
    for integrator in ("backward_euler", "bdf2"):
        angles = []
        for sol in emu.solve_frames(solver, [{}] * 100, dynamics=emu.Dynamics(0.005, integrator)):
            assert sol.converged
            e = testing.energy(solver._core, load, sol.positions) + 0.5 * np.sum(m[:, None] * sol.velocities ** 2)
            assert e <= e0 + 1e-9 * abs(e0)
            angles.append(emu.bone_angle(scene, sol.positions, "forearm"))
        assert min(angles) < static < max(angles)   # it passes the static angle
        ranges[integrator] = np.ptp(angles[-25:]) / np.ptp(angles[:25])
    assert ranges["bdf2"] > 0.8   # (docs: 0.96 at this step)
    assert ranges["backward_euler"] < 0.3 * ranges["bdf2"]


def test_emu_inertia_through_the_fit_matches_finite_differences():
    # EMU's positions are the fit x*(F): the inertia (w / 2) |x*(F) - y|^2_M
    # has gradient J^T w M (x - y) and Hessian J^T w M J (fit_jacobian.h), with
    # a movable forearm's unknown too
    scene = emu.scenes.arm(1)
    solver = emu.Solver(scene, "emu", alpha=100, error_estimate=False)
    core = solver._core
    load = solver.load_case({"flexor": 0.5}, normalized=True)
    nu = core.num_unknowns
    rng = np.random.default_rng(5)
    F = np.tile(np.eye(3).ravel(), (nu, 1)) + 0.02 * rng.standard_normal((nu, 9))
    plain = testing.hessian_product(core, load, F, F - np.eye(3).ravel(), True)
    m = lumped_masses(scene)
    load.inertia_weight = 0.1 * np.abs(plain).max() / m.max()
    load.inertia_target = scene.points + 0.01 * rng.standard_normal(scene.points.shape)
    products = {}
    for only_bone in (False, True):
        D = rng.standard_normal((nu, 9))
        if only_bone:
            D[:-1] = 0.0   # the forearm is the last unknown
        h = 1e-6
        g = testing.gradient(core, load, F)
        fd = (testing.energy(core, load, F + h * D) - testing.energy(core, load, F - h * D)) / (2 * h)
        assert abs(fd - np.sum(g * D)) <= 1e-6 * abs(fd) + 1e-9
        Hd = testing.hessian_product(core, load, F, D, True)
        fdH = (testing.gradient(core, load, F + h * D) - testing.gradient(core, load, F - h * D)) / (2 * h)
        assert np.abs(fdH - Hd).max() <= 1e-5 * np.abs(fdH).max()
        products[only_bone] = D, fdH
    # the inertia is a real share of the product (the soft rows of a soft direction)
    D, fdH = products[False]
    load.inertia_weight = 0.0
    H0 = testing.hessian_product(core, load, F, D, True)
    assert np.abs(fdH - H0)[:-1].max() > 1e-2 * np.abs(fdH[:-1]).max()


def test_emu_time_steps_match_fem_steps_from_the_same_state():
    # each EMU step (accuracy mode) against FEM's strict step from the same
    # state (positions, velocities): within the accuracy, its estimate certified
    scene = emu.scenes.fusiform(2, warn=False)
    dyn = emu.Dynamics(0.5)
    fem = emu.Solver(scene, "fem", rtol_grad=1e-10)
    solver = emu.Solver(scene, "emu", accuracy=0.01)
    state, prev = emu.MotionState.at_rest(scene.points), None
    for act in [{"belly": 5e4}] * 6 + [{}] * 6:
        inertia = dyn.inertia(state)
        prev = solver.solve(act, initial=prev, inertia=inertia)
        ref = fem.solve(act, initial=state.positions, inertia=inertia)
        assert prev.converged and ref.converged
        assert emu.vertex_error(prev.positions, ref.positions) < 0.01
        assert prev.error_estimate is not None and prev.error_estimate < 0.01
        state = dyn.advance(state, prev.positions)
    assert np.abs(state.velocities).max() > 0


def test_vertex_masses_are_the_solvers_masses():
    # emu.vertex_masses: the lumped masses the solvers' inertia uses, read back
    # from FEM's incremental potential: (w / 2) sum over moving vertices of
    # m_v |x_v - y_v|^2 (the forearm's vertices move with it, the humerus' not)
    scene = emu.scenes.arm(1)
    m = emu.vertex_masses(scene)
    np.testing.assert_allclose(m, lumped_masses(scene), rtol=1e-12)
    assert m.sum() == pytest.approx(sum(p.density * np.abs(rest_geometry(scene.points, scene.tets[p.tets])[0]).sum()
                                        for p in scene.parts.values()), rel=1e-12)
    solver = emu.Solver(scene, "fem")
    load = solver.load_case({})
    rng = np.random.default_rng(8)
    d = 1e-3 * rng.standard_normal(scene.points.shape)
    plain = testing.energy(solver._core, load, scene.points)
    load.inertia_weight, load.inertia_target = 7.0, scene.points + d
    moving = np.ones(len(m), bool)
    moving[scene.pinned] = False
    for p in scene.parts.values():
        if p.kind == "bone" and p.fixed:
            moving[np.unique(scene.tets[p.tets])] = False
    want = 0.5 * 7.0 * np.sum(m[moving] * np.sum(d[moving] ** 2, axis=1))
    assert testing.energy(solver._core, load, scene.points) - plain == pytest.approx(want, rel=1e-9)


def _dropped_bone():
    """A fixed block, a passive muscle block, and a bone on no joint (six
    degrees of freedom) hanging from it, under gravity."""
    pts, tets, lab = block_mesh({"base": [(0, 0, 0)], "m": [(1, 0, 0)], "loose": [(2, 0, 0)]}, 2)
    scene = emu.Scene(pts, tets, warn=False)
    scene.add_bone("base", lab == 0)
    scene.add_muscle("m", lab == 1, [1.0, 0.3, 0.1])
    scene.add_bone("loose", lab == 2, fixed=False)
    scene.gravity = [0.0, -9.81, 0.0]
    return scene


def test_a_dropped_bone_loses_energy_only_at_the_integrators_order():
    # Undamped, a time step's energy loss is the integrator's own: over half a
    # second of a bone dropped on a muscle, halving the step halves backward
    # Euler's loss (first order) and quarters BDF2's (second order), and the
    # energy (elastic, gravity's, kinetic) never rises above its start
    scene = _dropped_bone()
    m = emu.vertex_masses(scene)
    solver = emu.Solver(scene, "fem", rtol_grad=1e-10)
    load = solver.load_case({})

    def energy(x, v):
        return testing.energy(solver._core, load, x) + 0.5 * np.sum(m[:, None] * v ** 2)
    e0 = energy(scene.points, np.zeros_like(scene.points))
    motion = e0 - testing.energy(solver._core, load, solver.solve({}).positions)
    lost = {}
    for integrator in ("backward_euler", "bdf2"):
        for dt in (0.01, 0.005):
            energies = [energy(s.positions, s.velocities) for s in
                        emu.solve_frames(solver, [{}] * int(round(0.5 / dt)), dynamics=emu.Dynamics(dt, integrator))]
            assert max(energies) <= e0 + 1e-9 * motion
            lost[integrator, dt] = (e0 - energies[-1]) / motion
    assert 0.4 <= lost["backward_euler", 0.005] / lost["backward_euler", 0.01] <= 0.6
    assert 0.15 <= lost["bdf2", 0.005] / lost["bdf2", 0.01] <= 0.35
    assert lost["bdf2", 0.01] < 0.2 * lost["backward_euler", 0.01]
