"""The envelope identity, an independent check of the whole EMU pipeline.

Without loads, EMU minimises J(x, F) = sum_t V_t [Psi_t(F_t) + alpha w_t/2 |F_t - F_t(x)|^2]
over F and then x (the ACAP fit x*(F) inside E(F)). Minimising over F first
instead gives, per tet, the Moreau envelope of the density,
    env_t(G) = min_F Psi_t(F) + alpha w_t/2 |F - G|^2,
so EMU's positions are the FEM equilibrium of sum_t V_t env_t(F_t(x)). Here a
numpy FEM Newton on that enveloped energy (its own per-tet inner Newton for
the envelope, its own SNH, a dense Hessian) must land on EMU's positions."""
from __future__ import annotations

import numpy as np
import pytest

import emu
from emu.build.procedural import fusiform

from conftest import gradient_operator
from test_solvers import snh_numpy


class EnvelopeFEM:
    """E(x) = sum_t V_t env_t(F_t(x)) over the free vertices, env from SNH + a/2 |F u|^2."""

    def __init__(self, points, tets, fibers, mu, lam, a, weight, alpha, pinned):
        G, self.vol = gradient_operator(points, tets)
        self.G = G.tocsr()
        self.mu, self.lam, self.a, self.u = mu, lam, a, fibers   # mu, lam, a: per tet (m,)
        self.c = alpha * weight                                  # alpha w per tet
        self.UU = np.einsum("tij,kl->tikjl", np.einsum("ti,tj->tij", fibers, fibers), np.eye(3)).reshape(-1, 9, 9)
        n = len(points)
        self.free = np.setdiff1d(np.arange(n), pinned)
        self.fdof = (3 * self.free[:, None] + np.arange(3)).ravel()
        self.Fs = None   # the inner minimisers, warm-started

    def psi(self, F):
        e, P, H = np.empty(len(F)), np.empty_like(F), np.empty((len(F), 9, 9))
        for mu, lam in set(zip(self.mu.tolist(), self.lam.tolist())):   # one material at a time
            k = (self.mu == mu) & (self.lam == lam)
            e[k], P[k], H[k] = snh_numpy(F[k], mu, lam, hessian=True)
        Fu = np.einsum("tij,tj->ti", F, self.u)
        e = e + 0.5 * self.a * (np.einsum("ti,ti->t", Fu, Fu) - 1.0)
        P = P + self.a[:, None, None] * np.einsum("ti,tj->tij", Fu, self.u)
        H = H + self.a[:, None, None] * self.UU
        return e, P, H

    def envelope(self, Gm):
        """Per tet: F* = argmin Psi(F) + c/2 |F - G|^2 (Newton), env, its
        gradient c (G - F*) and Hessian c I - c^2 (H(F*) + c I)^-1 (column-major vec)."""
        F = Gm.copy() if self.Fs is None else self.Fs.copy()
        c = self.c[:, None, None]
        for _ in range(50):
            _, P, H = self.psi(F)
            r = (P + c * (F - Gm)).transpose(0, 2, 1).reshape(-1, 9)
            A = H + self.c[:, None, None] * np.eye(9)
            d = np.linalg.solve(A, r[:, :, None])[:, :, 0]
            F = F - d.reshape(-1, 3, 3).transpose(0, 2, 1)
            if np.abs(d).max() < 1e-14:
                break
        self.Fs = F
        e, P, H = self.psi(F)
        env = e + 0.5 * self.c * np.einsum("tij,tij->t", F - Gm, F - Gm)
        grad = c * (Gm - F)
        A = H + self.c[:, None, None] * np.eye(9)
        Henv = self.c[:, None, None] * np.eye(9) - (self.c ** 2)[:, None, None] * np.linalg.inv(A)
        return env, grad, Henv

    def _F(self, x):
        return (self.G @ x).reshape(-1, 3, 3).transpose(0, 2, 1)

    def solve(self, x0, gtol=1e-11):
        import scipy.linalg as sl
        import scipy.sparse as sp

        x = x0.ravel().copy()
        fd = self.fdof
        g0 = None
        for it in range(200):
            env, P, H = self.envelope(self._F(x))
            g = (self.G.T @ (self.vol[:, None] * P.transpose(0, 2, 1).reshape(-1, 9)).ravel())[fd]
            g0 = np.linalg.norm(g) if g0 is None else g0
            if np.linalg.norm(g) <= gtol * g0:
                return x.reshape(-1, 3), it
            def assembled(Hb):
                K = (self.G.T @ sp.block_diag(list(Hb * self.vol[:, None, None]), format="csr") @ self.G).toarray()
                return K[np.ix_(fd, fd)]
            try:   # the exact Hessian where it is definite, else per-tet PSD-projected blocks
                d = -sl.cho_solve(sl.cho_factor(assembled(H)), g)
            except np.linalg.LinAlgError:
                w, Q = np.linalg.eigh(H)
                d = -sl.cho_solve(sl.cho_factor(assembled(np.einsum("tij,tj,tkj->tik", Q, np.maximum(w, 0), Q))), g)
            E0, s = np.sum(self.vol * env), 1.0
            while True:
                xn = x.copy()
                xn[fd] += s * d
                if np.sum(self.vol * self.envelope(self._F(xn))[0]) <= E0 + 1e-4 * s * (g @ d) or s < 1e-8:
                    break
                s *= 0.5
            x = xn
        raise AssertionError("the enveloped FEM Newton did not converge")


@pytest.mark.parametrize("alpha", [3.0, 30.0, 300.0])
def test_emu_positions_are_the_fem_equilibrium_of_the_enveloped_energy(alpha):
    m = fusiform(2)   # tendon caps: a second material and ACAP weight
    s = emu.scenes.fusiform(2, warn=False)
    solver = emu.Solver(s, "emu", alpha=alpha, rtol_grad=1e-10, error_estimate=False)
    sol = solver.solve({"belly": 5e4})
    assert sol.converged, sol.status
    md = solver._core.model   # the tets in the solver's order (its unknowns' order)
    a = np.where(np.asarray(md.muscle) >= 0, 5e4, 0.0)
    ref = EnvelopeFEM(np.asarray(md.rest), np.asarray(md.tets).astype(np.int64), np.asarray(md.fiber),
                      np.asarray(md.mu), np.asarray(md.lam), a, np.asarray(md.acap_weight),
                      solver.settings["alpha_absolute"], np.asarray(md.pinned))
    x, its = ref.solve(np.asarray(md.rest))
    assert its > 2
    scale = emu.bbox_diagonal(m.points)
    moved = np.abs(x - m.points).max() / scale
    assert moved > 1e-2, "the load must deform the mesh for the identity to mean anything"
    # EMU's positions are the enveloped FEM's ...
    assert emu.vertex_error(sol.positions, x, m.points) < 1e-7
    # ... and not FEM's (the identity is not the trivial alpha -> infinity limit)
    fem = emu.solve(s, {"belly": 5e4}, "fem", rtol_grad=1e-9)
    assert emu.vertex_error(sol, fem) > 1e-3
    # EMU's F are the inner minimisers of the envelope at its positions
    Fref = ref.Fs
    np.testing.assert_allclose(sol.F[np.asarray(md.scene_tet)], Fref, rtol=0, atol=1e-6)
