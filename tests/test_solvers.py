"""Solvers end to end: rest state, FEM against an independent numpy Newton,
EMU converging to FEM as alpha grows, the two EMU steps agreeing, input
validation, mesh repair, histories and emu.info()."""
import warnings

import numpy as np
import pytest
import scipy.linalg as sl

import emu
from emu._core import testing
from emu.build.procedural import fusiform

from conftest import gradient_operator, small_scene


# ------------------------------------------------------------------ rest state
@pytest.mark.parametrize("method,options", [("fem", {}), ("emu", {}), ("emu", {"step": "woodbury"})])
@pytest.mark.parametrize("activation", [{}, None, {"belly": 0.0}])
@pytest.mark.parametrize("tendons", [True, False], ids=["with_tendons", "muscle_only"])
def test_rest_state_without_load(method, options, activation, tendons):
    s, m = small_scene(2, tendon_fraction=0.12 if tendons else 0.0)
    sol = emu.solve(s, activation, method, **options)
    assert sol.converged, sol.status
    assert sol.iterations == 0
    diag = emu.bbox_diagonal(s.points)
    assert np.abs(sol.positions - s.points).max() <= 1e-12 * diag
    assert len(sol.history["energy"]) == 1
    if method == "emu":
        np.testing.assert_allclose(sol.F, np.tile(np.eye(3), (len(s.tets), 1, 1)), atol=1e-12)


# ------------------------------------------- an independent FEM in numpy/scipy
def snh_numpy(F, mu, lam, hessian=False):
    """Stable Neo-Hookean per tet (docs/METHOD.md, 2. Materials, rest value subtracted):
    energy (m,), stress (m, 3, 3) and optionally the 9x9 Hessians in the
    column-major vec(F) layout (m, 9, 9)."""
    beta = 1.0 + 0.75 * mu / lam
    ic = np.einsum("tij,tij->t", F, F)
    J = np.linalg.det(F)
    cof = np.stack([np.cross(F[:, :, 1], F[:, :, 2]), np.cross(F[:, :, 2], F[:, :, 0]),
                    np.cross(F[:, :, 0], F[:, :, 1])], axis=2)  # column j of cof = dJ/dF column j
    rest = 0.5 * lam * (1 - beta) ** 2 - 0.5 * mu * np.log(4.0)
    e = 0.5 * mu * (ic - 3) + 0.5 * lam * (J - beta) ** 2 - 0.5 * mu * np.log(ic + 1) - rest
    P = (mu * (1 - 1 / (ic + 1)))[:, None, None] * F + (lam * (J - beta))[:, None, None] * cof
    if not hessian:
        return e, P
    m = len(F)
    f = F.transpose(0, 2, 1).reshape(m, 9)
    g = cof.transpose(0, 2, 1).reshape(m, 9)
    H = (mu * (1 - 1 / (ic + 1)))[:, None, None] * np.eye(9)
    H = H + (2 * mu / (ic + 1) ** 2)[:, None, None] * np.einsum("ti,tj->tij", f, f)
    H = H + lam * np.einsum("ti,tj->tij", g, g)
    # d2J: block (a, b) (columns a, b of F) = sum_c eps_abc [f_c]_x
    s = lam * (J - beta)

    def cross(v):  # (m, 3) -> (m, 3, 3)
        z = np.zeros(len(v))
        return np.stack([np.stack([z, -v[:, 2], v[:, 1]], 1), np.stack([v[:, 2], z, -v[:, 0]], 1),
                         np.stack([-v[:, 1], v[:, 0], z], 1)], 1)

    for a, b, c, sign in [(0, 1, 2, 1), (1, 2, 0, 1), (2, 0, 1, 1), (1, 0, 2, -1), (2, 1, 0, -1), (0, 2, 1, -1)]:
        H[:, 3 * a:3 * a + 3, 3 * b:3 * b + 3] -= sign * s[:, None, None] * cross(F[:, :, c])
    return e, P, H


def test_numpy_reference_material_finite_differences():
    """The reference itself: stress and Hessian are derivatives of its energy."""
    rng = np.random.default_rng(0)
    F = np.eye(3) + 0.3 * rng.standard_normal((4, 3, 3))
    F[0, :, 0] *= -1  # one inverted
    mu, lam = 2e4, 1e6
    e, P, H = snh_numpy(F, mu, lam, hessian=True)
    h = 1e-6
    for idx in range(9):
        i, j = idx % 3, idx // 3
        dF = np.zeros((3, 3))
        dF[i, j] = h
        ep, Pp = snh_numpy(F + dF, mu, lam)
        em, Pm = snh_numpy(F - dF, mu, lam)
        np.testing.assert_allclose((ep - em) / (2 * h), P[:, i, j], rtol=1e-6, atol=1e-3)
        dP = ((Pp - Pm) / (2 * h)).transpose(0, 2, 1).reshape(-1, 9)
        np.testing.assert_allclose(dP, H[:, :, idx], rtol=0, atol=1e-6 * np.abs(H).max())


class NumpyFEM:
    """E(x) = sum_t V_t [Psi_SNH(F_t) + a/2 |F_t u_t|^2] - sum_v m_v g . x_v over the free vertices."""

    def __init__(self, points, tets, fibers, youngs, poisson, activation, pinned, density=1060.0,
                 gravity=(0, 0, 0)):
        self.X, self.T = points, tets
        G, vol = gradient_operator(points, tets)
        self.G, self.vol = G.tocsr(), vol
        self.mu = youngs / (2 * (1 + poisson))
        self.lam = youngs * poisson / ((1 + poisson) * (1 - 2 * poisson))
        self.a, self.u = activation, fibers
        n = len(points)
        self.free = np.setdiff1d(np.arange(n), pinned)
        self.fdof = (3 * self.free[:, None] + np.arange(3)).ravel()
        mass = np.zeros(n)
        np.add.at(mass, tets.ravel(), np.repeat(0.25 * density * vol, 4))
        self.force = (mass[:, None] * np.asarray(gravity, float)[None, :]).ravel()
        # fibre Hessian a (u u^T kron I3) per tet, in the column-major vec(F) layout
        self.UU = np.einsum("tij,kl->tikjl", np.einsum("ti,tj->tij", fibers, fibers), np.eye(3)).reshape(-1, 9, 9)

    def _F(self, x):
        return (self.G @ x).reshape(-1, 3, 3).transpose(0, 2, 1)

    def energy(self, x):
        F = self._F(x)
        e, _ = snh_numpy(F, self.mu, self.lam)
        fib = 0.5 * self.a * np.einsum("tij,tj->ti", F, self.u) ** 2
        return np.sum(self.vol * (e + fib.sum(1))) - self.force @ x

    def gradient(self, x):
        F = self._F(x)
        _, P = snh_numpy(F, self.mu, self.lam)
        Fu = np.einsum("tij,tj->ti", F, self.u)
        P = P + self.a * np.einsum("ti,tj->tij", Fu, self.u)
        return self.G.T @ (self.vol[:, None] * P.transpose(0, 2, 1).reshape(-1, 9)).ravel() - self.force

    def hessian(self, x, project):
        F = self._F(x)
        _, _, H = snh_numpy(F, self.mu, self.lam, hessian=True)
        if project:
            w, Q = np.linalg.eigh(H)
            H = np.einsum("tij,tj,tkj->tik", Q, np.maximum(w, 0), Q)
        H = (H + self.a * self.UU) * self.vol[:, None, None]
        import scipy.sparse as sp
        Hb = sp.block_diag(list(H), format="csr")
        return (self.G.T @ Hb @ self.G).toarray()

    def solve(self, x0, gtol=1e-10, max_iterations=100):
        """Newton: the exact Hessian where it is definite, else projected; Armijo
        backtracking (full exact steps once they are under 1e-8 of the mesh
        size, where the energy is at round-off). Stops on |g| <= gtol |g0| or on
        an exact step below 1e-13 of the mesh size (round-off)."""
        x = x0.ravel().copy()
        fd = self.fdof
        g0 = np.linalg.norm(self.gradient(x)[fd])
        diag = np.linalg.norm(np.ptp(self.X, axis=0))
        for it in range(max_iterations):
            g = self.gradient(x)[fd]
            if np.linalg.norm(g) <= gtol * g0:
                return x.reshape(-1, 3), it
            exact = True
            H = self.hessian(x, project=False)[np.ix_(fd, fd)]
            try:
                c = sl.cho_factor(H)
            except np.linalg.LinAlgError:
                c = sl.cho_factor(self.hessian(x, project=True)[np.ix_(fd, fd)])
                exact = False
            d = -sl.cho_solve(c, g)
            if exact and np.abs(d).max() < 1e-13 * diag:
                return x.reshape(-1, 3), it
            if exact and np.abs(d).max() < 1e-8 * diag:
                # Newton's local regime: this energy (evaluated as written, with
                # O(eps lambda) round-off) can no longer rank steps this short, and
                # the full exact step converges quadratically.
                x[fd] += d
                continue
            E0, slope, s = self.energy(x), g @ d, 1.0
            assert slope < 0
            while True:
                xn = x.copy()
                xn[fd] += s * d
                if self.energy(xn) <= E0 + 1e-4 * s * slope or s < 1e-12:
                    break
                s *= 0.5
            x = xn
        raise AssertionError(f"numpy Newton did not converge: |g|/|g0| = {np.linalg.norm(g) / g0:.2e}")


@pytest.mark.parametrize("activation,gravity,pin", [(5e4, (0, 0, 0), "proximal"),
                                                    (2e4, (0, -0.5, 0), "both"),
                                                    (0.0, (0.0, -0.05, 0.0), "proximal")])
def test_fem_matches_independent_newton(activation, gravity, pin):
    m = fusiform(3, tendon_fraction=0)
    s = emu.Scene(m.points, m.tets)
    s.add_muscle("belly", np.arange(len(m.tets)), m.fibers, youngs=6e4, poisson=0.49, density=1060.0)
    pins = m.proximal if pin == "proximal" else np.concatenate([m.proximal, m.distal])
    s.pin(pins)
    sol = emu.solve(s, {"belly": activation}, "fem", gravity=list(gravity), rtol_grad=1e-7)
    assert sol.converged, sol.status
    ref = NumpyFEM(m.points, m.tets, m.fibers, 6e4, 0.49, activation, pins, gravity=gravity)
    x, its = ref.solve(m.points)
    moved = np.abs(x - m.points).max() / emu.bbox_diagonal(m.points)
    assert moved > 1e-3, "the load case must deform the mesh for the test to mean anything"
    assert emu.vertex_error(sol.positions, x, m.points) < 1e-6
    # the FEM energy function agrees with the reference up to a constant (rest offsets)
    solver = emu.Solver(s, "fem")
    load = solver.load_case({"belly": activation}, gravity=list(gravity))
    dE = testing.energy(solver._core, load, x) - testing.energy(solver._core, load, m.points)
    assert dE == pytest.approx(ref.energy(x.ravel()) - ref.energy(m.points.ravel()), rel=1e-9)
    assert abs(dE) > 0


# --------------------------------------------------------- EMU converges to FEM
def test_emu_approaches_fem_as_alpha_grows():
    s, m = small_scene(2)
    act = {"belly": 5e4}
    fem = emu.solve(s, act, "fem", rtol_grad=1e-7)
    assert fem.converged
    errors = []
    for alpha in [1.0, 10.0, 100.0, 1e3, 1e4]:
        sol = emu.solve(s, act, "emu", alpha=alpha)
        assert sol.converged, (alpha, sol.status)
        errors.append(emu.vertex_error(sol, fem))
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 1e-2 * errors[0]  # over four decades of alpha the error falls by > 100x
    assert errors[-1] < 1e-2
    assert errors[0] > 1e-3  # and alpha matters: the smallest alpha is visibly off


def test_emu_steps_agree_on_a_tiny_case():
    s, m = small_scene(1, tendon_fraction=0)
    act = {"belly": 5e4}
    nk = emu.solve(s, act, "emu", alpha=10.0, modes=24, rtol_grad=1e-10)
    wb = emu.solve(s, act, "emu", alpha=10.0, modes=24, step="woodbury", rtol_grad=1e-8, max_iterations=5000)
    assert nk.converged, nk.status
    assert wb.converged, wb.status
    assert wb.iterations > nk.iterations
    assert emu.vertex_error(wb, nk) < 1e-5
    np.testing.assert_allclose(wb.F, nk.F, atol=1e-4)
    moved = emu.vertex_error(nk.positions, s.points)
    assert moved > 1e-2


# ------------------------------------------------------------------- bad input
def mesh2():
    m = fusiform(2)
    return m.points.copy(), m.tets.copy(), m


def test_nan_points():
    p, t, _ = mesh2()
    p[5, 1] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        emu.Scene(p, t)


def test_out_of_range_tet_index():
    p, t, _ = mesh2()
    t[3, 2] = len(p)
    with pytest.raises(ValueError, match=r"tet indices must lie in \[0, "):
        emu.Scene(p, t)
    t[3, 2] = -1
    with pytest.raises(ValueError, match="tet indices"):
        emu.Scene(p, t)


@pytest.mark.parametrize("shape_case", ["points_2d", "points_1d", "tets_3"])
def test_wrong_shapes(shape_case):
    p, t, _ = mesh2()
    if shape_case == "points_2d":
        with pytest.raises(ValueError, match=r"points must have shape \(n, 3\)"):
            emu.Scene(p[:, :2], t)
    elif shape_case == "points_1d":
        with pytest.raises(ValueError, match=r"points must have shape"):
            emu.Scene(p.ravel(), t)
    else:
        with pytest.raises(ValueError, match=r"tets must have shape \(m, 4\)"):
            emu.Scene(p, t[:, :3])


def test_empty_part():
    p, t, m = mesh2()
    s = emu.Scene(p, t)
    with pytest.raises(ValueError, match="has no tets"):
        s.add_muscle("belly", [], np.zeros((0, 3)))
    with pytest.raises(ValueError, match="has no tets"):
        s.add_tendon("t", np.zeros(len(t), bool))


def test_wrong_fibers_shape():
    p, t, m = mesh2()
    s = emu.Scene(p, t)
    with pytest.raises(ValueError, match="fibers must have shape"):
        s.add_muscle("belly", ~m.is_tendon, m.fibers)  # one row per tet of the mesh, not of the part
    with pytest.raises(ValueError, match="fibers must have shape"):
        s.add_muscle("belly", ~m.is_tendon, np.ones((int((~m.is_tendon).sum()), 2)))
    with pytest.raises(ValueError, match="fibre direction"):
        s.add_muscle("belly", ~m.is_tendon, np.zeros(3))
    # no fibres and no bones to take them from: the solve says what to pass
    s.add_muscle("belly", ~m.is_tendon)
    s.add_tendon("tendons", m.is_tendon)
    s.pin(m.proximal)
    with pytest.raises(ValueError, match=r"no fibres and 0 bone attachment\(s\).*fibers="):
        emu.solve(s, {"belly": 1e4}, "fem")


def test_unanchored_scene():
    p, t, m = mesh2()
    s = emu.Scene(p, t)
    s.add_muscle("belly", np.arange(len(t)), m.fibers)
    for method in ("fem", "emu"):
        with pytest.raises(ValueError, match="not anchored"):
            emu.solve(s, {"belly": 1e4}, method)


def test_loose_component_without_pin():
    p, t, m = mesh2()
    p2 = np.vstack([p, p + [5.0, 0, 0]])
    t2 = np.vstack([t, t + len(p)])
    s = emu.Scene(p2, t2)
    s.add_muscle("belly", np.arange(len(t)), m.fibers)
    s.add_muscle("stray", len(t) + np.arange(len(t)), m.fibers)
    s.pin(m.proximal)  # only the first copy
    with pytest.raises(ValueError, match=r"'stray' is held by nothing .*pins = \[\"stray\"\]"):
        emu.Solver(s, "fem")
    s.pin(m.proximal + len(p))
    emu.Solver(s, "fem")  # both pinned: fine


def test_activation_errors():
    s, m = small_scene(2)
    solver = emu.Solver(s, "fem")
    with pytest.raises(ValueError, match="unknown muscle 'biceps'"):
        solver.solve({"biceps": 1e4})
    with pytest.raises(ValueError, match="must be finite and >= 0"):
        solver.solve({"belly": -1.0})
    with pytest.raises(ValueError, match="must be finite and >= 0"):
        solver.solve({"belly": np.nan})
    with pytest.raises(ValueError, match=r"must lie in \[0, 1\]"):
        solver.solve({"belly": 2.0}, normalized=True)
    with pytest.raises(TypeError, match="must be a dict"):
        solver.solve([1e4])


def test_tets_of_no_part():
    p, t, m = mesh2()
    s = emu.Scene(p, t)
    s.add_muscle("belly", ~m.is_tendon, m.fibers[~m.is_tendon])  # tendon tets left unlabelled
    s.pin(m.proximal)
    with pytest.raises(ValueError, match="belong to no part"):
        emu.solve(s, {"belly": 1e4}, "fem")


def test_other_bad_input():
    s, m = small_scene(2)
    with pytest.raises(ValueError, match="already belong to part 'belly'"):
        s.add_tendon("again", ~m.is_tendon)
    with pytest.raises(ValueError, match="method must be one of"):
        emu.Solver(s, "xfem")
    with pytest.raises(ValueError, match="alpha must be a positive number"):
        emu.Solver(s, "emu", alpha=-1.0)
    with pytest.raises(ValueError, match="step must be one of"):
        emu.Solver(s, "emu", step="gauss-newton")
    with pytest.raises(ValueError, match="eigen_filter must be one of"):
        emu.Solver(s, "fem", eigen_filter="flip")
    with pytest.raises(ValueError, match="pin: vertex ids"):
        s.pin([len(s.points)])
    with pytest.raises(ValueError, match="repeat a vertex"):
        p, t, _ = mesh2()
        t[0, 1] = t[0, 0]
        emu.Scene(p, t)
    # the C++ core rejects wrongly shaped arrays with a message, not a crash
    solver = emu.Solver(s, "emu", alpha=100.0, modes=6)
    load = solver.load_case({"belly": 1e4})
    F = np.tile(np.eye(3).flatten(order="F"), (len(s.tets), 1))
    with pytest.raises(ValueError, match="by 9"):
        testing.gradient(solver._core, load, F[:, :8])
    F[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        testing.energy(solver._core, load, F)


@pytest.mark.parametrize("method", ["fem", "emu"])
def test_eigen_filters_reach_the_same_equilibrium(method):
    """Reflecting negative eigenvalues (eigen_filter="abs") instead of clamping
    them changes the path, not the answer: both to the strict tolerance agree to
    the solver tolerance, and the abs run did need filtered steps."""
    s, _ = small_scene(2)
    kw = dict(alpha=100.0) if method == "emu" else {}
    a = emu.Solver(s, method, rtol_grad=1e-9, **kw).solve({"belly": 1e5})
    b = emu.Solver(s, method, rtol_grad=1e-9, eigen_filter="abs", **kw).solve({"belly": 1e5})
    assert a.converged and b.converged and b.settings["eigen_filter"] == "abs"
    assert emu.vertex_error(a.positions, b.positions) < 1e-6
    assert not np.array_equal(a.history["energy"], b.history["energy"])   # the filter did act


def test_negative_volume_tet_is_reoriented():
    p, t, m = mesh2()
    flipped = t.copy()
    flipped[7] = flipped[7][[1, 0, 2, 3]]
    with pytest.warns(emu.MeshWarning, match="reoriented"):
        s = emu.Scene(p, flipped)
    np.testing.assert_array_equal(s.mesh_report.reoriented, [7])
    q = s.points[s.tets[7]]
    assert np.dot(q[1] - q[0], np.cross(q[2] - q[0], q[3] - q[0])) > 0
    assert sorted(s.tets[7]) == sorted(t[7])
    # and it solves exactly like the mesh that was right to begin with
    s.add_muscle("belly", ~m.is_tendon, m.fibers[~m.is_tendon])
    s.add_tendon("tendons", m.is_tendon)
    s.pin(m.proximal)
    ref, _ = small_scene(2)
    a = emu.solve(s, {"belly": 5e4}, "fem")
    b = emu.solve(ref, {"belly": 5e4}, "fem")
    assert emu.vertex_error(a, b) < 1e-10


def test_clean_mesh_gives_no_warning():
    p, t, _ = mesh2()
    with warnings.catch_warnings():
        warnings.simplefilter("error", emu.MeshWarning)
        s = emu.Scene(p, t)
    assert len(s.mesh_report.reoriented) == 0


# --------------------------------------------------------------------- history
@pytest.mark.parametrize("method,options", [("fem", {}), ("emu", {"alpha": 100.0}),
                                            ("emu", {"alpha": 10.0, "step": "woodbury", "max_iterations": 300})])
def test_history(method, options):
    s, m = small_scene(2)
    sol = emu.solve(s, {"belly": 5e4}, method, **options)
    h = sol.history
    assert set(h) >= {"energy", "grad_norm", "time_s", "step", "cg_iterations", "backtracks", "iteration"}
    n = sol.iterations + 1
    assert sol.iterations > 0
    for k, v in h.items():
        assert len(v) == n, k
    np.testing.assert_array_equal(h["iteration"], np.arange(n))
    E = h["energy"]
    assert np.all(np.diff(E) <= 1e-12 * np.abs(E).max()), np.diff(E).max()
    assert E[-1] < E[0]
    assert np.all(np.diff(h["time_s"]) >= 0)
    assert h["grad_norm"][0] == pytest.approx(sol.grad_norm0)
    assert h["grad_norm"][-1] == pytest.approx(sol.grad_norm)
    assert sol.energy == pytest.approx(E[-1], rel=1e-12, abs=1e-12 * np.abs(E).max())
    assert np.all((h["step"][1:] > 0) & (h["step"][1:] <= 1))
    if method == "emu" and options.get("step", "newton-krylov") == "newton-krylov":
        assert h["cg_iterations"].sum() == sol.cg_iterations > 0


def test_info_reports_blas_and_threads():
    info = emu.info()
    assert isinstance(info["library"], str) and info["library"]
    assert "blas" in (info["library"] + info.get("config", "")).lower()
    assert int(info["blas_threads"]) >= 1
    assert int(info["omp_threads"]) >= 1
    assert info["version"] == emu.__version__


def test_return_to_rest_converges():
    # activation up, then back to zero from a warm start: the solve must reach the
    # rest shape (round-off near rest used to stall the line search)
    s = emu.scenes.fusiform(tets=800, warn=False)
    for method in ("emu", "fem"):
        # a fixed alpha: EMU iterates to the strict tolerance (not accuracy's step rule)
        solver = emu.Solver(s, method, **({"alpha": 100.0} if method == "emu" else {}))
        up = solver.solve({"belly": 1e4})
        down = solver.solve({"belly": 0.0}, initial=up)
        assert down.converged, (method, down.status)
        assert emu.vertex_error(down, s.points) < 1e-5, method


def test_emu_solve_takes_what_solver_solve_takes():
    """emu.solve passes pin_positions (and the rest) to Solver.solve: moved pins
    land where asked, with the same answer as the Solver."""
    s, m = small_scene(2)
    moved = s.points[s.pinned] + [0.0, 0.0, 0.05]
    one = emu.solve(s, {"belly": 0.2}, "fem", normalized=True, pin_positions=moved)
    two = emu.Solver(s, "fem").solve({"belly": 0.2}, normalized=True, pin_positions=moved)
    np.testing.assert_allclose(one.positions[s.pinned], moved, atol=1e-12)
    np.testing.assert_allclose(one.positions, two.positions, atol=1e-10)


def test_an_absolute_activation_that_looks_normalised_is_warned_about():
    """{"flexor": 0.4} without normalized=True is 0.4 stress units, 4e-6 of
    the muscle's maximum: a warning names the muscle and normalized=True, once
    per Solver and muscle; a fraction with normalized=True, a realistic
    absolute value and zero are silent."""
    s = emu.scenes.arm(1)
    for method in ("fem", "emu"):
        solver = emu.Solver(s, method)
        with pytest.warns(emu.ActivationWarning, match=r"activation 0.4 of 'flexor' is absolute.*normalized=True"):
            solver.load_case({"flexor": 0.4})
        with warnings.catch_warnings():
            warnings.simplefilter("error", emu.ActivationWarning)
            solver.load_case({"flexor": 0.4})                       # once per Solver and muscle
            solver.load_case({"flexor": 0.4, "extensor": 0.0})
            solver.load_case({"extensor": 0.4}, normalized=True)
            solver.load_case({"extensor": 4e4})
