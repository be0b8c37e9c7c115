"""EMU's operators on a small mesh against an independent numpy construction.

Built here from the rest mesh alone (not from emu's C++): G (9m x 3n) with
vec F_t = G_t x, D = diag(w_t V_t), K = G_f^T D G_f and C = G_f^T D over the
free (unpinned) vertices, x*(F) = K^-1 (C F - G_f^T D G_p x_p). Then

    E(F)  = sum_t V_t Psi(F_t) + alpha/2 |D^1/2 (G x* - F)|^2 - f . x*
    dE/dF = V P(F) + alpha D (F - G x*) - C^T K^-1 f
    H     = blockdiag(A_t) - alpha C^T K^-1 C
    H_k   = blockdiag(A_t) - alpha B^T Lambda^-1 B,  B = Phi^T C (k lowest modes of K)

Arrays of F are (#T, 9), row t = vec(F_t) column-major, and stacked row-major
into one 9#T vector (tet-major), as the C++ core does.
"""
import numpy as np
import pytest
import scipy.linalg as sl

import emu
from emu._core import testing
from emu import _core

from conftest import gradient_operator, small_scene
from emu.solve.load import set_inertia

GRAVITY = np.array([0.0, -9.81, 0.0])


def identity_rows(m):
    return np.tile(np.eye(3).flatten(order="F"), (m, 1))


def choose_scalar_modes(L, lo=6, hi=20, gap=1e-3):
    """A scalar mode count ks in [lo, hi] with a clear spectral gap after it, so the
    k lowest modes are well defined (not a split of a degenerate eigenspace)."""
    w = np.linalg.eigvalsh(L)
    for ks in range(lo, hi + 1):
        if (w[ks] - w[ks - 1]) > gap * w[ks]:
            return ks
    pytest.fail("no spectral gap found for the mode test")


class Reference:
    """The independent numpy model of one EmuSolver (its tets in the order the
    solver stores them: one F unknown per tet, in that order, on these scenes)."""

    def __init__(self, solver):
        md = solver._core.model
        self.solver, self.core = solver, solver._core
        self.rest = np.asarray(md.rest)
        self.tets = np.asarray(md.tets).astype(np.int64)
        self.m, self.n = len(self.tets), len(self.rest)
        G, vol = gradient_operator(self.rest, self.tets)
        self.G = G.toarray()
        self.vol = vol
        self.mu, self.lam = np.asarray(md.mu), np.asarray(md.lam)
        self.fiber = np.asarray(md.fiber)
        self.muscle = np.asarray(md.muscle)
        self.density = np.asarray(md.density)
        self.wv = np.asarray(md.acap_weight) * vol
        self.Dd = np.repeat(self.wv, 9)
        pinned = np.asarray(md.pinned)
        assert np.array_equal(np.sort(pinned), np.sort(solver.scene.model_pins()[0]))
        self.free = np.setdiff1d(np.arange(self.n), pinned)
        self.pinned = pinned
        dof = lambda v: (3 * v[:, None] + np.arange(3)).ravel()
        self.fdof, self.pdof = dof(self.free), dof(pinned)
        self.Gf, self.Gp = self.G[:, self.fdof], self.G[:, self.pdof]
        self.K = self.Gf.T @ (self.Dd[:, None] * self.Gf)
        self.C = self.Gf.T * self.Dd[None, :]
        self.L = self.K[0::3, 0::3]
        self.alpha = self.core.alpha
        self.mass = np.zeros(self.n)
        np.add.at(self.mass, self.tets.ravel(), np.repeat(0.25 * self.density * vol, 4))

    def activation(self, load):
        act = np.asarray(load.activation)
        return np.where(self.muscle >= 0, act[np.maximum(self.muscle, 0)], 0.0)

    def fit(self, load, Frows):
        xp = np.asarray(load.pin_positions).ravel() if np.size(load.pin_positions) else self.rest[self.pinned].ravel()
        rhs = self.C @ (Frows.ravel() - self.Gp @ xp)
        x = self.rest.copy().ravel()
        x[self.pdof] = xp
        x[self.fdof] = sl.solve(self.K, rhs, assume_a="pos")
        return x.reshape(-1, 3)

    def energy(self, load, Frows):
        act = self.activation(load)
        x = self.fit(load, Frows)
        Fx = (self.G @ x.ravel()).reshape(-1, 9)
        E = 0.0
        for t in range(self.m):
            Ft = Frows[t].reshape(3, 3, order="F")
            psi = _core.snh_energy(Ft, self.mu[t], self.lam[t])
            if act[t]:
                psi += 0.5 * act[t] * (np.sum((Ft @ self.fiber[t]) ** 2) - 1.0)
            E += self.vol[t] * psi
        E += 0.5 * self.alpha * np.sum(self.Dd * (Fx - Frows).ravel() ** 2)
        E -= np.sum(self.mass[:, None] * x * np.asarray(load.gravity)[None, :])
        return E

    def gradient(self, load, Frows):
        act = self.activation(load)
        x = self.fit(load, Frows)
        Fx = (self.G @ x.ravel()).reshape(-1, 9)
        g = np.empty_like(Frows)
        for t in range(self.m):
            Ft = Frows[t].reshape(3, 3, order="F")
            P = _core.snh_stress(Ft, self.mu[t], self.lam[t]) + act[t] * np.outer(Ft @ self.fiber[t], self.fiber[t])
            g[t] = self.vol[t] * P.flatten(order="F")
        g += self.alpha * self.wv[:, None] * (Frows - Fx)
        f = (self.mass[self.free, None] * np.asarray(load.gravity)[None, :]).ravel()
        g -= (self.C.T @ sl.solve(self.K, f, assume_a="pos")).reshape(-1, 9)
        return g

    def blocks(self, load, Frows, project=True):
        act = self.activation(load)
        A = np.empty((self.m, 9, 9))
        for t in range(self.m):
            Ft = Frows[t].reshape(3, 3, order="F")
            H = _core.snh_hessian(Ft, self.mu[t], self.lam[t])
            if project:
                H = _core.psd_project9(H)
            H = H + act[t] * np.kron(np.outer(self.fiber[t], self.fiber[t]), np.eye(3))
            A[t] = self.vol[t] * H + self.alpha * self.wv[t] * np.eye(9)
        return A

    def hessian(self, A):
        return sl.block_diag(*A) - self.alpha * self.C.T @ sl.solve(self.K, self.C, assume_a="pos")

    def modes(self, k):
        """k lowest eigenpairs of K (from the scalar L: K = L kron I3), as
        (values, Phi) with Phi[:, c + 3 l] = psi_l kron e_c."""
        w, psi = np.linalg.eigh(self.L)
        ks = k // 3
        vals = np.repeat(w[:ks], 3)
        Phi = np.zeros((3 * len(self.free), 3 * ks))
        for l in range(ks):
            for c in range(3):
                Phi[c::3, c + 3 * l] = psi[:, l]
        return vals, Phi


def make(alpha=100.0, modes=24, r=2, **kw):
    s, m = small_scene(r, **kw)
    solver = emu.Solver(s, "emu", alpha=alpha, modes=modes, preconditioner="woodbury")
    return solver, Reference(solver)


@pytest.fixture(scope="module")
def ref():
    solver, R = make()
    return R


def perturbed(m, eps, seed):
    return identity_rows(m) + eps * np.random.default_rng(seed).standard_normal((m, 9))


LOADS = [dict(activation={"belly": 5e4}), dict(activation={"belly": 5e4}, gravity=GRAVITY),
         dict(activation=None, gravity=GRAVITY)]


# --------------------------------------------------------------------- geometry
def test_reference_discretisation_is_consistent(ref):
    """Sanity of the numpy side: G reproduces F of an affine map, K = L kron I3."""
    rng = np.random.default_rng(0)
    A, c = np.eye(3) + 0.2 * rng.standard_normal((3, 3)), rng.standard_normal(3)
    x = ref.rest @ A.T + c
    np.testing.assert_allclose((ref.G @ x.ravel()).reshape(-1, 9), np.tile(A.flatten(order="F"), (ref.m, 1)),
                               atol=1e-12)
    np.testing.assert_allclose(ref.K, np.kron(ref.L, np.eye(3)), atol=1e-12 * np.abs(ref.K).max())
    assert ref.vol.min() > 0


@pytest.mark.parametrize("case", LOADS)
def test_fit_and_energy_match_numpy(ref, case):
    load = ref.solver.load_case(**case)
    F = perturbed(ref.m, 0.05, 1)
    np.testing.assert_allclose(testing.fit_positions(ref.core, load, F), ref.fit(load, F), rtol=0, atol=1e-11 * 10)
    E = testing.energy(ref.core, load, F)
    assert E == pytest.approx(ref.energy(load, F), rel=1e-10)


@pytest.mark.parametrize("case", LOADS)
def test_gradient_matches_numpy(ref, case):
    load = ref.solver.load_case(**case)
    F = perturbed(ref.m, 0.05, 2)
    g = testing.gradient(ref.core, load, F)
    assert g.shape == F.shape
    gn = ref.gradient(load, F)
    np.testing.assert_allclose(g, gn, rtol=0, atol=1e-10 * np.abs(gn).max())


@pytest.mark.parametrize("case", LOADS)
@pytest.mark.parametrize("eps", [0.0, 0.05, 0.2])
def test_gradient_finite_differences(ref, case, eps):
    load = ref.solver.load_case(**case)
    m = ref.m
    F = perturbed(m, eps, 3)
    g = testing.gradient(ref.core, load, F)
    rng = np.random.default_rng(4)
    h = 1e-6
    for _ in range(3):
        V = rng.standard_normal((m, 9))
        fd = (testing.energy(ref.core, load, F + h * V) - testing.energy(ref.core, load, F - h * V)) / (2 * h)
        assert np.sum(g * V) == pytest.approx(fd, rel=1e-6, abs=1e-7 * np.linalg.norm(g) * np.linalg.norm(V))
    # single entries, including a tendon tet and a muscle tet
    for t in (0, m // 2, m - 1):
        for j in (0, 4, 7):
            E1, E0 = F.copy(), F.copy()
            E1[t, j] += h
            E0[t, j] -= h
            fd = (testing.energy(ref.core, load, E1) - testing.energy(ref.core, load, E0)) / (2 * h)
            assert g[t, j] == pytest.approx(fd, rel=1e-5, abs=1e-6 * np.abs(g).max())


def test_gravity_enters_gradient(ref):
    """The load term -(dx*/dF)^T grad W = -C^T K^-1 f is present, exactly."""
    F = perturbed(ref.m, 0.05, 5)
    g0 = testing.gradient(ref.core, ref.solver.load_case({"belly": 5e4}), F)
    g1 = testing.gradient(ref.core, ref.solver.load_case({"belly": 5e4}, gravity=GRAVITY), F)
    f = (ref.mass[ref.free, None] * GRAVITY[None, :]).ravel()
    term = -(ref.C.T @ sl.solve(ref.K, f, assume_a="pos")).reshape(-1, 9)
    assert np.abs(term).max() > 0
    np.testing.assert_allclose(g1 - g0, term, rtol=0, atol=1e-6 * np.abs(term).max())
    # at rest without activation the gradient is the load term alone, and not zero
    load = ref.solver.load_case(gravity=GRAVITY)
    g = testing.gradient(ref.core, load, identity_rows(ref.m))
    np.testing.assert_allclose(g, term, rtol=0, atol=1e-9 * np.abs(term).max())
    # gravity in the energy at rest: E(I) = -f . x(I) = -sum m_v g . X_v
    gz = np.array([0.0, 0.0, -9.81])  # along the muscle, so the work is not ~0 by symmetry
    E = testing.energy(ref.core, ref.solver.load_case(gravity=gz), identity_rows(ref.m))
    W = np.sum(ref.mass * (ref.rest @ gz))
    assert abs(W) > 0
    assert E == pytest.approx(-W, rel=1e-10)


# ---------------------------------------------------------------------- Hessian
@pytest.mark.parametrize("eps", [0.0, 0.1, 0.3])
def test_block_hessians_match_numpy(ref, eps):
    load = ref.solver.load_case({"belly": 5e4})
    F = perturbed(ref.m, eps, 6)
    A = testing.block_hessians(ref.core, load, F)
    assert A.shape == (ref.m, 81)
    A = A.reshape(-1, 9, 9).transpose(0, 2, 1)  # column-major 9x9 per row
    An = ref.blocks(load, F)
    np.testing.assert_allclose(A, An, rtol=0, atol=1e-10 * np.abs(An).max())
    for t in range(ref.m):
        np.testing.assert_allclose(A[t], A[t].T, rtol=0, atol=1e-10 * np.abs(An).max())
        assert np.linalg.eigvalsh(A[t]).min() > 0


@pytest.mark.parametrize("eps", [0.0, 0.1, 0.3])
def test_hessian_product_matches_numpy_schur_complement(ref, eps):
    load = ref.solver.load_case({"belly": 5e4})
    F = perturbed(ref.m, eps, 7)
    H = ref.hessian(ref.blocks(load, F))
    V = np.random.default_rng(8).standard_normal((ref.m, 9))
    Hv = testing.hessian_product(ref.core, load, F, V)
    expected = (H @ V.ravel()).reshape(-1, 9)
    np.testing.assert_allclose(Hv, expected, rtol=0, atol=1e-10 * np.abs(expected).max())
    # the exact Hessian is PSD (projected blocks): the Schur complement of a PSD energy
    if eps == 0.3:
        sl.cho_factor(0.5 * (H + H.T) + 1e-9 * np.abs(H).max() * np.eye(len(H)))


def fd_hessian_product(core, load, F, V, h=1e-6):
    return (testing.gradient(core, load, F + h * V) - testing.gradient(core, load, F - h * V)) / (2 * h)


@pytest.mark.parametrize("eps", [0.0, 1e-4])
@pytest.mark.parametrize("case", LOADS[:2])
def test_hessian_product_finite_differences_where_blocks_definite(ref, eps, case):
    """At F = I the SNH Hessian is only semi-definite (zero curvature along
    infinitesimal rotations, and any perturbation can make it indefinite); a
    uniform 0.2% expansion makes every block definite, so the projected Hessian
    is the exact one and FD of the gradient must reproduce it."""
    load = ref.solver.load_case(**case)
    F = 1.002 * identity_rows(ref.m) + eps * np.random.default_rng(9).standard_normal((ref.m, 9))
    for t in range(ref.m):
        Ft = F[t].reshape(3, 3, order="F")
        Hs = _core.snh_hessian(Ft, ref.mu[t], ref.lam[t])
        assert np.linalg.eigvalsh(Hs).min() > 0
        assert np.array_equal(_core.psd_project9(Hs), Hs)
    rng = np.random.default_rng(10)
    for _ in range(2):
        V = rng.standard_normal((ref.m, 9))
        Hv = testing.hessian_product(ref.core, load, F, V)
        fd = fd_hessian_product(ref.core, load, F, V)
        np.testing.assert_allclose(Hv, fd, rtol=0, atol=1e-6 * np.abs(Hv).max())


def test_unprojected_hessian_finite_differences(ref):
    """At a strongly deformed F, where some SNH blocks are indefinite, FD of the
    gradient equals the unprojected Schur complement (and differs from the projected one)."""
    load = ref.solver.load_case({"belly": 5e4})
    F = perturbed(ref.m, 0.3, 11)
    indefinite = [t for t in range(ref.m)
                  if np.linalg.eigvalsh(_core.snh_hessian(F[t].reshape(3, 3, order="F"), ref.mu[t],
                                                          ref.lam[t])).min() < 0]
    assert indefinite, "the test needs some indefinite blocks"
    H_exact = ref.hessian(ref.blocks(load, F, project=False))
    V = np.random.default_rng(12).standard_normal((ref.m, 9))
    fd = fd_hessian_product(ref.core, load, F, V).ravel()
    Hv = H_exact @ V.ravel()
    np.testing.assert_allclose(fd, Hv, rtol=0, atol=1e-6 * np.abs(Hv).max())
    Hp = testing.hessian_product(ref.core, load, F, V).ravel()
    assert np.abs(Hp - Hv).max() > 1e-4 * np.abs(Hv).max()


def test_hessian_product_ignores_gravity_and_is_linear(ref):
    F = perturbed(ref.m, 0.1, 13)
    rng = np.random.default_rng(14)
    V, W = rng.standard_normal((2, ref.m, 9))
    l0 = ref.solver.load_case({"belly": 5e4})
    l1 = ref.solver.load_case({"belly": 5e4}, gravity=GRAVITY)
    a = testing.hessian_product(ref.core, l0, F, V)
    np.testing.assert_allclose(testing.hessian_product(ref.core, l1, F, V), a, rtol=0, atol=1e-12 * np.abs(a).max())
    b = testing.hessian_product(ref.core, l0, F, W)
    np.testing.assert_allclose(testing.hessian_product(ref.core, l0, F, 2 * V - 3 * W), 2 * a - 3 * b, rtol=0,
                               atol=1e-10 * np.abs(a).max())


# ------------------------------------------------------------------------ modes
@pytest.fixture(scope="module")
def mode_setup():
    s, _ = small_scene(2)
    base = emu.Solver(s, "emu", alpha=100.0, modes=3, preconditioner="woodbury")
    R0 = Reference(base)
    ks = choose_scalar_modes(R0.L)
    solver = emu.Solver(s, "emu", alpha=100.0, modes=3 * ks, preconditioner="woodbury")
    return solver, Reference(solver), ks


def test_mode_values_are_lowest_eigenvalues_of_K(mode_setup):
    solver, R, ks = mode_setup
    core = solver._core
    assert core.modes == 3 * ks
    lam = np.asarray(testing.mode_values(core))
    assert lam.shape == (3 * ks,)
    wK = np.linalg.eigvalsh(R.K)[: 3 * ks]
    np.testing.assert_allclose(np.sort(lam), wK, rtol=1e-9, atol=0)
    # each eigenvalue of L appears three times (K = L kron I3)
    wL = np.linalg.eigvalsh(R.L)[:ks]
    np.testing.assert_allclose(np.sort(lam), np.repeat(wL, 3), rtol=1e-9)


def test_mode_matrix_is_phi_transpose_C(mode_setup):
    solver, R, ks = mode_setup
    core = solver._core
    k = 3 * ks
    B = np.asarray(testing.mode_matrix(core))
    lam = np.asarray(testing.mode_values(core))
    assert B.shape == (k, 9 * R.m)
    vals, Phi = R.modes(k)
    Bn = Phi.T @ R.C
    # sign-invariant: B^T Lambda^-1 B
    S = B.T @ (B / lam[:, None])
    Sn = Bn.T @ (Bn / vals[:, None])
    np.testing.assert_allclose(S, Sn, rtol=0, atol=1e-8 * np.abs(Sn).max())
    # row by row up to sign (the chosen k has simple scalar eigenvalues below the gap)
    wL = np.linalg.eigvalsh(R.L)[: ks + 1]
    if np.all(np.diff(wL) > 1e-6 * wL[1:]):
        for row in range(k):
            b = B[row]
            j = np.argmax([abs(b @ bn) / (np.linalg.norm(b) * np.linalg.norm(bn)) for bn in Bn])
            assert abs(lam[row] - vals[j]) <= 1e-9 * vals[j]
            sign = np.sign(b @ Bn[j])
            np.testing.assert_allclose(b, sign * Bn[j], rtol=0, atol=1e-8 * np.abs(Bn[j]).max())


@pytest.mark.parametrize("eps", [0.0, 0.2])
@pytest.mark.parametrize("alpha", [1.0, 100.0])
def test_woodbury_solve_equals_dense_solve(eps, alpha):
    solver, R = make(alpha=alpha, modes=24)
    core = solver._core
    load = solver.load_case({"belly": 5e4})
    F = perturbed(R.m, eps, 15)
    A = R.blocks(load, F)
    B = np.asarray(testing.mode_matrix(core))
    lam = np.asarray(testing.mode_values(core))
    Hk = sl.block_diag(*A) - R.alpha * B.T @ (B / lam[:, None])
    # H_k over-estimates the exact Hessian, which is PSD: H_k is positive definite
    Rhs = np.random.default_rng(16).standard_normal((R.m, 9))
    x = testing.woodbury_solve(core, load, F, Rhs)
    xn = sl.cho_solve(sl.cho_factor(Hk), Rhs.ravel()).reshape(-1, 9)
    np.testing.assert_allclose(x, xn, rtol=0, atol=1e-8 * np.abs(xn).max())
    # and it is not simply A^-1 r (the low-rank term matters)
    xa = np.stack([np.linalg.solve(A[t], Rhs[t]) for t in range(R.m)])
    assert np.abs(xa - xn).max() > 1e-3 * np.abs(xn).max()


@pytest.mark.parametrize("eps", [0.0, 0.2])
def test_woodbury_with_all_modes_is_exact_newton(eps):
    s, _ = small_scene(2)
    nfree = len(s.points) - len(s.model_pins()[0])
    solver = emu.Solver(s, "emu", alpha=100.0, modes=3 * nfree, preconditioner="woodbury")
    core = solver._core
    assert core.modes == 3 * nfree
    R = Reference(solver)
    # all modes: B^T Lambda^-1 B is C^T K^-1 C
    B, lam = np.asarray(testing.mode_matrix(core)), np.asarray(testing.mode_values(core))
    S = R.C.T @ sl.solve(R.K, R.C, assume_a="pos")
    np.testing.assert_allclose(B.T @ (B / lam[:, None]), S, rtol=0, atol=1e-8 * np.abs(S).max())
    load = solver.load_case({"belly": 5e4})
    F = perturbed(R.m, eps, 17)
    H = R.hessian(R.blocks(load, F))
    Rhs = np.random.default_rng(18).standard_normal((R.m, 9))
    x = testing.woodbury_solve(core, load, F, Rhs)
    xn = np.linalg.solve(H, Rhs.ravel()).reshape(-1, 9)
    np.testing.assert_allclose(x, xn, rtol=0, atol=1e-7 * np.abs(xn).max())
    # and consistent with the Hessian product: H (H^-1 r) = r
    np.testing.assert_allclose(testing.hessian_product(core, load, F, x), Rhs, rtol=0, atol=1e-7 * np.abs(Rhs).max())


def test_modes_by_lanczos_on_a_larger_mesh():
    """More than 400 free vertices: the modes come from shift-invert Lanczos, not a
    dense eigensolver. Check values and the sign-invariant B^T Lambda^-1 B v."""
    import scipy.sparse as sp

    s, _ = small_scene(5)
    nfree = len(s.points) - len(s.model_pins()[0])
    assert nfree > 400
    solver = emu.Solver(s, "emu", alpha=100.0, modes=3, preconditioner="woodbury")
    md = solver._core.model   # its tets in the solver's order
    G, vol = gradient_operator(np.asarray(md.rest), np.asarray(md.tets).astype(np.int64))
    free = np.setdiff1d(np.arange(len(md.rest)), np.asarray(md.pinned))
    Dd = np.repeat(np.asarray(md.acap_weight) * vol, 9)
    Gs = G[:, 3 * free]  # x-coordinate columns: the scalar problem
    L = (Gs.T @ sp.diags(Dd) @ Gs).toarray()
    # G's x-columns give vec(F) rows 0, 3, 6 (F[0, k]); L_ab = sum w V b_a . b_b
    ks = choose_scalar_modes(L, lo=8, hi=30)
    solver = emu.Solver(s, "emu", alpha=100.0, modes=3 * ks, preconditioner="woodbury")
    core = solver._core
    lam = np.asarray(testing.mode_values(core))
    w, psi = np.linalg.eigh(L)
    np.testing.assert_allclose(np.sort(lam), np.repeat(w[:ks], 3), rtol=1e-7)
    B = np.asarray(testing.mode_matrix(core))
    fdof = (3 * free[:, None] + np.arange(3)).ravel()
    C = (G[:, fdof].T @ sp.diags(Dd)).tocsr()
    rng = np.random.default_rng(19)
    v = rng.standard_normal(B.shape[1])
    got = B.T @ ((B @ v) / lam)
    Phi = np.zeros((len(fdof), 3 * ks))
    for l in range(ks):
        for c in range(3):
            Phi[c::3, c + 3 * l] = psi[:, l]
    Bn = (C.T @ Phi).T
    want = Bn.T @ ((Bn @ v) / np.repeat(w[:ks], 3))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6 * np.abs(want).max())


@pytest.mark.parametrize("eps", [0.0, 0.2])
def test_schur_preconditioner_is_the_exact_inverse_of_the_filtered_hessian(eps):
    """preconditioner='schur' applies H^-1 through S = K - alpha C A^-1 C^T (a
    factorisation): against a dense solve of the filtered Hessian, and it makes
    CG converge in one iteration per Newton step when the Hessian it inverts is
    the one CG uses (exact_when_definite=False)."""
    s, _ = small_scene(2)
    solver = emu.Solver(s, "emu", alpha=100.0, preconditioner="schur")
    core = solver._core
    R = Reference(solver)
    load = solver.load_case({"belly": 5e4})
    F = perturbed(R.m, eps, 21)
    H = R.hessian(R.blocks(load, F))
    Rhs = np.random.default_rng(22).standard_normal((R.m, 9))
    x = testing.schur_solve(core, load, F, Rhs)
    xn = np.linalg.solve(H, Rhs.ravel()).reshape(-1, 9)
    np.testing.assert_allclose(x, xn, rtol=0, atol=1e-7 * np.abs(xn).max())
    # a solver holds only the preconditioner it uses: asking for another is a clear error
    with pytest.raises(ValueError, match="preconditioner='schur'"):
        testing.schur_solve(emu.Solver(s, "emu", alpha=100.0)._core, load, F, Rhs)
    with pytest.raises(ValueError, match="preconditioner='woodbury'"):
        testing.woodbury_solve(core, load, F, Rhs)
    with pytest.raises(ValueError, match="preconditioner='woodbury'"):
        testing.mode_values(core)
    assert core.modes == 0
    # the residual test alone (cg_model_decrease=0): the truncation test never
    # holds at the first iteration (k (q_0 - q_1) = |q_1|), so it would add a
    # second, empty one to every step
    filtered = emu.Solver(s, "emu", alpha=100.0, preconditioner="schur", preconditioner_refresh=1,
                          exact_when_definite=False, cg_model_decrease=0.0)
    sol = filtered.solve({"belly": 5e4})
    assert sol.converged, sol.status
    assert sol.cg_iterations <= sol.iterations + 2


@pytest.mark.parametrize("tendon_fraction", [0.12, 0.0])   # without tendons S0 = c K: K's own factor serves
@pytest.mark.parametrize("alpha", [30.0, 300.0])
@pytest.mark.parametrize("eps", [0.0, 0.2])
def test_constant_schur_preconditioner_against_numpy(eps, alpha, tendon_fraction):
    """preconditioner='constant-schur' applies M^-1 = A^-1 + alpha A^-1 C^T S0^-1 C A^-1
    with the constant S0 = G_f^T diag(e) G_f, e_t = w_t V_t h_t / (h_t + alpha w_t),
    h_t = mu_t + lambda_t / 3 (built here in numpy): the same vectors; M^-1 is
    symmetric positive definite; and, as for any block factorisation with an
    approximate Schur complement, the eigenvalues of M^-1 H lie between
    min(1, eig(S0^-1 S)) and max(1, eig(S0^-1 S)), S = K - alpha C A^-1 C^T.
    A new alpha refactorises S0 (the weights change). With S0's factor and the
    block inverses rounded to float (single_precision_preconditioner, the
    default) the vectors differ from these by float round-off, not more."""
    s, _ = small_scene(2, tendon_fraction=tendon_fraction)
    solver = emu.Solver(s, "emu", alpha=100.0, preconditioner="constant-schur", single_precision_preconditioner=False)
    core = solver._core
    core.alpha = alpha * solver.mu_ref
    R = Reference(solver)
    load = solver.load_case({"belly": 5e4})
    F = perturbed(R.m, eps, 23)
    A = R.blocks(load, F)
    w = R.wv / R.vol
    h = R.mu + R.lam / 3
    e = R.wv * h / (h + R.alpha * w)
    S0 = R.Gf.T @ (np.repeat(e, 9)[:, None] * R.Gf)
    Ainv = sl.block_diag(*np.linalg.inv(A))
    Minv = Ainv + R.alpha * Ainv @ R.C.T @ sl.solve(S0, R.C @ Ainv, assume_a="pos")
    Rhs = np.random.default_rng(24).standard_normal((R.m, 9))
    got = testing.constant_schur_solve(core, load, F, Rhs)
    want = (Minv @ Rhs.ravel()).reshape(-1, 9)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-8 * np.abs(want).max())
    rounded = emu.Solver(s, "emu", alpha=100.0, preconditioner="constant-schur")._core
    rounded.alpha = alpha * solver.mu_ref
    got_rounded = testing.constant_schur_solve(rounded, load, F, Rhs)
    assert 0 < np.abs(got_rounded - want).max() <= 1e-5 * np.abs(want).max()
    np.testing.assert_allclose(Minv, Minv.T, rtol=0, atol=1e-9 * np.abs(Minv).max())
    assert np.linalg.eigvalsh(0.5 * (Minv + Minv.T)).min() > 0
    H = R.hessian(A)
    S = R.K - R.alpha * R.C @ Ainv @ R.C.T
    s_eig = sl.eigh(0.5 * (S + S.T), S0, eigvals_only=True)
    lo, hi = min(1.0, s_eig.min()), max(1.0, s_eig.max())
    ev = np.sort(np.linalg.eigvals(Minv @ H).real)
    assert ev.min() >= lo * (1 - 1e-6) and ev.max() <= hi * (1 + 1e-6), (ev.min(), ev.max(), lo, hi)
    with pytest.raises(ValueError, match="preconditioner='constant-schur'"):
        testing.constant_schur_solve(emu.Solver(s, "emu", alpha=100.0, preconditioner="woodbury")._core, load, F, Rhs)


def test_single_precision_preconditioner_with_bones_changes_cg_not_the_answer():
    """With movable bones the constant Schur preconditioner's own S0 is solved
    with its factor rounded to float, the bone elimination included, and the
    block inverses are kept in float (one symmetric SPD preconditioner still):
    the arm's strict solve reaches the same answer in about as many CG
    iterations as in double."""
    s = emu.scenes.arm(2)
    sols = {}
    for single in (False, True):
        solver = emu.Solver(s, "emu", alpha=100.0, error_estimate=False, single_precision_preconditioner=single)
        sols[single] = solver.solve({"flexor": 0.45}, normalized=True)
        assert sols[single].converged, sols[single].status
    assert emu.vertex_error(sols[True].positions, sols[False].positions) <= 1e-6
    a, b = sols[False].cg_iterations, sols[True].cg_iterations
    assert a > 0 and abs(a - b) <= 0.15 * a + 2, (a, b)


def test_single_precision_s0_is_the_old_name_of_single_precision_preconditioner():
    """The option's name of 0.1.0 development still works, with a warning naming the new one."""
    s, _ = small_scene(2)
    with pytest.warns(DeprecationWarning, match="single_precision_preconditioner"):
        solver = emu.Solver(s, "emu", alpha=100.0, error_estimate=False, single_precision_s0=False)
    assert solver.settings["single_precision_preconditioner"] is False
    assert emu.Solver(s, "emu", alpha=100.0, error_estimate=False).settings["single_precision_preconditioner"] is True
    with pytest.raises(ValueError, match="give only single_precision_preconditioner"):
        emu.Solver(s, "emu", alpha=100.0, error_estimate=False, single_precision_s0=False,
                   single_precision_preconditioner=True)


@pytest.mark.parametrize("ratio, tendon_fraction, single", [(0.1, 0.12, False), (10.0, 0.12, False),
                                                            (10.0, 0.0, True)])
def test_constant_schur_preconditioner_with_inertia(ratio, tendon_fraction, single):
    """A time step's inertia (w / 2) |x(F) - y|^2_M adds J^T w M J (J = K^-1 C,
    the fit's Jacobian) to the Hessian. The constant Schur preconditioner then
    inverts A - alpha^2 C^T (alpha K + w M)^-1 C through S0 + (w / alpha) M on
    the free vertices (built here in numpy): the same vectors, and the
    preconditioned Hessian with the inertia far better conditioned than with
    the preconditioner that leaves it out. w is set so that w M stands at
    `ratio` x alpha K's mean diagonal. Without tendons S0 = c K serves the
    quasi-static solves and the inertia gives S0 its own factor (and back);
    single precision rounds it (float round-off, not more)."""
    s, _ = small_scene(2, tendon_fraction=tendon_fraction)
    solver = emu.Solver(s, "emu", alpha=100.0, preconditioner="constant-schur", single_precision_preconditioner=single)
    core = solver._core
    R = Reference(solver)
    mf = R.mass[R.free]
    assert mf.min() > 0
    w = ratio * R.alpha * np.mean(np.diag(R.L)) / np.mean(mf)
    load = solver.load_case({"belly": 5e4})
    set_inertia(load, s, (w, R.rest))
    F = perturbed(R.m, 0.1, 31)
    A = R.blocks(load, F)
    h = R.mu + R.lam / 3
    e = R.wv * h / (h + R.alpha * R.wv / R.vol)
    S0 = R.Gf.T @ (np.repeat(e, 9)[:, None] * R.Gf)
    Mf = np.diag(np.repeat(mf, 3))
    Ainv = sl.block_diag(*np.linalg.inv(A))

    def preconditioner(S):
        return Ainv + R.alpha * Ainv @ R.C.T @ sl.solve(S, R.C @ Ainv, assume_a="pos")
    with_inertia, without = preconditioner(S0 + w / R.alpha * Mf), preconditioner(S0)
    Rhs = np.random.default_rng(32).standard_normal((R.m, 9))
    got = testing.constant_schur_solve(core, load, F, Rhs)
    want = (with_inertia @ Rhs.ravel()).reshape(-1, 9)
    tol = (1e-5 if single else 1e-8) * np.abs(want).max()
    np.testing.assert_allclose(got, want, rtol=0, atol=tol)
    J = sl.solve(R.K, R.C, assume_a="pos")
    H = R.hessian(A) + w * J.T @ Mf @ J

    def condition(Minv):
        ev = np.linalg.eigvals(Minv @ H).real
        assert ev.min() > 0
        return ev.max() / ev.min()
    kept, left_out = condition(with_inertia), condition(without)
    assert kept < 0.5 * left_out
    load.inertia_weight = 0.0   # back to the quasi-static preconditioner
    np.testing.assert_allclose(testing.constant_schur_solve(core, load, F, Rhs),
                               (without @ Rhs.ravel()).reshape(-1, 9), rtol=0, atol=tol)


def test_each_emu_solve_gives_its_preconditioner_the_steps_inertia():
    """EmuSolver::solve sets the constant Schur preconditioner's inertia from its
    load: a time step's weight, then 0 for a quasi-static solve, whose CG and
    answer are then those of a solver that never took a time step."""
    s, _ = small_scene(2)
    act = {"belly": 5e4}
    fresh = emu.Solver(s, "emu", alpha=100.0, error_estimate=False)
    want = fresh.solve(act)
    solver = emu.Solver(s, "emu", alpha=100.0, error_estimate=False)
    assert testing.constant_schur_inertia(solver._core) == 0.0
    step = solver.solve(act, inertia=(2.5e3, s.points))
    assert step.converged and testing.constant_schur_inertia(solver._core) == 2.5e3
    got = solver.solve(act)
    assert testing.constant_schur_inertia(solver._core) == 0.0
    assert got.cg_iterations == want.cg_iterations and got.iterations == want.iterations
    np.testing.assert_array_equal(got.positions, want.positions)
