"""Solving a scene for its quasi-static equilibrium, by FEM or by EMU."""
from __future__ import annotations

import contextlib
import math
import re
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from . import _core
from .accuracy import (ACCURACY_CG_FORCING, ACCURACY_CG_FORCING_MIN, CERTIFY_CONTRACTION, CERTIFY_STEPS,
                       FEM_ACCURACY_CG_FORCING,
                       DEFAULT_ACCURACY, DEFAULT_ALPHA, STEP_FRACTION, STEP_GRAD, AccuracyMode, AccuracyWarning)
from .checks import inverted_tets
from .contact import ContactTerm
from .geometry import bbox_diagonal, deformation_gradients, tet_vertices, vertex_error
from .options import (CHOICES, METHODS, OPTIONS, POSITION_TOL, OptionGroup, check_options, merge_groups,
                      options_text, solver_signature)
from .lowering import build_model, declared_joint_rows, declared_joint_world
from .poses import parse_pose
from .runtime import adapt_threads, set_threads
from .scene import Scene

__all__ = ["Solver", "Solution", "solve", "METHODS", "STEPS", "NeutralModeWarning", "AccuracyWarning",
           "ActivationWarning"]


class NeutralModeWarning(UserWarning):
    """A movable bone can turn (or slide) with nothing resisting it: its
    equilibrium is not unique (see Solution.neutral_modes)."""


class ActivationWarning(UserWarning):
    """An absolute activation that looks like a fraction of the muscle's
    maximum (normalized=True forgotten)."""


# An absolute activation in (0, 1] at most this fraction of the muscle's
# maximum is almost surely a fraction meant with normalized=True.
NORMALIZED_LOOKALIKE = 1e-3


STEPS = CHOICES["step"]
# EMU's strict solves (no accuracy) also stop when a full step moves no vertex
# by more than POSITION_TOL x the bounding-box diagonal, once |g| <=
# POSITION_TOL_GRAD |g_0|: with bones the gradient's round-off (the fit's
# conditioning) can sit within a few times rtol_grad |g_0|, and the steps that
# chase it change the answer only below POSITION_TOL (docs/DESIGN.md, "The gradient's round-off").
POSITION_TOL_GRAD = 1e-3
# L-BFGS keeps its initial inverse (the Woodbury preconditioner) this many
# steps: its curvature pairs make up for the lag (docs/DESIGN.md, "Newton-Krylov details")
LBFGS_REFRESH = 20
# The error estimate's FEM corrections: PCG on the last factorisation for at
# most this many iterations before factorising (SolverOptions::lagged_cg_iterations)
ESTIMATE_LAGGED_CG = 25
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
                converge (emu.accuracy.AccuracyMode.correct); error_estimate is
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


def _phase_times(r, estimate_s: float) -> dict:
    """Solution.phase_times of one solve from a core SolveResult and its estimate's seconds
    (other: the rest of the solver's time; Solver.solve makes it the rest of the whole)."""
    times = {name: float(getattr(r.phases, name)) for name in PHASES}
    times["other"] = max(0.0, float(r.time_s) - sum(times.values()))
    times["error_estimate"] = float(estimate_s)
    return times


class Solver:
    """A solver bound to one scene: factorisation (FEM: symbolic analysis; EMU:
    the ACAP matrix and its modes) happens once here, every ``solve`` reuses it.

    method        "emu" or "fem"
    options       keyword options, listed below by group (emu.options.OPTIONS,
                  the one table they are written in); an option that does not
                  apply to ``method`` (or to EMU's ``step``) is an error naming it

    fibers        (m, 3) the rest fibre direction per tet of the scene the model
                  was built with (emu.lowering.tet_fibers); the scene is not changed
    """

    def __init__(self, scene: Scene, method: str = "emu", *groups, **options):
        if isinstance(method, OptionGroup):   # Solver(scene, emu.StoppingOptions(...)): the default method
            method, groups = "emu", (method, *groups)
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        options = merge_groups(groups, options)
        check_options(method, options.get("step", OPTIONS["step"].default), options)
        self._setup(scene, method, **{**{n: o.default for n, o in OPTIONS.items()}, **options})

    def _setup(self, scene: Scene, method: str, *, alpha, modes, step, rtol_grad, rtol_energy, noise_factor,
               position_tol, max_iterations, cg_max_iterations, cg_model_decrease, cg_forcing_min, preconditioner,
               preconditioner_refresh, bone_coarse_space, joint_coordinates, exact_when_definite, threads, error_estimate,
               error_estimate_steps, accuracy, recycled_directions, lagged_factor, lagged_cg_iterations,
               lbfgs_memory, eigen_filter, negative_curvature, fem_correction, step_fraction,
               single_precision_preconditioner, single_precision_s0):
        """The Solver's setup, every option given (defaults from emu.options.OPTIONS)."""
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        if method == "emu" and alpha is None and accuracy is None and error_estimate:
            accuracy = DEFAULT_ACCURACY   # the default, every step kind: an answer within 1% of FEM's
        alpha = DEFAULT_ALPHA if alpha is None else alpha
        for name, v in (("alpha", alpha), ("rtol_grad", rtol_grad), ("rtol_energy", rtol_energy)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v!r}")
        if not (isinstance(position_tol, (int, float)) and math.isfinite(position_tol) and 0 <= position_tol < 1):
            raise ValueError(f"position_tol is a vertex motion relative to the bounding-box diagonal in [0, 1) "
                             f"(0: off), got {position_tol!r}")
        if not (isinstance(noise_factor, (int, float)) and math.isfinite(noise_factor) and noise_factor >= 0):
            raise ValueError(f"noise_factor must be a number >= 0 (0: off), got {noise_factor!r}")
        if int(modes) < 0:
            raise ValueError(f"modes must be >= 0, got {modes}")
        if threads is not None:
            set_threads(threads)
        if accuracy is not None and not (isinstance(accuracy, (int, float)) and math.isfinite(accuracy)
                                         and 0 < accuracy < 1):
            raise ValueError(f"accuracy is a vertex error relative to the bounding-box diagonal in (0, 1), "
                             f"e.g. 0.01 for 1%; got {accuracy!r}")
        self.scene, self.method, self.step = scene, method, step
        self.accuracy = None if accuracy is None else float(accuracy)
        self.alpha = float(alpha)
        self.model = build_model(scene)
        self.fibers = np.zeros((len(scene.tets), 3))
        self.fibers[np.asarray(self.model.scene_tet)] = np.asarray(self.model.fiber)  # muscles always carry unknowns
        opts = _core.SolverOptions()
        opts.rtol_grad, opts.rtol_energy = float(rtol_grad), float(rtol_energy)
        opts.noise_factor = float(noise_factor)
        opts.exact_when_definite = bool(exact_when_definite)
        opts.eigen_filter = eigen_filter   # a choice's name, checked by the core (emu.options.CHOICES)
        opts.negative_curvature = bool(negative_curvature)
        if max_iterations is None:
            max_iterations = 200 if method == "fem" else {"newton-krylov": 500, "lbfgs": 5000}.get(step, 20000)
        opts.max_iterations = int(max_iterations)
        if not (isinstance(step_fraction, (int, float)) and 0 < step_fraction <= 1):
            raise ValueError(f"step_fraction must lie in (0, 1], got {step_fraction!r}")
        if self.accuracy is not None:
            opts.step_tol = float(step_fraction) * self.accuracy * bbox_diagonal(scene.points)
            opts.step_tol_grad = STEP_GRAD
            opts.step_tol_cold_scale = True   # warm starts gate on the cold start's |g| too (STEP_GRAD)
            if method == "fem":   # FEM's stop sees its steps contract (EMU's answers are checked by the estimate)
                opts.step_tol_contraction = CERTIFY_CONTRACTION
            position_tol = None   # accuracy mode's own step test applies
        elif method == "emu" and step == "newton-krylov" and position_tol > 0:
            # (Newton-Krylov only: its steps contract by at least half, so a
            # short full step bounds the distance left; the Woodbury and L-BFGS
            # steps converge slowly and linearly)
            opts.step_tol = float(position_tol) * bbox_diagonal(scene.points)
            opts.step_tol_grad = POSITION_TOL_GRAD
        else:
            position_tol = None   # not applied: recorded as such
        self.mu_ref = scene.reference_shear_modulus()
        self.settings = dict(method=method, rtol_grad=rtol_grad, rtol_energy=rtol_energy,
                             noise_factor=float(noise_factor),
                             position_tol=None if position_tol is None else float(position_tol),
                             eigen_filter=eigen_filter,
                             step_fraction=float(step_fraction),
                             max_iterations=int(max_iterations), accuracy=self.accuracy)
        if lagged_factor:
            if method != "fem":
                raise ValueError("lagged_factor is a FEM option (EMU factorises nothing per iteration)")
            if int(lagged_cg_iterations) < 1:
                raise ValueError(f"lagged_cg_iterations must be >= 1, got {lagged_cg_iterations}")
            opts.lagged_cg_iterations = int(lagged_cg_iterations)
            if self.accuracy is not None:
                # PCG's forcing term at most FEM_ACCURACY_CG_FORCING: where the step test
                # applies its steps are then Newton steps (with a looser one a soft mode
                # gives short inexact steps that stop the solve short of the accuracy;
                # docs/DESIGN.md, "Accuracy mode as shipped" and "A short step is evidence
                # only when it is an accurate Newton step")
                opts.lagged_cg_forcing = FEM_ACCURACY_CG_FORCING
            self.settings.update(lagged_factor=True, lagged_cg_iterations=int(lagged_cg_iterations))
        self.contact = None   # the ContactTerm of a scene with contact (scene.enable_contact)
        if scene.contact is not None:
            if lagged_factor:
                raise ValueError("lagged_factor does not handle contact yet (the contact pairs change the "
                                 "Newton matrix's pattern); leave it off for scenes with contact")
            self.contact = ContactTerm(scene, scene.contact)
            self.settings.update(contact_distance=self.contact.distance, contact_stiffness=self.contact.stiffness)
        if cg_forcing_min is not None:
            if method != "emu" or step != "newton-krylov":
                raise ValueError("cg_forcing_min is an option of EMU's Newton-Krylov step (CG's forcing floor); "
                                 f"leave it out for method={method!r}, step={step!r}")
            if isinstance(cg_forcing_min, bool) or not (isinstance(cg_forcing_min, (int, float))
                                                          and 0 <= cg_forcing_min < 1):
                raise ValueError(f"cg_forcing_min must lie in [0, 1) (0: no floor; above 0.5 it acts as 0.5, "
                                 f"the forcing term's cap), got {cg_forcing_min!r}")
        if method == "fem":
            self._core = self._named(_core.FemSolver, self.model, opts, self.contact)
        else:
            eo = _core.EmuOptions()
            eo.alpha = float(alpha) * self.mu_ref
            eo.modes = int(modes)
            eo.step = step
            eo.cg_max_iterations = int(cg_max_iterations)
            if not 0 <= cg_model_decrease <= 1:
                raise ValueError(f"cg_model_decrease must lie in [0, 1] (0: the residual test alone), "
                                 f"got {cg_model_decrease!r}")
            eo.cg_model_decrease = float(cg_model_decrease)
            if cg_forcing_min is None:
                cg_forcing_min = ACCURACY_CG_FORCING_MIN if self.accuracy is not None else 0.0
            eo.cg_forcing_min = float(cg_forcing_min)
            if preconditioner_refresh is None:
                preconditioner_refresh = LBFGS_REFRESH if step == "lbfgs" else 3
            if int(preconditioner_refresh) < 1:
                raise ValueError(f"preconditioner_refresh must be >= 1, got {preconditioner_refresh}")
            eo.preconditioner_refresh = int(preconditioner_refresh)
            eo.preconditioner = preconditioner
            eo.bone_coarse_space = bool(bone_coarse_space)
            eo.joint_coordinates = bool(joint_coordinates)
            if int(recycled_directions) < 0:
                raise ValueError(f"recycled_directions must be >= 0, got {recycled_directions}")
            eo.recycled_directions = int(recycled_directions)
            if int(lbfgs_memory) < 1:
                raise ValueError(f"lbfgs_memory must be >= 1, got {lbfgs_memory}")
            eo.lbfgs_memory = int(lbfgs_memory)
            if single_precision_s0 is not None:
                if single_precision_preconditioner is not None:
                    raise ValueError("single_precision_s0 is the old name of single_precision_preconditioner; "
                                     "give only single_precision_preconditioner")
                warnings.warn("single_precision_s0 is now single_precision_preconditioner (it rounds the "
                              "block inverses too); use that name", DeprecationWarning, stacklevel=2)
                single_precision_preconditioner = single_precision_s0
            eo.single_precision_preconditioner = (True if single_precision_preconditioner is None
                                                  else bool(single_precision_preconditioner))
            self._core = self._named(_core.EmuSolver, self.model, opts, eo, self.contact)
            self.settings.update(alpha=float(alpha), alpha_absolute=eo.alpha, modes=self._core.modes, step=step,
                                 single_precision_preconditioner=eo.single_precision_preconditioner,
                                 preconditioner=preconditioner if step == "newton-krylov" else None,
                                 cg_model_decrease=eo.cg_model_decrease if step == "newton-krylov" else None,
                                 cg_forcing_min=eo.cg_forcing_min if step == "newton-krylov" else None)
        self.setup_time_s = self._core.setup_seconds
        self.error_estimate = (bool(error_estimate) or self.accuracy is not None) and method == "emu"
        if int(error_estimate_steps) < 1:
            raise ValueError(f"error_estimate_steps must be >= 1, got {error_estimate_steps}")
        self.error_estimate_steps = int(error_estimate_steps)
        # by default not with contact: the corrections are full Newton steps that
        # know no collision detection, and they can land farther than the accuracy
        # while the estimate itself is right (docs/DESIGN.md, "Contact")
        if fem_correction is None:
            fem_correction = self.contact is None
        self.fem_correction = bool(fem_correction) and method == "emu"
        self.settings["fem_correction"] = self.fem_correction
        if self.scene.movable_bones:
            self.settings["bone_coordinates"] = self.bone_coordinates
            why = self._bone_names(self._core.bone_forest_error) if method == "emu" else ""
            if self.accuracy is not None and why:
                # FEM, and so the error estimate accuracy mode stands on, takes
                # trees of bones only
                raise ValueError(
                    f"EMU's accuracy mode needs FEM's error estimate, which this scene does not allow: "
                    f"{why}. To solve it as it is, give alpha= without "
                    "accuracy (EMU turns each bone on its own there, with no estimate of its error)")
        # accuracy mode's controller (EMU): alpha per solve, answers accepted or corrected
        self._accuracy = (AccuracyMode(self.accuracy, self.fem_correction, self.alpha)
                          if self.accuracy is not None and method == "emu" else None)
        self._estimator = None       # FEM's Newton system for the error estimate, built at first use
        self._observers = (None, None)   # (on_iteration, iterates) of the solve in progress
        self._estimator_error = ""   # why there is none (a scene FEM does not handle)
        self._warned_activation = set()   # muscles whose normalised-looking activation was warned about

    def _named(self, make, *args):
        """make(*args) with the C++ core's bone numbers in its errors replaced by
        the bones' names (the core knows movable bones by their order)."""
        try:
            return make(*args)
        except ValueError as e:
            raise ValueError(self._bone_names(str(e))) from None

    def _bone_names(self, text: str) -> str:
        """text with the C++ core's movable-bone numbers replaced by the bones' names."""
        names = self.scene.movable_bones
        text = re.sub(r"movable bones (\d+) and (\d+)",
                      lambda m: f"movable bones '{names[int(m[1])]}' and '{names[int(m[2])]}'", text)
        return re.sub(r"movable bone (\d+)", lambda m: f"movable bone '{names[int(m[1])]}'", text)

    def activation_vector(self, activation=None, normalized: bool = False) -> np.ndarray:
        """Per-muscle absolute activations from a {muscle: value} dict (missing: 0)."""
        names = self.scene.muscles
        a = np.zeros(len(names))
        if activation is None:
            return a
        if not isinstance(activation, dict):
            raise TypeError("activation must be a dict {muscle name: value}")
        for name, v in activation.items():
            if name not in names:
                raise ValueError(f"unknown muscle '{name}'; the scene's muscles are {names}")
            v = float(v)
            if not math.isfinite(v) or v < 0:
                raise ValueError(f"activation of '{name}' must be finite and >= 0, got {v}")
            top = self.scene.parts[name].max_activation
            if normalized:
                if v > 1:
                    raise ValueError(f"normalised activation of '{name}' must lie in [0, 1], got {v}")
                v *= top
            elif 0 < v <= 1 and v <= NORMALIZED_LOOKALIKE * top and name not in self._warned_activation:
                self._warned_activation.add(name)
                warnings.warn(ActivationWarning(
                    f"activation {v:g} of '{name}' is absolute (a stress in the mesh's units; the muscle's "
                    f"maximum is {top:g}), so it barely acts: for a fraction of the maximum pass "
                    "normalized=True (scene files and --activation take fractions)"), stacklevel=3)
            a[names.index(name)] = v
        return a

    def _bone_targets(self, bone_poses, ids, targets):
        """Move the vertices of scripted bones: x = R X + t for each {bone: (R, t)}."""
        if not isinstance(bone_poses, dict):
            raise TypeError("bone_poses must be a dict {bone name: (R, t)} or {bone name: 4x4 matrix}")
        bones = {p.name: p for p in self.scene.parts.values() if p.kind == "bone"}
        poses = {}
        for name, pose in bone_poses.items():
            if name not in bones:
                raise ValueError(f"bone_poses: no bone named '{name}' (bones: {', '.join(bones) or 'none'})")
            if not bones[name].fixed:
                raise ValueError(f"bone_poses: bone '{name}' is moved by the muscles (fixed=False); only fixed "
                                 "bones can be scripted")
            poses[name] = parse_pose(name, pose)

        def placed(name, X):  # where bone `name` puts rest points X
            if name not in poses:
                return X
            R, t = poses[name]
            return X @ R.T + t

        targets = targets.copy()
        for name in poses:
            verts = tet_vertices(self.scene.tets[bones[name].tets], len(self.scene.points))
            targets[np.searchsorted(ids, verts)] = placed(name, self.scene.points[verts])
        # a vertex shared by two bones (a joint) must land in the same place under both poses
        diag = bbox_diagonal(self.scene.points)
        for joint in self.scene.joints():
            a, b = joint.bones
            if joint.declared or not (bones[a].fixed and bones[b].fixed):
                continue  # a movable bone follows its joint by itself
            X = self.scene.points[joint.vertices]
            gap = np.linalg.norm(placed(a, X) - placed(b, X), axis=1)
            if gap.max() > 1e-9 * diag:
                v = joint.vertices[int(np.argmax(gap))]
                raise ValueError(f"bones '{a}' and '{b}' share vertex {v}, which their poses put "
                                 f"{gap.max():.3g} apart; a joint must stay together "
                                 "(rotate about the joint: the hinge axis or ball centre)")
        return targets

    def load_case(self, activation=None, normalized=False, gravity=None, pin_positions=None, bone_poses=None):
        load = _core.LoadCase()
        load.activation = self.activation_vector(activation, normalized)
        g = self.scene.gravity if gravity is None else np.asarray(gravity, dtype=np.float64)
        if np.shape(g) != (3,) or not np.all(np.isfinite(g)):
            raise ValueError(f"gravity must be a finite 3-vector, got {g!r}")
        load.gravity = g
        ids, targets = self.scene.model_pins()
        if bone_poses:
            targets = self._bone_targets(bone_poses, ids, targets)
        if pin_positions is not None:
            pins = np.asarray(pin_positions, dtype=np.float64)
            if pins.shape != (len(self.scene.pinned), 3):
                raise ValueError(f"pin_positions must have shape ({len(self.scene.pinned)}, 3) (one row per "
                                 f"scene.pinned vertex), got {pins.shape}")
            if not np.all(np.isfinite(pins)):
                raise ValueError("pin_positions contain NaN or inf")
            targets = targets.copy()
            targets[np.searchsorted(ids, self.scene.pinned)] = pins
        load.pin_positions = targets
        world = declared_joint_world(self.scene)
        if world and bone_poses:
            pts, _ = declared_joint_rows(self.scene)
            jt = pts.copy()
            for row, bone in world:
                if bone in bone_poses:
                    R, t = parse_pose(bone, bone_poses[bone])
                    jt[row] = R @ pts[row] + t
            load.joint_targets = jt
        return load

    def solve(self, activation=None, *, normalized: bool = False, gravity=None, pin_positions=None,
              bone_poses=None, initial=None, on_iteration=None, record_iterates: bool = False) -> Solution:
        """Equilibrium under the given activations.

        activation    {muscle: a} absolute activation (or in [0, 1] with normalized=True)
        bone_poses    {bone: (R, t)} (or a 4x4 rigid transform) placing scripted bones at
                      x = R X + t; bones not listed stay at rest
        initial       warm start: a previous Solution of this solver (or, for FEM,
                      (n, 3) positions; for EMU, (m, 3, 3) deformation gradients)
        on_iteration  on_iteration(record, positions) is called with the start and
                      every accepted iterate: record a dict (iteration, energy,
                      grad_norm, step, time_s, cg_iterations, backtracks), positions
                      (n, 3) (EMU: the fit of the iterate). A true return value stops
                      the solve (status "stopped by on_iteration"); an exception it
                      raises stops it and propagates.
        record_iterates  keep (time_s, positions) of every iterate in Solution.iterates (a
                      FEM-corrected answer last, at the solve's time plus its estimates')
        """
        load = self.load_case(activation, normalized, gravity, pin_positions, bone_poses)
        if on_iteration is not None and not callable(on_iteration):
            raise TypeError(f"on_iteration must be callable, got {type(on_iteration).__name__}")
        iterates = [] if record_iterates else None
        start = None if initial is None else self._initial_array(initial)
        self._observers = (on_iteration, iterates)
        threads = adapt_threads()   # fewer where other processes hold cores (emu.runtime)
        t0 = time.perf_counter()
        sol = self._accuracy.solve(self, load, start, t0) if self._accuracy is not None else self._run(load, start, t0)
        sol.settings = {**sol.settings, "threads": threads}
        sol.time_s = time.perf_counter() - t0   # the whole solve, estimates and corrections included
        sol.phase_times["other"] = max(0.0, sol.time_s - sum(v for k, v in sol.phase_times.items() if k != "other"))
        return sol

    @property
    def bone_coordinates(self) -> str:
        """How this solver turns movable bones: "joint coordinates" (each
        bone's turn the sum of its chain's joint turns; FEM always, EMU where a
        hinge joins two movable bones) or, for EMU, "per bone: <why>" (no such
        hinge, joints that close a loop or weld two bones, or
        ``joint_coordinates=False``); "" without movable bones."""
        if not self.scene.movable_bones:
            return ""
        return self._bone_names(self._core.bone_coordinates) if self.method == "emu" else "joint coordinates"

    def structures(self) -> dict:
        """{name: bytes} of what this solver built for its scene (per-solve work
        arrays aside), the error estimate's FEM system once built: a scene
        without bones, joints, gravity or a Schur preconditioner lists none of
        their structures (docs/DESIGN.md, "A scene pays for what it uses")."""
        out = {name: int(b) for name, b in self._core.structures()}
        if self._estimator is not None:
            out.update({f"error estimate: {name}": int(b) for name, b in self._estimator.structures()})
        return out

    def set_alpha(self, alpha: float) -> None:
        """EMU: a new alpha (relative to the reference shear modulus) for the
        following solves; nothing is refactorised. With ``accuracy`` the alpha
        carried from solve to solve stays within 1e4 x max(alpha, 100)."""
        self._set_alpha(alpha)
        if self._accuracy is not None:
            self._accuracy.bound_from(self.alpha)

    def _set_alpha(self, alpha: float) -> None:
        """set_alpha for accuracy mode's own changes (the bound stays)."""
        if self.method != "emu":
            raise ValueError("alpha is an EMU setting; this solver is FEM")
        if not (math.isfinite(alpha) and alpha > 0):
            raise ValueError(f"alpha must be a positive number, got {alpha!r}")
        self._core.alpha = float(alpha) * self.mu_ref
        self.alpha = float(alpha)
        self.settings.update(alpha=self.alpha, alpha_absolute=self._core.alpha)

    # The port accuracy mode drives (emu.accuracy): one solve, one FEM correction,
    # tight CG, inverted tets.
    def _run(self, load, start, t0: float) -> Solution:
        """One solve from start (None: rest; a Solution or a start array as
        _initial_array makes; (n, 3) positions: EMU from the deformation
        gradients of those positions), with its error estimate (EMU); t0 the
        perf_counter of the whole solve's start."""
        if isinstance(start, Solution):
            start = self._initial_array(start)
        elif start is not None and np.shape(start) == self.scene.points.shape and self.method == "emu":
            start = self._initial_array(deformation_gradients(self.scene.points, self.scene.tets, start))
        on_iteration, iterates = self._observers
        return self._solve_once(load, start, on_iteration, iterates, time.perf_counter() - t0)

    def _correction(self, load, x):
        """One FEM Newton correction of positions x by PCG on the estimator's
        last factor (nothing factorised, no filtered fallback), None where that
        fails: accuracy mode's corrections, certified only in Newton's regime."""
        try:
            y = self._estimator.newton_correction(load, x, hessian="lagged-newton", max_steps=1)
        except (RuntimeError, ValueError):   # ValueError: with contact, x has surfaces through each other
            return None
        y = np.asarray(y)
        return y if np.all(np.isfinite(y)) else None

    @contextlib.contextmanager
    def _tight_cg(self):
        """CG to the forcing term ACCURACY_CG_FORCING inside the context."""
        eta_max = self._core.cg_forcing_max
        self._core.cg_forcing_max = min(eta_max, ACCURACY_CG_FORCING)
        try:
            yield
        finally:
            self._core.cg_forcing_max = eta_max

    def _inverted(self, x) -> int:
        return len(inverted_tets(self.scene.tets, x))

    def _solve_once(self, load, start, on_iteration, iterates, time_offset) -> Solution:
        settings = dict(self.settings)
        settings["activation"] = dict(zip(self.scene.muscles, np.asarray(load.activation).tolist()))
        callback = None
        if on_iteration is not None or iterates is not None:
            def callback(record, positions):
                record["time_s"] += time_offset
                if iterates is not None:
                    iterates.append((record["time_s"], positions))
                return bool(on_iteration(record, positions)) if on_iteration is not None else False
        if start is None:
            r = self._core.solve(load, on_iteration=callback)
        else:
            r = self._core.solve_from(load, start, on_iteration=callback)
        if not np.all(np.isfinite(r.positions)):
            raise FloatingPointError("the solver produced non-finite positions; this is a bug, please report it")
        h = np.asarray(r.history)
        history = {name: h[:, i] for i, name in enumerate(HISTORY_COLUMNS)}
        F = None if r.F is None else np.asarray(r.F)   # EMU: per scene tet, identity on fixed bones
        positions = np.asarray(r.positions)
        x1, estimate_s, note = (self._fem_correction_of(load, positions) if self.error_estimate
                                else (None, 0.0, ""))
        estimate, certified, chain = None, None, None
        if x1 is not None:
            t1 = time.perf_counter()
            certified, chain, why = self._certify(load, positions, x1)
            estimate = vertex_error(positions, chain[-1])   # the FEM point nearest FEM's answer
            estimate_s += time.perf_counter() - t1
            note = note or why
        history["time_s"] = history["time_s"] + time_offset
        return Solution(method=self.method, positions=positions, converged=bool(r.converged),
                        status=self._bone_names(r.status), iterations=r.iterations, cg_iterations=r.cg_iterations,
                        time_s=r.time_s + estimate_s, solve_time_s=r.time_s, setup_time_s=self.setup_time_s,
                        energy=r.energy,
                        grad_norm=r.grad_norm, grad_norm0=r.grad_norm0, rel_energy_change=r.rel_energy_change,
                        history=history, F=F, settings=settings, filtered_steps=r.filtered_steps,
                        exact_attempts_failed=r.exact_attempts_failed, factorizations=r.factorizations,
                        negative_curvature_steps=r.negative_curvature_steps,
                        neutral_modes=self._neutral_modes(r), iterates=iterates, error_estimate=estimate,
                        error_estimate_time_s=estimate_s, error_estimate_note=note,
                        phase_times=_phase_times(r, estimate_s),
                        inverted_tets=len(inverted_tets(self.scene.tets, positions)),
                        emu_positions=positions if self.method == "emu" else None, fem_correction=x1,
                        error_estimate_certified=certified, fem_steps=chain,
                        contact=self._contact_report(positions))

    def _contact_report(self, positions):
        if self.contact is None:
            return None
        return {"pairs": self.contact.active_pairs(positions),
                "min_distance": self.contact.minimum_distance(positions),
                "intersecting": self.contact.intersecting(positions)}

    def _fem_correction_of(self, load, positions) -> tuple:
        """(x1 or None, seconds, note): the linearised correction x1 of FEM's
        Newton steps at EMU's positions x (FemSolver::newton_correction: the
        exact step in Newton's regime, else the lower-energy one of the exact
        and PSD-filtered steps, another step after a filtered one), by which
        EMU's vertex error to FEM is estimated: vertex_error(x, x1)."""
        t0 = time.perf_counter()
        if self._estimator is None and not self._estimator_error:
            opts = _core.SolverOptions()
            # the corrections of a sequence's frames (and of accuracy mode's
            # re-solves) by PCG on the last factorisation (docs/DESIGN.md, "The FEM
            # baselines: a factorisation per step, or a lagged factor")
            opts.lagged_cg_iterations = ESTIMATE_LAGGED_CG   # (without contact: its pattern changes)
            if self.accuracy is not None:   # _fem_settle: FEM's accuracy-mode stop, as Solver(method="fem") sets it
                opts.step_tol = self.settings["step_fraction"] * self.accuracy * bbox_diagonal(self.scene.points)
                opts.step_tol_grad = STEP_GRAD
                opts.step_tol_cold_scale = True
                opts.step_tol_contraction = CERTIFY_CONTRACTION
                opts.lagged_cg_forcing = FEM_ACCURACY_CG_FORCING
                opts.max_iterations = 200
            try:   # the same energy as EMU's, contact included
                self._estimator = self._named(_core.FemSolver, self.model, opts, self.contact)
            except ValueError as e:   # e.g. a closed loop of joints (FEM takes trees of bones)
                self._estimator_error = f"no error estimate: {e}"
        if self._estimator is None:
            return None, 0.0, self._estimator_error
        try:
            x1 = np.asarray(self._estimator.newton_correction(load, positions, max_steps=self.error_estimate_steps))
        except RuntimeError as e:
            return None, time.perf_counter() - t0, f"no error estimate: {e}"
        return x1, time.perf_counter() - t0, ""

    def _certify(self, load, x, x1) -> tuple:
        """(certified, [x1, x2, ...], note): up to CERTIFY_STEPS more FEM Newton
        corrections of x1 (PCG on the estimator's factor: nothing factorised),
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
        if self._estimator is None:   # an estimate from elsewhere (tests' stand-ins): no certificate
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
            return self._correction(load, y)
        try:   # no lagged factor with contact (its pattern changes): a step of its own
            return np.asarray(self._estimator.newton_correction(load, y, max_steps=1))
        except (RuntimeError, ValueError):
            return None

    def _fem_settle(self, load, x):
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
            r = self._estimator.solve_from(load, x, on_iteration=record)
        except (RuntimeError, ValueError):
            return None
        if not r.converged or not np.all(np.isfinite(r.positions)):
            return None
        return r, steps[-2:]

    def _neutral_modes(self, r) -> list:
        bones = self.scene.movable_bones
        modes = [(bones[b], np.asarray(a, float)) for b, a in zip(r.neutral_bones, np.asarray(r.neutral_axes))]
        for bone, axis in modes:
            warnings.warn(NeutralModeWarning(
                f"bone '{bone}' can turn about axis {np.round(axis, 3).tolist()} with nothing resisting it (a "
                "neutral mode): its equilibrium is not unique and that turn was left alone. Fix the bone, add an "
                "antagonist muscle, gravity, or a joint_stiffness"), stacklevel=3)
        return modes

    def _initial_array(self, initial):
        if isinstance(initial, Solution):
            if initial.method != self.method:
                raise ValueError(f"cannot warm-start a {self.method} solve from a {initial.method} solution")
            initial = initial.F if self.method == "emu" else initial.positions
        a = np.asarray(initial, dtype=np.float64)
        if self.method == "fem":
            if a.shape != self.scene.points.shape:
                raise ValueError(f"initial positions must have shape {self.scene.points.shape}, got {a.shape}")
            return a
        m = len(self.scene.tets)
        if a.shape != (m, 3, 3):
            raise ValueError(f"initial deformation gradients must have shape ({m}, 3, 3), got {a.shape}")
        return a


# help(emu.Solver) and IDEs show every option with its default, from the one table
Solver.__init__.__signature__ = solver_signature(Solver.__init__)
Solver.__doc__ += options_text()


def solve(scene: Scene, activation=None, method: str = "emu", *groups, normalized: bool = False, gravity=None,
          pin_positions=None, bone_poses=None, initial=None, on_iteration=None, record_iterates: bool = False,
          **options) -> Solution:
    """Build a Solver for ``scene`` and solve once: Solver(scene, method,
    *groups, **options).solve(...) with the same arguments as Solver.solve
    (activation absolute, or fractions of each muscle's maximum with
    normalized=True)."""
    return Solver(scene, method, *groups, **options).solve(activation, normalized=normalized, gravity=gravity,
                                                  pin_positions=pin_positions, bone_poses=bone_poses,
                                                  initial=initial, on_iteration=on_iteration,
                                                  record_iterates=record_iterates)
