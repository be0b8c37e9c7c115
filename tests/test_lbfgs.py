"""EMU's L-BFGS step (Solver(step="lbfgs")): the Woodbury step as its initial
inverse Hessian, curvature pairs on top; the same EMU equilibrium as
Newton-Krylov at the same alpha, with no CG."""
from __future__ import annotations

import pytest

import emu
from conftest import SMALL_KINDS


@pytest.mark.parametrize("name", list(SMALL_KINDS))
def test_lbfgs_reaches_the_newton_krylov_equilibrium(name):
    make, act, normalized = SMALL_KINDS[name]
    scene = make()
    kw = dict(alpha=100, error_estimate=False)  # the default tolerance (L-BFGS meets round-off near 1e-7)
    nk = emu.Solver(scene, "emu", **kw).solve(act, normalized=normalized)
    lb = emu.Solver(scene, "emu", step="lbfgs", **kw).solve(act, normalized=normalized)
    assert nk.converged and lb.converged, (nk.status, lb.status)
    assert lb.cg_iterations == 0 and lb.iterations > nk.iterations
    assert emu.vertex_error(lb.positions, nk.positions) < 1e-5
    assert lb.label == "emu_lbfgs"


def test_lbfgs_beats_the_plain_woodbury_step():
    # The curvature pairs on top of the paper's step: far fewer iterations.
    make, act, normalized = SMALL_KINDS["fusiform (pinned, tendons)"]
    scene = make()
    kw = dict(alpha=100, error_estimate=False, rtol_grad=1e-6)
    plain = emu.Solver(scene, "emu", step="woodbury", **kw).solve(act, normalized=normalized)
    lb = emu.Solver(scene, "emu", step="lbfgs", **kw).solve(act, normalized=normalized)
    assert lb.converged
    assert lb.iterations < plain.iterations / 3


def test_lbfgs_memory_is_checked():
    make, _, _ = SMALL_KINDS["fusiform (pinned, tendons)"]
    with pytest.raises(ValueError, match="lbfgs_memory must be >= 1"):
        emu.Solver(make(), "emu", step="lbfgs", lbfgs_memory=0)
