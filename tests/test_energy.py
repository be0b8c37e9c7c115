"""Element kernels through the bindings: Stable Neo-Hookean, the active fibre
term and the 9x9 PSD projection against the formulas of docs/METHOD.md, 2.
Materials, written out here in numpy (energies, the fibre's closed forms, the
projection against numpy's eigendecomposition), and the bindings' layout:
vec(F) is column-major, vec(F)[i + 3 j] = F[i, j]. The derivatives against
finite differences are checked once, in C++ (cpp/tests/energy/test_energy.cpp,
over the same kinds of F and materials)."""
import numpy as np
import pytest

from emu import _core

MU, LAM = 2e4, 1e6


def vec(F):
    return np.asarray(F).flatten(order="F")


def snh_reference(F, mu, lam):
    """docs/METHOD.md, 2. Materials, with the rest value Psi(I) subtracted."""
    ic = np.sum(F * F)
    J = np.linalg.det(F)
    beta = 1.0 + 0.75 * mu / lam
    psi = 0.5 * mu * (ic - 3) + 0.5 * lam * (J - beta) ** 2 - 0.5 * mu * np.log(ic + 1)
    rest = 0.5 * lam * (1 - beta) ** 2 - 0.5 * mu * np.log(4.0)
    return psi - rest


def random_rotation(rng):
    Q, R = np.linalg.qr(rng.standard_normal((3, 3)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0:
        Q[:, 0] *= -1
    return Q


def sample_F(kind, rng):
    if kind == "near_rest":
        return np.eye(3) + 1e-3 * rng.standard_normal((3, 3))
    if kind == "moderate":
        return np.eye(3) + 0.3 * rng.standard_normal((3, 3))
    if kind == "compressed":
        return random_rotation(rng) @ np.diag([0.6, 0.8, 1.3]) @ random_rotation(rng).T
    if kind == "inverted":
        F = np.eye(3) + 0.3 * rng.standard_normal((3, 3))
        F[:, 0] *= -1 if np.linalg.det(F) > 0 else 1
        assert np.linalg.det(F) < 0
        return F
    if kind == "inverted_flat":
        return random_rotation(rng) @ np.diag([-0.2, 0.9, 1.1]) @ random_rotation(rng).T
    raise ValueError(kind)


KINDS = ["near_rest", "moderate", "compressed", "inverted", "inverted_flat"]


# ------------------------------------------------------------- Stable Neo-Hookean
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("seed", [0, 1])
def test_snh_energy_matches_formula(kind, seed):
    F = sample_F(kind, np.random.default_rng(seed))
    e = _core.snh_energy(F, MU, LAM)
    ref = snh_reference(F, MU, LAM)
    assert e == pytest.approx(ref, rel=1e-10, abs=1e-9 * LAM * 1e-6)


def test_snh_layout_is_column_major():
    """A non-symmetric F exposes a row-major/column-major mix-up."""
    F = np.array([[1.0, 0.3, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    P = _core.snh_stress(F, MU, LAM)
    h = 1e-6
    E = np.zeros((3, 3))
    E[0, 1] = h
    dP01 = (_core.snh_energy(F + E, MU, LAM) - _core.snh_energy(F - E, MU, LAM)) / (2 * h)
    assert P[0, 1] == pytest.approx(dP01, rel=1e-6)
    assert abs(P[0, 1] - P[1, 0]) > 1e-3 * abs(P[0, 1])  # the test distinguishes them
    H = _core.snh_hessian(F, MU, LAM)
    # column 3 of H is d vec(P) / d F[0, 1]
    dP = (vec(_core.snh_stress(F + E, MU, LAM)) - vec(_core.snh_stress(F - E, MU, LAM))) / (2 * h)
    np.testing.assert_allclose(H[:, 3], dP, rtol=0, atol=1e-7 * np.abs(dP).max())


def test_snh_positive_away_from_rest_and_finite_when_inverted():
    rng = np.random.default_rng(4)
    for kind in KINDS:
        for _ in range(5):
            F = sample_F(kind, rng)
            e = _core.snh_energy(F, MU, LAM)
            assert np.isfinite(e)
            assert np.all(np.isfinite(_core.snh_hessian(F, MU, LAM)))
            if kind.startswith("inverted"):
                assert e > 0


# ------------------------------------------------------------------------ fibre
def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fiber_energy_zero_at_rest(seed):
    rng = np.random.default_rng(seed)
    u = unit(rng.standard_normal(3))
    assert abs(_core.fiber_energy(np.eye(3), u, 5e4)) <= 1e-9
    np.testing.assert_allclose(_core.fiber_stress(np.eye(3), u, 0.0), 0.0, atol=0)
    # the energy differs between two F exactly as a/2 (|F u|^2 - |G u|^2)
    F, G = sample_F("moderate", rng), sample_F("inverted", rng)
    a = 5e4
    de = _core.fiber_energy(F, u, a) - _core.fiber_energy(G, u, a)
    assert de == pytest.approx(0.5 * a * (np.sum((F @ u) ** 2) - np.sum((G @ u) ** 2)), rel=1e-10)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("seed", [0, 1])
def test_fiber_stress_and_hessian_closed_forms(kind, seed):
    rng = np.random.default_rng(seed)
    F = sample_F(kind, rng)
    u = unit(rng.standard_normal(3))
    a = 5e4
    P = _core.fiber_stress(F, u, a)
    np.testing.assert_allclose(P, a * np.outer(F @ u, u), rtol=1e-12, atol=1e-12 * a)
    H = _core.fiber_hessian(u, a)
    np.testing.assert_allclose(H, a * np.kron(np.outer(u, u), np.eye(3)), rtol=0, atol=1e-12 * a)
    assert np.linalg.eigvalsh(H).min() >= -1e-9 * a


# ------------------------------------------------------------------ projection
def random_symmetric(rng, eigs):
    Q, _ = np.linalg.qr(rng.standard_normal((9, 9)))
    return (Q * eigs) @ Q.T, Q


@pytest.mark.parametrize("seed", range(4))
def test_psd_projection_clamps(seed):
    rng = np.random.default_rng(seed)
    eigs = rng.uniform(-1, 1, 9) * 10.0 ** rng.uniform(0, 6, 9)
    eigs[0] = -abs(eigs[0])  # at least one negative
    H, Q = random_symmetric(rng, eigs)
    scale = np.abs(eigs).max()
    P = _core.psd_project9(H)
    np.testing.assert_allclose(P, P.T, rtol=0, atol=1e-12 * scale)
    assert np.linalg.eigvalsh(P).min() >= -1e-9 * scale
    expected = (Q * np.maximum(eigs, 0)) @ Q.T
    np.testing.assert_allclose(P, expected, rtol=0, atol=1e-10 * scale)
    R = _core.psd_project9(H, reflect=True)
    np.testing.assert_allclose(R, R.T, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(np.linalg.eigvalsh(R), np.sort(np.abs(eigs)), rtol=1e-9, atol=1e-10 * scale)
    np.testing.assert_allclose(R, (Q * np.abs(eigs)) @ Q.T, rtol=0, atol=1e-10 * scale)


@pytest.mark.parametrize("reflect", [False, True])
def test_psd_projection_keeps_definite_matrix_exactly(reflect):
    rng = np.random.default_rng(7)
    H, _ = random_symmetric(rng, rng.uniform(0.1, 1e5, 9))
    H = 0.5 * (H + H.T)
    P = _core.psd_project9(H, reflect=reflect)
    assert np.array_equal(P, H)


@pytest.mark.parametrize("kind", KINDS)
def test_psd_projection_of_snh_hessians(kind):
    rng = np.random.default_rng(11)
    for _ in range(4):
        F = sample_F(kind, rng)
        H = _core.snh_hessian(F, MU, LAM)
        w, Q = np.linalg.eigh(H)
        scale = np.abs(w).max()
        P = _core.psd_project9(H)
        assert np.linalg.eigvalsh(P).min() >= -1e-9 * scale
        np.testing.assert_allclose(P, (Q * np.maximum(w, 0)) @ Q.T, rtol=0, atol=1e-9 * scale)
        if w.min() > 0:
            assert np.array_equal(P, H)


def test_snh_hessian_indefinite_somewhere():
    """The projection matters: SNH Hessians are indefinite at compressed or inverted F
    (otherwise the projection tests above would prove nothing about clamping)."""
    rng = np.random.default_rng(5)
    mins = [np.linalg.eigvalsh(_core.snh_hessian(sample_F(k, rng), MU, LAM)).min()
            for k in ("compressed", "inverted", "inverted_flat") for _ in range(3)]
    assert min(mins) < 0
