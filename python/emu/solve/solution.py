"""A solve's result: the Solution of one call of Solver.solve, and its phase times."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Solution", "HISTORY_COLUMNS", "PHASES", "phase_times_of", "solution_of"]

HISTORY_COLUMNS = ("iteration", "energy", "grad_norm", "step", "time_s", "cg_iterations", "backtracks")


@dataclass
class Solution:
    """The result of one solve.

    positions   (n, 3) equilibrium positions (EMU: the ACAP fit x*(F))
    converged   whether the stopping test passed; status says why it stopped
    time_s      the whole solve, as a wall clock sees it: every solve at every
                alpha, the error estimates and FEM corrections, the Python
                around them (setup_time_s, the Solver's construction, apart);
                its parts: solve_time_s (the solver's iterations) and
                error_estimate_time_s, and phase_times
    solve_time_s  the solver's own iterations (every alpha's solve)
    history     dict of per-iteration arrays (entry 0 is the start): energy,
                grad_norm, time_s (since the solve began, estimates included), step,
                cg_iterations, backtracks
    F           (m, 3, 3) EMU's deformation-gradient unknowns (None for FEM)
    iterates    with solve(record_iterates=True): one (time_s, positions (n, 3))
                per iterate, the start first (see emu.error_history)
    error_estimate  EMU: the estimated vertex error to the converged FEM answer
                (the measure of emu.vertex_error): the distance from EMU's
                positions to the last of up to three Newton corrections of the
                FEM energy from them, fem_steps[-1] (docs/DESIGN.md: how it was
                validated; see error_estimate_certified); None for FEM, or where
                it is not available (error_estimate_note says why)
    inverted_tets  how many tets are inverted or collapsed at ``positions``
                (emu.inverted_tets lists them)
    emu_positions  EMU: its own answer, the ACAP fit x*(F) of its unknowns F
                (None for FEM); ``positions`` is the same array unless corrected
    corrected   EMU with ``accuracy=``: True where ``positions`` are EMU's answer
                corrected by FEM Newton steps (the step the error estimate
                computes, then exact Newton steps on the estimator's factor),
                because EMU's own estimate missed the accuracy and those steps
                converge (emu.solve.accuracy.AccuracyMode.correct); error_estimate is
                then the length of the last step(s)
    contact     scenes with contact (Scene.enable_contact): {"pairs": point-triangle and
                edge-edge pairs within the barrier's reach, "min_distance": the smallest
                gap between surfaces that may touch (inf: none within reach),
                "intersecting": False (checked)}; None otherwise
    fem_correction  EMU with an error estimate: the FEM Newton correction x1 of
                emu_positions
    fem_steps   EMU with an error estimate: [x1, x2, ...] the FEM Newton
                corrections the estimate and its certificate computed (x1 is
                fem_correction; the estimate is vertex_error(emu_positions,
                fem_steps[-1]))
    fem_check   (a property) fem_steps[-1] where the certificate took a step
                beyond x1, else None
    error_estimate_certified  EMU with an error estimate: True where the
                certificate's FEM Newton steps after x1 each contract (at most
                CERTIFY_CONTRACTION of the one before, or the last as short as
                FEM's own accuracy stop): FEM's Newton is in its regime at EMU's
                answer and the estimate holds; False where they do not (a
                softly resisted turn, a valley far from quadratic: the estimate
                can be several times low; accuracy mode then settles the answer
                by a FEM solve from it, and error_estimate_note says so); None
                without an estimate
    accuracy_reached  EMU with ``accuracy=``: whether the error estimate ended
                within the accuracy asked for (False: an AccuracyWarning, and
                error_estimate_note says by how much it missed); None otherwise
    velocities  a time step's (solve_frames with dynamics=emu.Dynamics): (n, 3) vertex velocities
                at its end; None for a quasi-static solve
    phase_times seconds per phase of the solve, summing to time_s: hessian
                (element Hessian blocks; FEM: and their assembly), preconditioner
                (EMU: its rebuilds and the bone coarse space), linear_solve (FEM:
                factorisations and back-substitutions; EMU: CG), line_search,
                step (the accepted step and its gradient), error_estimate (EMU:
                estimates and FEM corrections), other (the rest)
    """
    method: str
    positions: np.ndarray
    converged: bool
    status: str
    iterations: int
    cg_iterations: int
    time_s: float
    setup_time_s: float
    energy: float
    grad_norm: float
    grad_norm0: float
    rel_energy_change: float
    history: dict = field(repr=False)
    F: np.ndarray | None = field(default=None, repr=False)
    settings: dict = field(default_factory=dict)
    filtered_steps: int = 0          # iterations that fell back to the PSD-filtered Hessian
    exact_attempts_failed: int = 0   # FEM: factorisations that found the exact Hessian indefinite
    factorizations: int = 0          # sparse Cholesky factorisations of a Newton matrix (FEM)
    negative_curvature_steps: int = 0  # FEM: steps that left a saddle along negative curvature
    neutral_modes: list = field(default_factory=list)  # [(bone, unit axis)] turns nothing resists
    iterates: list | None = field(default=None, repr=False)
    error_estimate: float | None = None
    error_estimate_time_s: float = 0.0
    error_estimate_note: str = ""
    phase_times: dict = field(default_factory=dict, repr=False)
    inverted_tets: int = 0           # tets with non-positive volume at the returned positions
    accuracy_reached: bool | None = None
    emu_positions: np.ndarray | None = field(default=None, repr=False)
    corrected: bool = False
    fem_correction: np.ndarray | None = field(default=None, repr=False)
    error_estimate_certified: bool | None = None
    fem_steps: list | None = field(default=None, repr=False)
    contact: dict | None = None      # scenes with contact: active pairs and minimum gap at positions
    solve_time_s: float = 0.0        # the solver's iterations alone (time_s: the whole solve)
    velocities: np.ndarray | None = field(default=None, repr=False)  # time steps (emu.Dynamics): (n, 3)

    def __repr__(self) -> str:
        """One line: what a result is, not its arrays (positions, history: the fields)."""
        est = "" if self.error_estimate is None else f", error_estimate={self.error_estimate:.2g}"
        return (f"Solution(method={self.method!r}, status={self.status!r}, iterations={self.iterations}, "
                f"time_s={self.time_s:.3g}{est}, vertices={len(self.positions)})")

    @property
    def fem_check(self) -> np.ndarray | None:
        """The certificate's last FEM Newton correction beyond x1 (None: none taken)."""
        return self.fem_steps[-1] if self.fem_steps and len(self.fem_steps) > 1 else None

    def summary(self) -> str:
        cg = f" ({self.cg_iterations} CG)" if self.cg_iterations else ""
        state = "converged" if self.converged else f"NOT converged ({self.status})"
        est = f", {self.inverted_tets} inverted tet(s)" if self.inverted_tets else ""
        if self.error_estimate is not None:
            est += f", estimated error to FEM {self.error_estimate:.1e} of the diagonal"
        if self.accuracy_reached is False:
            est += f" ({self.error_estimate_note})"
        if self.corrected and self.error_estimate_certified is False:
            est += " (EMU's estimate did not certify itself: its answer settled by a FEM solve)"
        elif self.corrected:
            est += " (EMU's answer corrected by FEM Newton steps)"
        return (f"{self.label}: {state} in {self.iterations} iterations{cg}, "
                f"{self.time_s:.3f} s{self._parts()} (+{self.setup_time_s:.3f} s setup), |g|/|g0| = "
                f"{self.grad_norm / self.grad_norm0 if self.grad_norm0 else 0:.2e}{est}")

    def _parts(self) -> str:
        if not self.error_estimate_time_s:
            return ""
        return f" (solve {self.solve_time_s:.3f} s, error estimate {self.error_estimate_time_s:.3f} s)"

    @property
    def label(self) -> str:
        if self.method == "emu":
            label = f"emu_{self.settings.get('step', 'newton-krylov').replace('-', '_')}"
            if self.settings.get("preconditioner") == "schur":
                label += "_schur"
            return label
        return "fem_lagged_cg" if self.settings.get("lagged_factor") else self.method


PHASES = ("hessian", "preconditioner", "linear_solve", "line_search", "step")


def phase_times_of(r, estimate_s: float) -> dict:
    """Solution.phase_times of one solve from a core SolveResult and its estimate's seconds
    (other: the rest of the solver's time; Solver.solve makes it the rest of the whole)."""
    times = {name: float(getattr(r.phases, name)) for name in PHASES}
    times["other"] = max(0.0, float(r.time_s) - sum(times.values()))
    times["error_estimate"] = float(estimate_s)
    return times


def solution_of(r, method: str, positions, estimate, *, status: str, setup_time_s: float, settings: dict,
                time_offset: float, neutral_modes: list, iterates, inverted: int, contact) -> Solution:
    """The Solution of one core solve r (a SolveResult) with its error estimate
    (emu.solve.estimate.Estimate); time_offset: seconds since the whole solve began."""
    h = np.asarray(r.history)
    history = {name: h[:, i] for i, name in enumerate(HISTORY_COLUMNS)}
    history["time_s"] = history["time_s"] + time_offset
    F = None if r.F is None else np.asarray(r.F)   # EMU: per scene tet, identity on fixed bones
    return Solution(method=method, positions=positions, converged=bool(r.converged), status=status,
                    iterations=r.iterations, cg_iterations=r.cg_iterations, time_s=r.time_s + estimate.seconds,
                    solve_time_s=r.time_s, setup_time_s=setup_time_s, energy=r.energy, grad_norm=r.grad_norm,
                    grad_norm0=r.grad_norm0, rel_energy_change=r.rel_energy_change, history=history, F=F,
                    settings=settings, filtered_steps=r.filtered_steps, exact_attempts_failed=r.exact_attempts_failed,
                    factorizations=r.factorizations, negative_curvature_steps=r.negative_curvature_steps,
                    neutral_modes=neutral_modes, iterates=iterates, error_estimate=estimate.value,
                    error_estimate_time_s=estimate.seconds, error_estimate_note=estimate.note,
                    phase_times=phase_times_of(r, estimate.seconds), inverted_tets=inverted,
                    emu_positions=positions if method == "emu" else None, fem_correction=estimate.x1,
                    error_estimate_certified=estimate.certified, fem_steps=estimate.steps, contact=contact)
