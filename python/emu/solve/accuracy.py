"""Accuracy mode: EMU asked for a vertex error to FEM instead of an alpha.

One solve of ``Solver(accuracy=e)`` is: solve at the current alpha, estimate
the error to FEM (FEM's Newton correction x1 of EMU's answer x), and while
the estimate is above ACCEPT x e either return EMU's answer corrected by
FEM Newton steps (where those steps certify themselves: they contract, or
one is as short as FEM's own accuracy stop asks) or raise alpha and solve
again from x1; where the estimate cannot certify itself (its further FEM
Newton steps do not contract) settle the answer by a FEM solve from it; then carry
an alpha over to the next solve. docs/DESIGN.md,
"Accuracy as the knob" and "Accuracy mode as shipped", measure every rule here.

The controller drives one solve through a small typed port, AccuracyPort (the
Solver makes one per solve): EMU runs, alpha, FEM corrections and settling.
"""
from __future__ import annotations

import math
from typing import ContextManager, Protocol
import time
import warnings

import numpy as np

from ..core.geometry import vertex_error

__all__ = ["AccuracyMode", "AccuracyPort", "AccuracyWarning"]


class AccuracyWarning(UserWarning):
    """EMU with ``accuracy=``: the error estimate stayed above the accuracy asked
    for after every alpha tried (see Solution.accuracy_reached)."""


# Accept a solve whose error estimate is within ACCEPT x the target (a margin
# for the estimate's own error: docs/DESIGN.md, "EMU's error estimate"), aim new alphas at AIM
# x the target; stop iterating when a full step moves no vertex by more than
# STEP_FRACTION x the target; at most MAX_ALPHA_ATTEMPTS solves per call.
ACCEPT, AIM, STEP_FRACTION, MAX_ALPHA_ATTEMPTS = 0.6, 0.4, 0.1, 5
# A re-solve warm-started from EMU's own F at a larger alpha runs CG to this
# forcing term, so that the step test sees Newton steps (with a loose one a
# single CG iteration can pass the test while missing a bone's turn). A re-solve
# from x1 (FEM's correction: the bones already turned) needs no such cap.
ACCURACY_CG_FORCING = 0.01
# FEM-corrected answers: the corrections x2 of x1 and x3 of x2 contract,
# |x2 - x1| <= CORRECTION_CONTRACTION |x1 - x| (and within ACCEPT x target)
# and |x3 - x2| <= CORRECTION_CONTRACTION |x2 - x1|, and x4's step stays
# no longer than |x2 - x1| (else the estimate is not certified: settled); or, within
# MAX_CORRECTIONS corrections, one moves no vertex by more than STEP_FRACTION
# x target (FEM's own accuracy stop, for corrections that do not contract
# twice in a row).
CORRECTION_CONTRACTION, MAX_CORRECTIONS, CORRECTION_LASTS = 0.3, 4, 1.0
# The error estimate |y - x| (y: FEM Newton steps from EMU's answer x, the
# first x1 on a factorisation, up to CERTIFY_STEPS more by PCG on it) is
# certified where every step after x1 is at most CERTIFY_CONTRACTION of the
# one before, or the last is within STEP_FRACTION x target (FEM's own stop;
# the steps end early at a tenth of it). Where FEM's Newton converges at least linearly at rate r
# the estimate is then at least (1 - r^2) of the true error (0.75 at r =
# 0.5), so an accepted estimate (<= ACCEPT x target) keeps the true error
# within 0.8 x target; two steps in a row, because one short step after a
# long one also happens far from Newton's regime (on real bones: 0.25 and
# within FEM's stop, then 2.75). Otherwise FEM's energy is far from quadratic about x (a softly
# resisted turn) and the estimate can be several times low: the answer is
# settled by a FEM solve from y (docs/DESIGN.md, "The estimate's certificate").
CERTIFY_CONTRACTION, CERTIFY_STEPS = 0.5, 2
# EMU without alpha or accuracy: accuracy = DEFAULT_ACCURACY, starting at DEFAULT_ALPHA.
DEFAULT_ACCURACY, DEFAULT_ALPHA = 0.01, 100.0
# The step test applies once |g| <= STEP_GRAD max(|g_0|, |g| at the cold start
# under the same load) ...
STEP_GRAD = 1e-2
# ... and CG is asked for no more than Eisenstat-Walker's forcing term there.
ACCURACY_CG_FORCING_MIN = math.sqrt(STEP_GRAD)
# FEM's accuracy-mode solves on a lagged factor (lagged_factor=True, and the settle of an
# answer whose estimate did not certify itself) stop on a short step only where that step is
# an accurate Newton step: PCG on the lagged factor to this relative residual, the exact
# Hessian, and a contraction seen (step_tol_contraction). At ACCURACY_CG_FORCING_MIN PCG
# leaves most of a softly resisted turn out of the step, and a short step stopped a settle
# 2.2% from FEM (arm26, cold at the biceps' peak; DESIGN).
FEM_ACCURACY_CG_FORCING = 1e-3
# A re-solve at a larger alpha whose estimate is above RESOLVE_GAIN x the one
# before shows the error is not alpha's: no more raises without FEM
# corrections, and none carried over. The alpha carried to the next solve is
# at most ALPHA_MAX_RATIO x max(the alpha given, DEFAULT_ALPHA).
RESOLVE_GAIN, ALPHA_MAX_RATIO = 0.9, 1e4
# The next solve's alpha is lowered (at most by half, towards AIM x target)
# where the estimate is below AIM x target, but not below ALPHA_MIN: where
# geometry, not alpha, sets the error (a bone's turn) the estimate stays low
# whatever alpha, and halving alpha every frame would drive it far down and
# slow every solve (docs/DESIGN.md, "Accuracy as the knob").
ALPHA_MIN = 10.0
# error ~ alpha^-P_RAISE when raising (p varies by scene; 0.75 makes a
# second raise rare), ~ alpha^-1 when lowering; a raise is by a factor in
# [RAISE_MIN, RAISE_MAX].
P_RAISE, RAISE_MIN, RAISE_MAX = 0.75, 1.5, 30.0
# After a settle (an estimate that did not certify itself) the next alpha is raised by at most
# this: EMU's distance to FEM there is a softly resisted turn's, which alpha^-P_RAISE does not
# describe, and the full raise drove upper_limb's alpha 132 -> 65,736 mu over four settled
# frames, each later frame 50+ Newton steps (examples: upper_limb 4.92 -> 3.00 s, arm26
# 8.41 -> 5.87 s at a cap of 2, the same largest errors; DESIGN, "The estimate's certificate").
SETTLE_RAISE_MAX = 2.0


def stop_estimate(steps) -> float:
    """What FEM's accuracy stop leaves after its last steps (steps: their
    lengths, the last two or fewer counted): at most the last step where the last two halve
    (a geometric tail at rate r <= 1/2 sums to r / (1 - r) <= 1 of it), else
    the last two summed (a bound: the steps need not shrink at once)."""
    return float(steps[-1] if len(steps) >= 2 and steps[-1] <= 0.5 * steps[-2] else sum(steps[-2:]))


class AccuracyPort(Protocol):
    """What accuracy mode drives: one solve's EMU runs and FEM steps under one load
    (the Solver makes one per solve)."""

    alpha: float          # EMU's alpha (relative to the reference shear modulus) of the next run
    has_contact: bool     # the scene has contact (no warm EMU re-solve from a FEM point)

    def run(self, start):
        """One EMU solve with its error estimate (a Solution), from start: None (rest), a
        Solution, (m, 3, 3) deformation gradients, or (n, 3) positions."""

    def set_alpha(self, alpha: float) -> None:
        """The alpha of the following runs (this solve's and later solves')."""

    def tight_cg(self) -> ContextManager:
        """A context in which runs take CG to ACCURACY_CG_FORCING."""

    def correction(self, x):
        """One FEM Newton correction of positions x (PCG on the estimate's factor, else a
        factorisation at x), or None."""

    def settle(self, x):
        """A FEM solve from positions x to FEM's accuracy stop: (core result, the last two
        steps' lengths), or None where it fails."""

    def inverted(self, x) -> int:
        """How many tets are inverted at positions x."""

    def elapsed(self) -> float:
        """Seconds since the solve began (an iterate's time)."""


class AccuracyMode:
    """The accuracy controller of one EMU Solver: its target, whether FEM
    corrections are on, and the bound on the alpha it carries between solves."""

    def __init__(self, target: float, fem_correction: bool, alpha: float):
        self.target = float(target)
        self.fem_correction = bool(fem_correction)
        self.alpha_max = ALPHA_MAX_RATIO * max(alpha, DEFAULT_ALPHA)   # automatic raises stop there
        self.warned_settle = False   # settle warns once per Solver

    def bound_from(self, alpha: float) -> None:
        """The user set alpha: the carried alpha's bound moves with it."""
        self.alpha_max = ALPHA_MAX_RATIO * max(alpha, DEFAULT_ALPHA)

    def raise_factor(self, error: float) -> float:
        """The factor on alpha that brings an error to AIM x target (error ~ alpha^-P_RAISE)."""
        return min(RAISE_MAX, max(RAISE_MIN, (error / (AIM * self.target)) ** (1 / P_RAISE)))

    def solve(self, port: AccuracyPort, start):
        """Solutions at increasing alphas until the estimate is within ACCEPT x
        target (or corrected), from start (as AccuracyPort.run takes it); returns
        the last with its totals over the solves."""
        target = self.target
        sol = port.run(start)
        runs = [sol]
        estimate_s = sol.error_estimate_time_s
        alpha_start = highest = port.alpha
        before, stalled = None, False   # before: the estimate before a re-solve
        while (sol.converged and sol.error_estimate is not None and sol.error_estimate > ACCEPT * target
               and (sol.error_estimate_certified is not False or not self.fem_correction)):
            own = sol.error_estimate   # a correction replaces it with its last step's length
            stalled = before is not None and own > RESOLVE_GAIN * before
            t1 = time.perf_counter()
            corrected = self.correct(port, sol) if self.fem_correction else False
            estimate_s += time.perf_counter() - t1   # the corrections count as estimation time
            if sol.error_estimate_certified is False and self.fem_correction:
                break   # settled below
            if corrected:
                # the next solve starts at this one's alpha: a correction costs less than a
                # raised alpha's CG on every later frame (DESIGN, "Accuracy mode: FEM-corrected answers")
                port.set_alpha(alpha_start)
                if sol.iterates is not None:   # the corrected answer: after the estimates
                    sol.iterates.append((port.elapsed(), sol.positions))
                break
            if (stalled and not self.fem_correction) or len(runs) >= MAX_ALPHA_ATTEMPTS:
                if stalled:
                    port.set_alpha(alpha_start)
                break
            before, stalled = own, False
            port.set_alpha(port.alpha * self.raise_factor(own))
            highest = port.alpha
            x1 = sol.fem_correction
            if x1 is not None and not port.has_contact:
                # from FEM's correction: the positions are already near FEM's,
                # EMU only settles at the new alpha (docs/DESIGN.md, "Accuracy mode as shipped")
                sol = port.run(x1)
            else:
                with port.tight_cg():
                    sol = port.run(sol)
            runs.append(sol)
            estimate_s += sol.error_estimate_time_s
        if sol.converged and sol.error_estimate_certified is False and self.fem_correction:
            t1 = time.perf_counter()
            if self.settle(port, sol) and sol.iterates is not None:   # the settled answer, last
                sol.iterates.append((port.elapsed(), sol.positions))
            estimate_s += time.perf_counter() - t1
        self._totals(sol, runs, estimate_s)
        if sol.error_estimate is not None:
            self._report(sol, len(runs), highest, stalled)
        if (sol.error_estimate is not None and sol.error_estimate < AIM * target and not sol.corrected
                and (sol.error_estimate_certified is not False or not self.fem_correction)):
            lower = max(port.alpha * 0.5, port.alpha * sol.error_estimate / (AIM * target))
            port.set_alpha(max(lower, min(port.alpha, ALPHA_MIN)))
        if port.alpha > self.alpha_max:   # what the next solve starts at stays bounded
            port.set_alpha(self.alpha_max)
        return sol

    @staticmethod
    def _totals(sol, runs, estimate_s) -> None:
        """The last solution carries the totals over all solves (its history: one block per solve)."""
        sol.solve_time_s = sum(r.solve_time_s for r in runs)
        sol.error_estimate_time_s = estimate_s
        sol.iterations = sum(r.iterations for r in runs)
        sol.cg_iterations = sum(r.cg_iterations for r in runs)
        sol.phase_times = {k: sum(r.phase_times[k] for r in runs) for k in runs[0].phase_times}
        sol.phase_times["error_estimate"] = estimate_s
        sol.history = {k: np.concatenate([r.history[k] for r in runs]) for k in runs[0].history}
        sol.settings["alpha_attempts"] = len(runs)

    def settle(self, port: AccuracyPort, sol) -> bool:
        """EMU's estimate not certified (sol.error_estimate_certified False):
        the answer settled by a FEM solve to FEM's own accuracy stop, from the
        certificate's last correction (fem_steps[-1]); its estimate FEM's last step where the
        steps halve, else the last two summed (a bound). The next solve's alpha is raised as
        a re-solve's would be from the distance settled, by at most SETTLE_RAISE_MAX
        (EMU's answers near the target make the settling short). False (the solution unchanged)
        where that solve fails."""
        settled = port.settle(sol.fem_steps[-1])
        if settled is None:
            return False
        r, steps = settled
        x = sol.positions
        answer = np.asarray(r.positions)
        distance = vertex_error(x, answer)
        own = sol.error_estimate
        sol.positions, sol.corrected = answer, True
        sol.error_estimate = stop_estimate(steps)
        sol.error_estimate_note = (f"EMU's answer (estimated {own:.2g} from FEM's, not certified: its FEM Newton "
                                   f"steps did not contract) settled by a FEM solve from it ({r.iterations} Newton "
                                   f"steps, {distance:.2g} from EMU's answer); the estimate is the length of its "
                                   "last steps")
        sol.inverted_tets = port.inverted(answer)
        if distance > AIM * self.target:   # at most SETTLE_RAISE_MAX: see its comment
            port.set_alpha(min(self.alpha_max, port.alpha * min(SETTLE_RAISE_MAX, self.raise_factor(distance))))
        if not self.warned_settle:
            self.warned_settle = True
            warnings.warn(AccuracyWarning(
                f"EMU's error estimate could not certify itself (its FEM Newton steps from EMU's answer did "
                f"not contract: FEM's energy is far from quadratic there, e.g. a softly resisted turn); the answer "
                f"was settled by a FEM solve from EMU's, {distance:.2g} from it where the estimate read {own:.2g}. "
                "Such answers are settled so (Solution.corrected, error_estimate_note); where most are, "
                "method='fem' is likely faster for this scene"), stacklevel=5)
        return True

    def _report(self, sol, attempts: int, highest: float, stalled: bool) -> None:
        target = self.target
        sol.accuracy_reached = bool(sol.error_estimate <= target and (sol.error_estimate_certified is not False
                                                                      or sol.corrected))
        if sol.accuracy_reached:
            return
        if sol.error_estimate <= target:   # an estimate within the target that did not certify itself
            if sol.converged:
                warnings.warn(AccuracyWarning(f"accuracy {target:g} not certified: {sol.error_estimate_note}"),
                              stacklevel=4)
            return
        # e.g. far past the activations that invert tets, where EMU and FEM
        # find different inverted equilibria (docs/stability.md)
        sol.error_estimate_note = f"accuracy {target:g} not reached: the error estimate is " \
            f"{sol.error_estimate:.2g}" + (
                f" after {attempts} alpha(s), up to alpha = {highest:.3g} mu" +
                ("; raising alpha did not lower it" if stalled else "") +
                "; use method='fem' for this load" if sol.converged
                else f" where the solve stopped ({sol.status})")
        if sol.converged:   # a solve that stopped early says so in its status already
            warnings.warn(AccuracyWarning(sol.error_estimate_note), stacklevel=4)

    def _verdict(self, steps) -> tuple:
        """What FEM's correction steps so far say (steps: |x2 - x1|, |x3 - x2|,
        ...): ("answer", k, estimate) the answer is point k (x1 is 0); ("not
        certified",) the contraction did not last; ("more",) another step
        decides. Where x1 overshot (|x2 - x1| over CORRECTION_CONTRACTION |x1 - x|)
        the steps from x2 on decide all the same: x2's error is theirs to tell."""
        tenth = 0.1 * STEP_FRACTION * self.target   # the certificate's early exit
        if len(steps) >= 2 and steps[1] <= CORRECTION_CONTRACTION * steps[0]:
            # x2, estimated by the way FEM's steps still go from it, where x4's step
            # is no longer than |x2 - x1| (CORRECTION_LASTS): along a chain's soft turn
            # the steps alternate long and short, the third longer than the first
            if steps[1] <= tenth:
                return ("answer", 1, 2 * steps[1])
            if len(steps) >= 3:
                if steps[2] <= max(CORRECTION_LASTS * steps[0], tenth):
                    return ("answer", 1, steps[1] + steps[2])
                return ("not certified",)
        elif len(steps) >= 2 and steps[-1] <= STEP_FRACTION * self.target:
            # FEM's own accuracy stop, estimated by the last two steps summed (a bound: a
            # geometric tail read from two steps was 2.3x low along upper_limb's soft turn)
            return ("answer", len(steps), steps[-2] + steps[-1])
        return ("more",)

    def correct(self, port: AccuracyPort, sol) -> bool:
        """EMU's estimate above ACCEPT x target: FEM Newton corrections from the
        estimate's x1 (x2 of x1, x3 of x2, ... at most MAX_CORRECTIONS), each
        certified or not as FEM's own solves are:
        - the corrections contract (|x3 - x2| <= CORRECTION_CONTRACTION |x2 -
          x1|: FEM's Newton in its fast regime from x2) and the next step |x4 - x3|
          is no longer than |x2 - x1| (none asked where |x3 - x2| is within
          a tenth of FEM's accuracy stop): x2, estimated |x3 - x2| + |x4 - x3|
          (2 |x3 - x2| without x4). Where x4's step is longer, the contraction
          did not last (along a chain's soft turn FEM's steps alternate long and
          short): the estimate is marked not certified, fem_steps extended to
          x4, and False returned; the caller settles the answer;
        - or a correction moves no vertex by more than STEP_FRACTION x target
          (FEM's accuracy-mode stop): that correction's result, with its last two
          steps' lengths summed as its estimate (a bound: the steps need not
          shrink at once, and along a chain's soft turn they alternate).
        Corrections are asked only while they shrink (|x2 - x1| < |x1 - x|) and
        |x2 - x1| is within ACCEPT x target or already contracts to x3 (x1 may
        overshoot EMU's error along a bone's turn and x2 still land in FEM's
        Newton regime: upper_limb). Then the solution's positions are the corrected
        answer and True is returned; otherwise the solution is left as it was
        and False returned."""
        target = self.target
        x, x1 = sol.positions, sol.fem_correction
        if x1 is None:
            return False
        own = vertex_error(x, x1)
        points = list(sol.fem_steps) if sol.fem_steps else [x1]   # the estimate's and certificate's own steps
        if len(points) == 1:
            if (x2 := port.correction(x1)) is None:
                return False
            points.append(x2)
        steps = [vertex_error(a, b) for a, b in zip(points, points[1:])]
        # corrections that do not shrink, or stay longer than the target without
        # contracting after: no FEM point near enough to be worth another
        if not (steps[0] < own and (steps[0] <= ACCEPT * target or
                                    (len(steps) >= 2 and steps[1] <= CORRECTION_CONTRACTION * steps[0]))):
            return False
        while True:
            verdict = self._verdict(steps)
            if verdict[0] == "answer":
                answer, estimate = points[verdict[1]], verdict[2]
                break
            if verdict[0] == "not certified":   # settled from the last point by the caller
                sol.error_estimate_certified, sol.fem_steps = False, points
                return False
            if len(steps) >= MAX_CORRECTIONS:
                return False
            y = port.correction(points[-1])
            if y is None:
                return False
            points.append(y)
            steps.append(vertex_error(points[-2], y))
        sol.positions, sol.corrected, sol.error_estimate = answer, True, estimate
        sol.error_estimate_note = (f"EMU's answer (estimated {own:.2g} from FEM's) corrected by {len(steps)} FEM "
                                   "Newton steps; the estimate is the length of the last ones")
        sol.inverted_tets = port.inverted(answer)
        return True
