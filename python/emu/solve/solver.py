"""Solving a scene for its quasi-static equilibrium, by FEM or by EMU.

The Solver wires the pieces of this package to the C++ core: the options
lowered to the core's (options.lower), the load (load), the error estimate
(estimate) and accuracy mode's controller (accuracy), the result (solution)."""
from __future__ import annotations

import contextlib
import math
import re
import time
import warnings

import numpy as np

from .. import _core
from ..core.checks import inverted_tets
from ..model.contact import ContactTerm
from ..core.geometry import deformation_gradients
from ..model.lowering import build_model
from ..core.runtime import adapt_threads, set_threads
from ..model.scene import Scene
from .accuracy import ACCURACY_CG_FORCING, AccuracyMode, AccuracyWarning
from .estimate import Estimate, ErrorEstimator
from .load import ActivationWarning, activation_vector, load_case, set_inertia, start_array
from .options import (CHOICES, METHODS, OPTIONS, OptionGroup, check_options, lower, merge_groups, options_text,
                      solver_signature)
from .solution import Solution, solution_of

__all__ = ["Solver", "Solution", "solve", "METHODS", "STEPS", "NeutralModeWarning", "AccuracyWarning",
           "ActivationWarning"]


class NeutralModeWarning(UserWarning):
    """A movable bone can turn (or slide) with nothing resisting it: its
    equilibrium is not unique (see Solution.neutral_modes)."""


STEPS = CHOICES["step"]


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
        values = {**{n: o.default for n, o in OPTIONS.items()}, **options}
        low = lower(method, values, scene)   # every value checked before anything changes
        if values["threads"] is not None:
            set_threads(values["threads"])
        self.scene, self.method, self.step = scene, method, values["step"]
        self.accuracy, self.alpha, self.settings = low.accuracy, low.alpha, low.settings
        self.model = build_model(scene)
        self.fibers = np.zeros((len(scene.tets), 3))
        self.fibers[np.asarray(self.model.scene_tet)] = np.asarray(self.model.fiber)  # muscles always carry unknowns
        self.mu_ref = scene.reference_shear_modulus()
        self.contact = None   # the ContactTerm of a scene with contact (scene.enable_contact)
        if scene.contact is not None:
            self.contact = ContactTerm(scene, scene.contact)
            self.settings.update(contact_distance=self.contact.distance, contact_stiffness=self.contact.stiffness)
        self._core = self._build_core(low)
        self.setup_time_s = self._core.setup_seconds
        self.error_estimate = low.error_estimate
        self.error_estimate_steps = int(values["error_estimate_steps"])
        self.fem_correction = low.fem_correction
        self.settings["fem_correction"] = self.fem_correction
        if self.scene.movable_bones:
            self._check_bone_coordinates()
        # accuracy mode's controller (EMU): alpha per solve, answers accepted or corrected
        self._accuracy = (AccuracyMode(self.accuracy, self.fem_correction, self.alpha)
                          if self.accuracy is not None and method == "emu" else None)
        self._estimator = ErrorEstimator(self.model, scene.points, self.contact, self.accuracy,
                                        self.settings["step_fraction"], self.error_estimate_steps, self._named)
        self._warned_activation = set()   # muscles whose normalised-looking activation was warned about

    def _build_core(self, low):
        """The C++ solver of the method, from the lowered options."""
        if self.method == "fem":
            return self._named(_core.FemSolver, self.model, low.solver, self.contact)
        core = self._named(_core.EmuSolver, self.model, low.solver, low.emu, self.contact)
        eo, nk = low.emu, self.step == "newton-krylov"
        self.settings.update(alpha=self.alpha, alpha_absolute=eo.alpha, modes=core.modes, step=self.step,
                             single_precision_preconditioner=eo.single_precision_preconditioner,
                             preconditioner=eo.preconditioner if nk else None,
                             cg_model_decrease=eo.cg_model_decrease if nk else None,
                             cg_forcing_min=eo.cg_forcing_min if nk else None)
        return core

    def _check_bone_coordinates(self) -> None:
        """Solution.settings says how movable bones turn; EMU's accuracy mode
        refuses bones FEM (and so the error estimate) cannot take."""
        self.settings["bone_coordinates"] = self.bone_coordinates
        why = self._bone_names(self._core.bone_forest_error) if self.method == "emu" else ""
        if self.accuracy is not None and why:
            # FEM, and so the error estimate accuracy mode stands on, takes
            # trees of bones only
            raise ValueError(
                f"EMU's accuracy mode needs FEM's error estimate, which this scene does not allow: "
                f"{why}. To solve it as it is, give alpha= without "
                "accuracy (EMU turns each bone on its own there, with no estimate of its error)")

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
        return activation_vector(self.scene, activation, normalized, self._warned_activation)

    def load_case(self, activation=None, normalized=False, gravity=None, pin_positions=None, bone_poses=None):
        """The core's load of a solve (emu.solve.load.load_case)."""
        return load_case(self.scene, activation, normalized, gravity, pin_positions, bone_poses,
                         self._warned_activation)

    def solve(self, activation=None, *, normalized: bool = False, gravity=None, pin_positions=None,
              bone_poses=None, initial=None, on_iteration=None, record_iterates: bool = False,
              inertia=None) -> Solution:
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
        inertia       a time step's inertia (w, y): the weight 1 / h_eff^2 and the (n, 3)
                      predicted positions of an implicit integrator (emu.solve.dynamics;
                      solve_frames(..., dynamics=emu.Dynamics(dt)) sets them)
        """
        load = self.load_case(activation, normalized, gravity, pin_positions, bone_poses)
        if inertia is not None:
            set_inertia(load, self.scene, inertia)
        if on_iteration is not None and not callable(on_iteration):
            raise TypeError(f"on_iteration must be callable, got {type(on_iteration).__name__}")
        iterates = [] if record_iterates else None
        start = None if initial is None else start_array(self.scene, self.method, initial)
        threads = adapt_threads()   # fewer where other processes hold cores (emu.runtime)
        t0 = time.perf_counter()
        port = SolvePort(self, load, t0, on_iteration, iterates)
        sol = self._accuracy.solve(port, start) if self._accuracy is not None else port.run(start)
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
        return {**{name: int(b) for name, b in self._core.structures()}, **self._estimator.structures()}

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

    def _run(self, load, start, t0: float, on_iteration=None, iterates=None) -> Solution:
        """One solve from start (None: rest; a Solution or a start array as
        start_array makes; (n, 3) positions: EMU from the deformation
        gradients of those positions), with its error estimate (EMU); t0 the
        perf_counter of the whole solve's start; on_iteration and iterates as
        Solver.solve takes and records them."""
        if isinstance(start, Solution):
            start = start_array(self.scene, self.method, start)
        elif start is not None and np.shape(start) == self.scene.points.shape and self.method == "emu":
            start = start_array(self.scene, self.method, deformation_gradients(self.scene.points, self.scene.tets, start))
        return self._solve_once(load, start, on_iteration, iterates, time.perf_counter() - t0)

    @contextlib.contextmanager
    def _tight_cg(self):
        """CG to the forcing term ACCURACY_CG_FORCING inside the context."""
        eta_max = self._core.cg_forcing_max
        self._core.cg_forcing_max = min(eta_max, ACCURACY_CG_FORCING)
        try:
            yield
        finally:
            self._core.cg_forcing_max = eta_max

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
        positions = np.asarray(r.positions)
        estimate = self._estimator.estimate(load, positions) if self.error_estimate else Estimate()
        return solution_of(r, self.method, positions, estimate, status=self._bone_names(r.status),
                           setup_time_s=self.setup_time_s, settings=settings, time_offset=time_offset,
                           neutral_modes=_neutral_modes(self.scene, r), iterates=iterates,
                           inverted=len(inverted_tets(self.scene.tets, positions)),
                           contact=None if self.contact is None else self.contact.report(positions))


def _neutral_modes(scene, r) -> list:
    """[(bone, unit axis)] of the turns nothing resists in a core result, each warned about."""
    bones = scene.movable_bones
    modes = [(bones[b], np.asarray(a, float)) for b, a in zip(r.neutral_bones, np.asarray(r.neutral_axes))]
    for bone, axis in modes:
        warnings.warn(NeutralModeWarning(
            f"bone '{bone}' can turn about axis {np.round(axis, 3).tolist()} with nothing resisting it (a "
            "neutral mode): its equilibrium is not unique and that turn was left alone. Fix the bone, add an "
            "antagonist muscle, gravity, or a joint_stiffness"), stacklevel=3)
    return modes


class SolvePort:
    """The AccuracyPort of one solve (emu.solve.accuracy): the Solver's EMU runs
    and its estimator's FEM steps under the solve's load, timed from its start."""

    def __init__(self, solver: Solver, load, t0: float, on_iteration=None, iterates=None):
        self._solver, self._load, self._t0 = solver, load, t0
        self._observers = (on_iteration, iterates)   # Solver.solve's, for every run of this solve

    @property
    def alpha(self) -> float:
        return self._solver.alpha

    @property
    def has_contact(self) -> bool:
        return self._solver.contact is not None

    def run(self, start) -> Solution:
        return self._solver._run(self._load, start, self._t0, *self._observers)

    def set_alpha(self, alpha: float) -> None:
        self._solver._set_alpha(alpha)

    def tight_cg(self):
        return self._solver._tight_cg()

    def correction(self, x):
        return self._solver._estimator.correction(self._load, x)

    def settle(self, x):
        return self._solver._estimator.settle(self._load, x)

    def inverted(self, x) -> int:
        return len(inverted_tets(self._solver.scene.tets, x))

    def elapsed(self) -> float:
        return time.perf_counter() - self._t0


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
