"""EMU's error estimate: FEM's Newton steps at EMU's answer, their certificate,
and the FEM corrections and settling that accuracy mode builds on them
(docs/DESIGN.md, "EMU's error estimate" and "The estimate's certificate")."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .. import _core
from ..core.geometry import bbox_diagonal, vertex_error
from .accuracy import (CERTIFY_CONTRACTION, CERTIFY_STEPS, DEFAULT_ACCURACY, FEM_ACCURACY_CG_FORCING,
                       STEP_FRACTION, STEP_GRAD)

__all__ = ["Estimate", "ErrorEstimator", "ESTIMATE_LAGGED_CG"]

# The error estimate's FEM corrections: PCG on the last factorisation for at
# most this many iterations before factorising (SolverOptions::lagged_cg_iterations),
# and a new factorisation once a PCG solve on it costs more than about half of
# one (SolverOptions::lagged_refresh: a sequence's later frames; DESIGN, "The FEM baselines")
ESTIMATE_LAGGED_CG, ESTIMATE_REFRESH = 25, True


@dataclass
class Estimate:
    """One solve's error estimate (Solution's fields of the same meaning)."""
    value: float | None = None        # error_estimate: |x - fem_steps[-1]|
    certified: bool | None = None     # error_estimate_certified
    steps: list | None = None         # fem_steps: [x1, x2, ...]
    note: str = ""                    # error_estimate_note
    seconds: float = 0.0              # error_estimate_time_s

    @property
    def x1(self):
        """FEM's first Newton correction (Solution.fem_correction), or None."""
        return None if self.steps is None else self.steps[0]


class ErrorEstimator:
    """FEM's Newton system for one EMU Solver's error estimates, built at first
    use (the same energy as EMU's, contact included).

    model        the Solver's _core.Model; model_points (n, 3) its rest points
    contact      the Solver's ContactTerm or None
    accuracy     the Solver's accuracy (None: strict solves); step_fraction its step test's
    steps        at most this many FEM Newton correction steps in the estimate (error_estimate_steps)
    make         make(cls, *args): the core class built with the bones' names in its errors
    """

    def __init__(self, model, model_points, contact, accuracy, step_fraction: float, steps: int, make):
        self.model, self.model_points, self.contact = model, model_points, contact
        self.accuracy, self.step_fraction, self.steps = accuracy, float(step_fraction), int(steps)
        self._make = make
        self.fem = None     # the _core.FemSolver, built at first use
        self.error = ""     # why there is none (a scene FEM does not handle)

    def structures(self) -> dict:
        """{name: bytes} of the FEM system once built ({} before)."""
        return {} if self.fem is None else {f"error estimate: {name}": int(b) for name, b in self.fem.structures()}

    def estimate(self, load, positions) -> Estimate:
        """EMU's error estimate at its answer: FEM's correction x1 and the certificate's steps from it."""
        x1, seconds, note = self.first_correction(load, positions)
        if x1 is None:
            return Estimate(note=note, seconds=seconds)
        t1 = time.perf_counter()
        certified, chain, why = self.certify(load, positions, x1)
        value = vertex_error(positions, chain[-1])   # the FEM point nearest FEM's answer
        return Estimate(value, certified, chain, note or why, seconds + time.perf_counter() - t1)

    def first_correction(self, load, positions) -> tuple:
        """(x1 or None, seconds, note): the linearised correction x1 of FEM's
        Newton steps at EMU's positions x (FemSolver::newton_correction: the
        exact step in Newton's regime, else the lower-energy one of the exact
        and PSD-filtered steps, another step after a filtered one), by which
        EMU's vertex error to FEM is estimated: vertex_error(x, x1)."""
        t0 = time.perf_counter()
        if self.fem is None and not self.error:
            opts = _core.SolverOptions()
            # the corrections of a sequence's frames (and of accuracy mode's
            # re-solves) by PCG on the last factorisation (docs/DESIGN.md, "The FEM
            # baselines: a factorisation per step, or a lagged factor")
            opts.lagged_cg_iterations = ESTIMATE_LAGGED_CG   # (without contact: its pattern changes)
            opts.lagged_refresh = ESTIMATE_REFRESH
            if self.accuracy is not None:   # settle: FEM's accuracy-mode stop, as Solver(method="fem") sets it
                opts.step_tol = self.step_fraction * self.accuracy * bbox_diagonal(self.model_points)
                opts.step_tol_grad = STEP_GRAD
                opts.step_tol_cold_scale = True
                opts.step_tol_contraction = CERTIFY_CONTRACTION
                opts.lagged_cg_forcing = FEM_ACCURACY_CG_FORCING
                opts.max_iterations = 200
            try:   # the same energy as EMU's, contact included
                self.fem = self._make(_core.FemSolver, self.model, opts, self.contact)
            except ValueError as e:   # e.g. a closed loop of joints (FEM takes trees of bones)
                self.error = f"no error estimate: {e}"
        if self.fem is None:
            return None, 0.0, self.error
        try:
            x1 = np.asarray(self.fem.newton_correction(load, positions, max_steps=self.steps))
        except RuntimeError as e:
            return None, time.perf_counter() - t0, f"no error estimate: {e}"
        return x1, time.perf_counter() - t0, ""

    def certify(self, load, x, x1) -> tuple:
        """(certified, [x1, x2, ...], note): up to CERTIFY_STEPS more FEM Newton
        corrections of x1 (exact Newton steps: PCG on the estimator's factor,
        a factorisation only where that PCG does not converge),
        by which the estimate |x - last| holds where FEM's Newton is in its
        regime at EMU's answer x: each step at most CERTIFY_CONTRACTION of the
        one before, or the last within STEP_FRACTION x the accuracy (FEM's own
        accuracy stop; the steps end early at a tenth of it). Where they do not contract, FEM's
        energy is far from quadratic about x (a softly resisted turn: Newton
        steps there cover a fraction of the way each) and the estimate can be
        several times low (docs/DESIGN.md, "The estimate's certificate")."""
        estimate = vertex_error(x, x1)
        if estimate == 0.0:   # FEM's gradient at round-off at x: no step, nothing to certify
            return True, [x1], ""
        if self.fem is None:   # an estimate from elsewhere (tests' stand-ins): no certificate
            return None, [x1], ""
        floor = STEP_FRACTION * (self.accuracy if self.accuracy is not None else DEFAULT_ACCURACY)
        chain, before = [x1], estimate
        for k in range(CERTIFY_STEPS):
            z = self._certificate_step(load, chain[-1])
            if z is None:
                return False, chain, (
                    f"the error estimate ({vertex_error(x, chain[-1]):.2g}) is not certified: FEM Newton step "
                    f"{k + 2} from EMU's answer met negative curvature or did not converge (EMU's answer is not "
                    "in FEM's Newton regime), so the true error can be several times the estimate")
            step = vertex_error(chain[-1], z)
            chain.append(z)
            # within FEM's own stop: certified at the last step, or at once where
            # even a tenfold next step would stay within it
            if step <= floor and (k == CERTIFY_STEPS - 1 or step <= 0.1 * floor):
                return True, chain, ""
            if step > CERTIFY_CONTRACTION * before:
                return False, chain, (
                    f"the error estimate ({vertex_error(x, z):.2g}) is not certified: FEM Newton step {k + 2} "
                    f"from EMU's answer moved {step:.2g}, {step / before:.2g} of the one before (Newton's regime "
                    f"needs at most {CERTIFY_CONTRACTION:g}): FEM's energy is far from quadratic about EMU's "
                    "answer (a softly resisted motion), so the true error can be several times the estimate")
            before = step
        return True, chain, ""

    def _certificate_step(self, load, y):
        """One FEM Newton correction of y for the certificate, or None."""
        if self.contact is None:
            return self.correction(load, y)
        try:   # no lagged factor with contact (its pattern changes): a step of its own
            return np.asarray(self.fem.newton_correction(load, y, max_steps=1))
        except (RuntimeError, ValueError):
            return None

    def correction(self, load, x):
        """One exact FEM Newton correction of positions x: by PCG on the
        estimator's last factor where it converges, else with a factorisation
        at x (where x moved off that factor's reach: a chain's soft turn, a
        sequence's later frames); None where the exact Newton matrix is not
        definite there (no filtered step: the certificate and accuracy mode's
        corrections compare Newton steps, certified only in Newton's regime)."""
        try:
            y = self.fem.newton_correction(load, x, hessian="newton", max_steps=1)
        except (RuntimeError, ValueError):   # ValueError: with contact, x has surfaces through each other
            return None
        y = np.asarray(y)
        return y if np.all(np.isfinite(y)) else None

    def settle(self, load, x):
        """A FEM solve from positions x with FEM's accuracy-mode stop, on the
        estimator (its lagged factor): accuracy mode's answer where EMU's
        estimate could not certify itself. (core result, the last two steps'
        vertex lengths) or None where it fails."""
        steps, last = [], [np.asarray(x, dtype=np.float64)]

        def record(_, positions):
            p = np.array(positions)
            steps.append(vertex_error(last[0], p))
            last[0] = p
            return False
        try:
            r = self.fem.solve_from(load, x, on_iteration=record)
        except (RuntimeError, ValueError):
            return None
        if not r.converged or not np.all(np.isfinite(r.positions)):
            return None
        return r, steps[-2:]
