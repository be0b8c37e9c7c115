"""The solver's options, written once: name, type, default, group, the
methods it applies to, and what it does. emu.Solver's signature and the
check of what a user passes, the scene-file schema's [solver] table and the
options page of the docs (docs/guide/options.md) all come from ``OPTIONS``.

Groups: ``stopping`` (when a solve ends), ``accuracy`` (the error to FEM
wanted and EMU's estimate of it), ``newton`` (both methods' Newton matrix),
``emu`` (EMU's step, preconditioner and alpha), ``fem`` (FEM's Newton
variants), ``machine`` (threads). Each group but the machine's is also a
class (StoppingOptions, ...) a user may build once and pass to several
solvers: ``emu.Solver(scene, "emu", emu.StoppingOptions(rtol_grad=1e-8))``.
"""
from __future__ import annotations

import dataclasses
import difflib
import inspect
import math
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .. import _core
from ..core.geometry import bbox_diagonal
from .accuracy import (ACCURACY_CG_FORCING_MIN, CERTIFY_CONTRACTION, DEFAULT_ACCURACY, DEFAULT_ALPHA,
                       FEM_ACCURACY_CG_FORCING, STEP_FRACTION, STEP_GRAD)

__all__ = ["Option", "OPTIONS", "Lowered", "lower", "GROUPS", "CHOICES", "OptionGroup", "StoppingOptions", "AccuracyOptions",
           "NewtonOptions", "EmuOptions", "FemOptions", "GROUP_CLASSES", "merge_groups", "parse_option", "check_options", "options_markdown",
           "options_text", "scene_file_types", "solver_signature"]

METHODS = BOTH = ("emu", "fem")
# EMU's Newton-Krylov step without ``accuracy``: converged when a full step
# moves no vertex by more than this x the bounding-box diagonal ...
POSITION_TOL = 1e-7
# ... once |g| <= POSITION_TOL_GRAD |g_0|: with bones the gradient's round-off (the fit's
# conditioning) can sit within a few times rtol_grad |g_0|, and the steps that chase it
# change the answer only below POSITION_TOL (docs/DESIGN.md, "The gradient's round-off").
POSITION_TOL_GRAD = 1e-3
# L-BFGS keeps its initial inverse (the Woodbury preconditioner) this many
# steps: its curvature pairs make up for the lag (docs/DESIGN.md, "Newton-Krylov details")
LBFGS_REFRESH = 20


@dataclass(frozen=True)
class Option:
    name: str
    type: type | tuple           # what a scene file may give (int where a float is asked is accepted)
    default: object
    group: str
    methods: tuple               # the methods it applies to
    doc: str
    steps: tuple | None = None   # EMU: the steps it applies to (None: all)
    check: Callable | None = None   # check(value) -> whether the value is valid ...
    must: str = ""               # ... and what the error says otherwise: "<name> <must>, got <value>"
    core: str = ""               # "solver" / "emu": copied as it is to that _core options field of its name
                                 # ("": lowered by lower(), or not the core's)

    @property
    def choices(self) -> tuple | None:
        """The names it takes, for an option that is one of a few (spelled as in C++)."""
        return CHOICES.get(self.name)


# {option: its choices, the default first}: spelled once, in the C++ core
# (emu/solvers/option_choices.h), which takes and gives the same strings
CHOICES = dict(_core.option_choices())


GROUPS = {
    "stopping": "When a solve ends",
    "accuracy": "The error to FEM wanted, and EMU's estimate of it",
    "newton": "Both methods: the Newton matrix",
    "emu": "EMU: alpha, the step and its preconditioner",
    "fem": "FEM: Newton's variants",
    "machine": "The machine",
}

NK = ("newton-krylov",)


def _finite(v) -> bool:
    """A real number (not a bool), finite."""
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_)) \
        and math.isfinite(v)


def _integer(v) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


def _positive(v) -> bool:
    return _finite(v) and v > 0


def _at_least(low):
    return lambda v: _finite(v) and v >= low

_TABLE = [
    # stopping
    Option("rtol_grad", float, 1e-6, "stopping", BOTH,
           "converged when |g| <= rtol_grad |g_0| (the strict test; with ``accuracy`` the step test usually ends first)",
           check=_positive, must="must be a positive number", core="solver"),
    Option("rtol_energy", float, 1e-10, "stopping", BOTH,
           "... and the last energy decrease is at most rtol_energy x the total decrease",
           check=_positive, must="must be a positive number", core="solver"),
    Option("noise_factor", float, 2.0, "stopping", BOTH,
           "... or when |g| <= noise_factor x the gradient's round-off, measured in the endgame from the "
           "gradient at the iterate moved by one rounding (EMU with bones needs it: its fit's conditioning can "
           "bring the round-off near rtol_grad |g_0|; 0: off)",
           check=_at_least(0.0), must="must be a number >= 0 (0: off)", core="solver"),
    Option("position_tol", float, POSITION_TOL, "stopping", ("emu",),
           "EMU's Newton-Krylov step without ``accuracy``: ... or when a full step moves no vertex by more than "
           "this x the bounding-box diagonal, once |g| <= 1e-3 |g_0| (0: off)", NK,
           check=lambda v: _finite(v) and 0 <= v < 1,
           must="is a vertex motion relative to the bounding-box diagonal in [0, 1) (0: off)"),
    Option("max_iterations", (int, type(None)), None, "stopping", BOTH,
           "per solve (None: 200 for FEM, 500 for EMU's Newton-Krylov, 5000 for L-BFGS, 20000 for Woodbury)",
           check=lambda v: v is None or (_finite(v) and v >= 0 and float(v).is_integer()),
           must="must be a whole number >= 0 or None"),
    Option("step_fraction", float, STEP_FRACTION, "stopping", BOTH,
           "with ``accuracy``: stop when a full step moves no vertex by more than this fraction of it",
           check=lambda v: _finite(v) and 0 < v <= 1, must="must lie in (0, 1]"),
    # accuracy
    Option("accuracy", (float, type(None)), None, "accuracy", BOTH,
           "the vertex error to FEM wanted, relative to the bounding-box diagonal (0.01: 1%; EMU's default, "
           "every ``step``, unless ``alpha`` is given or ``error_estimate`` is off), instead of a tolerance: both methods stop when a full Newton step moves "
           "no vertex by more than ``step_fraction`` of it; EMU also picks alpha so that its error estimate is "
           "within 0.6 x accuracy, raising it (or correcting its answer, ``fem_correction``) where not, and "
           "carries the alpha over to the next solve",
           check=lambda v: v is None or (_finite(v) and 0 < v < 1),
           must="is a vertex error relative to the bounding-box diagonal in (0, 1), e.g. 0.01 for 1%"),
    Option("error_estimate", bool, True, "accuracy", ("emu",),
           "estimate every solve's error to FEM (Solution.error_estimate) from FEM Newton steps at EMU's "
           "answer: one or two sparse factorisations per step, no FEM solve"),
    Option("error_estimate_steps", int, 2, "accuracy", ("emu",),
           "at most this many FEM Newton correction steps in the estimate",
           check=_at_least(1), must="must be >= 1"),
    Option("fem_correction", (bool, type(None)), None, "accuracy", ("emu",),
           "with ``accuracy``: where the estimate misses it, return EMU's answer corrected by FEM Newton steps "
           "instead of re-solving at a larger alpha (None: on, except with contact)"),
    # emu
    Option("alpha", (float, type(None)), None, "emu", ("emu",),
           "the ACAP coupling's weight relative to the softest muscle's shear modulus; given (without "
           "``accuracy``) it is kept fixed and iterated to the strict tolerance (None: 100, or chosen for "
           "``accuracy``)",
           check=lambda v: v is None or _positive(v), must="must be a positive number"),
    Option("step", str, CHOICES["step"][0], "emu", ("emu",),
           "EMU's step: \"newton-krylov\" (default), \"woodbury\" (the paper's quasi-Newton step) or \"lbfgs\"",
           core="emu"),
    Option("preconditioner", str, CHOICES["preconditioner"][0], "emu", ("emu",),
           "Newton-Krylov's preconditioner: \"constant-schur\" (the filtered Hessian's inverse through a "
           "constant Schur complement: one factorisation per alpha; default), \"schur\" (the exact Schur "
           "complement: a factorisation per rebuild) or \"woodbury\" (the paper's approximation through "
           "``modes``)", NK,
           core="emu"),
    Option("modes", int, 24, "emu", ("emu",),
           "the ACAP modes the Woodbury step and preconditioner use",
           check=_at_least(0), must="must be >= 0", core="emu"),
    Option("preconditioner_refresh", (int, type(None)), None, "emu", ("emu",),
           "rebuild the preconditioner every n steps (None: 3 for Newton-Krylov, 20 for L-BFGS)",
           check=lambda v: v is None or _at_least(1)(v), must="must be >= 1"),
    Option("cg_max_iterations", int, 500, "emu", ("emu",), "CG iterations per Newton step at most", NK,
           core="emu"),
    Option("cg_model_decrease", float, 0.5, "emu", ("emu",),
           "CG's truncation test (Nash-Sofer): stop when an iteration lowers the quadratic model by at most "
           "this fraction of its decrease so far over the iteration count (0: the residual test alone)", NK,
           check=lambda v: _finite(v) and 0 <= v <= 1, must="must lie in [0, 1] (0: the residual test alone)",
           core="emu"),
    Option("cg_forcing_min", (float, type(None)), None, "emu", ("emu",),
           "a floor on CG's forcing term eta (CG stops at |r| <= eta |g|, eta = min(0.5, max(floor, "
           "sqrt(|g| / |g_0|))), Eisenstat-Walker; None: 0.1 with ``accuracy``, else 0)", NK,
           check=lambda v: v is None or (_finite(v) and 0 <= v < 1),
           must="must lie in [0, 1) (0: no floor; above 0.5 it acts as 0.5, the forcing term's cap)"),
    Option("exact_when_definite", bool, True, "newton", BOTH,
           "use the unfiltered Hessian while it is definite, the PSD-filtered one after it fails",
           core="solver"),
    Option("eigen_filter", str, CHOICES["eigen_filter"][0], "newton", BOTH,
           "where an element Hessian is not PSD: \"clamp\" its negative eigenvalues to 0 or reflect them "
           "(\"abs\")",
           core="solver"),
    Option("bone_coarse_space", bool, True, "emu", ("emu",),
           "with movable bones: a coarse correction for the bones' turns in the preconditioner",
           core="emu"),
    Option("joint_coordinates", bool, True, "emu", ("emu",),
           "where a hinge joins two movable bones (a chain): turn the bones in joint coordinates (a bone's "
           "turn the sum of its chain's joint turns), so steps keep that hinge exactly; other scenes, and "
           "joints that close a loop or weld two bones, turn each bone on its own (``Solver.bone_coordinates`` "
           "says which)",
           core="emu"),
    Option("recycled_directions", int, 4, "emu", ("emu",),
           "with movable bones: keep the directions of up to this many long CG solves in that correction, "
           "and cut a CG solve that stalls (at twice the last step's iterations, at least 30) to keep its "
           "direction (0: off)",
           check=_at_least(0), must="must be >= 0", core="emu"),
    Option("lbfgs_memory", int, 8, "emu", ("emu",), "the L-BFGS step's curvature pairs", ("lbfgs",),
           check=_at_least(1), must="must be >= 1", core="emu"),
    Option("single_precision_preconditioner", (bool, type(None)), None, "emu", ("emu",),
           "the constant-Schur preconditioner's solves in single precision (None: on)"),
    Option("single_precision_s0", (bool, type(None)), None, "emu", ("emu",),
           "the old name of ``single_precision_preconditioner`` (deprecated)"),
    # fem
    Option("lagged_factor", bool, False, "fem", ("fem",),
           "Newton-CG preconditioned by the last Cholesky factor, kept across iterations and solves; a new "
           "factorisation only when PCG misses its tolerance"),
    Option("lagged_cg_iterations", int, 25, "fem", ("fem",),
           "with ``lagged_factor``: PCG iterations before a new factorisation",
           check=_at_least(1), must="must be >= 1"),
    Option("lagged_refresh", bool, True, "fem", ("fem",),
           "with ``lagged_factor``: a PCG solve longer than about half a factorisation's cost (in iterations, "
           "from the factor's size) makes the next step factorise afresh (an aged factor's PCG grows frame by frame)"),
    Option("negative_curvature", bool, True, "fem", ("fem",),
           "near a saddle (a shape about to buckle) add the most negative curvature direction to the step",
           core="solver"),
    # machine
    Option("threads", (int, type(None)), None, "machine", BOTH, "OpenMP and OpenBLAS threads, for every solver from then on (None: leave as is; "
           "the default is automatic: every core, fewer where other processes keep cores busy; "
           "emu.runtime)"),
]
OPTIONS = {o.name: o for o in _TABLE}
DEPRECATED = {"single_precision_s0"}


class OptionGroup:
    """Base of the option group classes: frozen dataclasses whose fields are
    one group's options with the table's defaults."""

    group: str = ""

    def given(self) -> dict:
        """{option: value} of the fields not at their default."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if getattr(self, f.name) != OPTIONS[f.name].default}


def _value_fits(v, types: tuple) -> bool:
    """Whether v is of one of the table's types (an int serves a float; a bool
    serves neither)."""
    for t in types:
        if t is type(None) and v is None:
            return True
        if t is bool and isinstance(v, (bool, np.bool_)):
            return True
        if t in (int, float) and isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_)):
            return True
        if t is float and isinstance(v, (float, np.floating)):
            return True
        if t is str and isinstance(v, str):
            return True
    return False


def _check_group_values(self) -> None:
    """An option group's values checked when it is built (the type the table
    gives, a choice among its choices), not first when a Solver sees them."""
    for f in dataclasses.fields(self):
        o, v = OPTIONS[f.name], getattr(self, f.name)
        types = o.type if isinstance(o.type, tuple) else (o.type,)
        if v is not o.default and not _value_fits(v, types):
            want = " or ".join("None" if t is type(None) else t.__name__ for t in types)
            raise TypeError(f"{type(self).__name__}: {f.name} takes {want}, got {v!r}")
        if o.choices and v not in o.choices:
            raise ValueError(f"{f.name} must be one of {', '.join(map(repr, o.choices))}, got {v!r}")


def _group_class(name: str, group: str) -> type:
    """A frozen dataclass of ``group``'s options (keyword-only, the table's
    defaults), its docstring the group's part of options_text()."""
    fields = [(o.name, object, dataclasses.field(default=o.default)) for o in _TABLE
              if o.group == group and o.name not in DEPRECATED]
    cls = dataclasses.make_dataclass(name, fields, bases=(OptionGroup,), frozen=True, kw_only=True,
                                     namespace={"group": group, "__post_init__": _check_group_values})
    cls.__module__ = __name__
    cls.__doc__ = f"{GROUPS[group]}: emu.Solver's options of the {group!r} group.\n" + _group_text(group)
    return cls


def _group_text(group: str) -> str:
    import textwrap

    out = []
    for o in _TABLE:
        if o.group == group:
            out.append(f"    {o.name} = {o.default!r}")
            out += textwrap.wrap(o.doc, 92, initial_indent=" " * 8, subsequent_indent=" " * 8)
    return "\n".join(out)


StoppingOptions = _group_class("StoppingOptions", "stopping")
AccuracyOptions = _group_class("AccuracyOptions", "accuracy")
NewtonOptions = _group_class("NewtonOptions", "newton")
EmuOptions = _group_class("EmuOptions", "emu")
FemOptions = _group_class("FemOptions", "fem")
GROUP_CLASSES = (StoppingOptions, AccuracyOptions, NewtonOptions, EmuOptions, FemOptions)


def merge_groups(groups, options: dict) -> dict:
    """One {option: value} from option group objects and keyword options:
    each group once, each option given once (TypeError naming it otherwise);
    a group's fields at their default are left out (they change nothing and
    need not apply to the method)."""
    merged, seen = dict(options), set()
    for g in groups:
        if not isinstance(g, OptionGroup):
            raise TypeError(f"options are passed by keyword or as option groups (emu.StoppingOptions(...), ...), "
                            f"got {g!r}")
        if type(g) in seen:
            raise TypeError(f"{type(g).__name__} is given twice; pass one")
        seen.add(type(g))
        for name, v in g.given().items():
            if name in merged:
                raise TypeError(f"{name} is given twice (as a keyword and in {type(g).__name__}); give it once")
            merged[name] = v
    return merged


def check_options(method: str, step: str, given: dict) -> None:
    """Raise ValueError for an option that is not one (naming the nearest) or
    that does not apply to ``method`` (and EMU's ``step``), naming it; an
    option given at its default changes nothing and passes."""
    for name in given:
        o = OPTIONS.get(name)
        if o is None:
            near = difflib.get_close_matches(name, OPTIONS, n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise ValueError(f"unknown solver option {name!r}{hint}; the options are listed by "
                             "help(emu.Solver) and in docs/guide/options.md")
        if given[name] is o.default or given[name] == o.default:
            continue   # the default changes nothing, whatever the method
        if o.choices and given[name] not in o.choices:
            raise ValueError(f"{name} must be one of {', '.join(map(repr, o.choices))}, got {given[name]!r}")
        if method not in o.methods:
            raise ValueError(f"{name} is an option of {' and '.join(m.upper() for m in o.methods)} only; leave "
                             f"it out for method={method!r}")
        if o.steps is not None and method == "emu" and step not in o.steps:
            raise ValueError(f"{name} applies to EMU's {' or '.join(o.steps)} step only; leave it out for "
                             f"step={step!r}")


def parse_option(text: str) -> tuple:
    """(name, value) of a command-line ``NAME=VALUE`` (emu solve/run --option),
    the value read as the table's type says: a number, true/false, none, or
    one of the option's choices. ValueError naming the problem otherwise."""
    name, eq, raw = text.partition("=")
    name, raw = name.strip(), raw.strip()
    if not eq or not name:
        raise ValueError(f"--option takes NAME=VALUE (e.g. rtol_grad=1e-8), got {text!r}")
    o = OPTIONS.get(name)
    if o is None:
        near = difflib.get_close_matches(name, OPTIONS, n=1)
        raise ValueError(f"unknown solver option {name!r}" + (f" (did you mean {near[0]!r}?)" if near else "")
                         + "; the options are listed in docs/guide/options.md")
    types = o.type if isinstance(o.type, tuple) else (o.type,)
    if raw.lower() == "none" and type(None) in types:
        return name, None
    if bool in types:
        if raw.lower() in ("true", "on", "yes", "1"):
            return name, True
        if raw.lower() in ("false", "off", "no", "0"):
            return name, False
    for t in (int, float):
        if t in types:
            try:
                return name, t(raw)
            except ValueError:
                pass
    if str in types:
        return name, raw
    want = " or ".join("none" if t is type(None) else "true/false" if t is bool else t.__name__ for t in types)
    raise ValueError(f"--option {name} takes {want}, got {raw!r}")


def scene_file_types() -> dict:
    """{option: type} for a scene file's [solver] table (None-able options
    take their value type; None is not written in TOML)."""
    out = {"method": str}
    for o in _TABLE:
        if o.name == "single_precision_s0":
            continue
        t = o.type if isinstance(o.type, tuple) else (o.type,)
        t = tuple(x for x in t if x is not type(None))
        out[o.name] = t[0] if len(t) == 1 else t
    return out


def solver_signature(init) -> inspect.Signature:
    """Solver.__init__'s signature from the table (help(), IDEs): self, scene,
    method, *groups, then every option keyword-only with its default."""
    params = list(inspect.signature(init).parameters.values())[:4]
    params += [inspect.Parameter(o.name, inspect.Parameter.KEYWORD_ONLY, default=o.default) for o in _TABLE]
    return inspect.Signature(params)


def options_text() -> str:
    """The options as plain text by group (Solver's docstring)."""
    classes = {c.group: c.__name__ for c in GROUP_CLASSES}
    out = ["", "    Options", "    -------"]
    for group, title in GROUPS.items():
        out += ["", f"    {title}" + (f" (emu.{classes[group]}):" if group in classes else ":"), _group_text(group)]
    return "\n".join(out) + "\n"


def options_markdown() -> str:
    """The options page (docs/guide/options.md): a table per group."""
    out = ["# Solver options", "",
           "Every option of `emu.Solver(scene, method, **options)`, `emu.solve(...)`, a scene file's "
           "`[solver]` table and `emu solve`/`emu run --option NAME=VALUE`, by group. An option that does not "
           "apply to the method chosen is an error naming it. A group can also be built once as an object and "
           "passed to several solvers, e.g. `emu.Solver(scene, \"emu\", emu.StoppingOptions(rtol_grad=1e-8), "
           "emu.EmuOptions(step=\"lbfgs\"))`; its fields are the group's options below. Generated from `emu.options.OPTIONS` (`python -c \"from emu.solve.options import "
           "options_markdown as m; print(m(), end='')\" > docs/guide/options.md`; a test keeps this page "
           "current).", ""]
    classes = {c.group: c.__name__ for c in GROUP_CLASSES}
    for group, title in GROUPS.items():
        out += [f"## {title}", ""]
        if group in classes:
            out += [f"As an object: `emu.{classes[group]}(...)`.", ""]
        out += ["| option | default | methods | what it does |", "|---|---|---|---|"]
        for o in _TABLE:
            if o.group != group:
                continue
            where = ", ".join(m.upper() for m in o.methods)
            if o.steps:
                where += f" ({', '.join(o.steps)})"
            doc = o.doc.replace("|", "\\|")   # |g| inside a table cell
            if o.choices:
                doc += " Choices: " + ", ".join(f"`{c!r}`" for c in o.choices) + "."
            out.append(f"| `{o.name}` | `{o.default!r}` | {where} | {doc} |")
        out.append("")
    return "\n".join(out)



@dataclass
class Lowered:
    """A Solver's options as the C++ core takes them (lower)."""
    solver: object             # _core.SolverOptions
    emu: object | None         # _core.EmuSolverOptions (EMU), None for FEM
    settings: dict             # Solution.settings: the options as applied
    accuracy: float | None     # the accuracy asked for (EMU's default included)
    alpha: float               # EMU's alpha relative to the reference shear modulus
    error_estimate: bool       # EMU: estimate every solve's error to FEM
    fem_correction: bool       # EMU with accuracy: correct answers by FEM Newton steps


def check_values(values: dict) -> None:
    """ValueError naming the first option whose value its table entry's check refuses."""
    for o in _TABLE:
        if o.check is not None and not o.check(values[o.name]):
            raise ValueError(f"{o.name} {o.must}, got {values[o.name]!r}")


def _as_core(o: Option, v):
    """v as the core's field of o takes it: the table's (first) type."""
    t = next(t for t in (o.type if isinstance(o.type, tuple) else (o.type,)) if t is not type(None))
    return t(v) if t in (bool, int, float) else v


def lower(method: str, values: dict, scene) -> Lowered:
    """Every option's value (the table's defaults filled in, check_options passed)
    checked and lowered to the core's options for ``scene``: the options the
    table marks ``core`` copied, the rest derived here (accuracy's step test,
    defaults that depend on the method or step, alpha in absolute units)."""
    check_values(values)
    v = values
    step, accuracy = v["step"], v["accuracy"]
    if method == "emu" and v["alpha"] is None and accuracy is None and v["error_estimate"]:
        accuracy = DEFAULT_ACCURACY   # the default, every step kind: an answer within 1% of FEM's
    accuracy = None if accuracy is None else float(accuracy)
    alpha = DEFAULT_ALPHA if v["alpha"] is None else float(v["alpha"])
    so = _core.SolverOptions()
    for o in _TABLE:
        if o.core == "solver":
            setattr(so, o.name, _as_core(o, v[o.name]))
    max_iterations = v["max_iterations"]
    if max_iterations is None:
        max_iterations = 200 if method == "fem" else {"newton-krylov": 500, "lbfgs": 5000}.get(step, 20000)
    so.max_iterations = int(max_iterations)
    position_tol = _step_test(so, method, step, accuracy, v, scene)
    settings = dict(method=method, rtol_grad=v["rtol_grad"], rtol_energy=v["rtol_energy"],
                    noise_factor=float(v["noise_factor"]),
                    position_tol=None if position_tol is None else float(position_tol),
                    eigen_filter=v["eigen_filter"], step_fraction=float(v["step_fraction"]),
                    max_iterations=int(max_iterations), accuracy=accuracy)
    if v["lagged_factor"]:
        if scene.contact is not None:
            raise ValueError("lagged_factor does not handle contact yet (the contact pairs change the "
                             "Newton matrix's pattern); leave it off for scenes with contact")
        so.lagged_cg_iterations = int(v["lagged_cg_iterations"])
        so.lagged_refresh = bool(v["lagged_refresh"])
        if accuracy is not None:
            # PCG's forcing term at most FEM_ACCURACY_CG_FORCING: where the step test
            # applies its steps are then Newton steps (with a looser one a soft mode
            # gives short inexact steps that stop the solve short of the accuracy;
            # docs/DESIGN.md, "Accuracy mode as shipped" and "A short step is evidence
            # only when it is an accurate Newton step")
            so.lagged_cg_forcing = FEM_ACCURACY_CG_FORCING
        settings.update(lagged_factor=True, lagged_cg_iterations=int(v["lagged_cg_iterations"]),
                        lagged_refresh=bool(v["lagged_refresh"]))
    eo = _emu_options(v, step, accuracy, alpha * scene.reference_shear_modulus()) if method == "emu" else None
    fem_correction = v["fem_correction"]
    if fem_correction is None:
        # by default not with contact: the corrections are full Newton steps that
        # know no collision detection, and they can land farther than the accuracy
        # while the estimate itself is right (docs/DESIGN.md, "Contact")
        fem_correction = scene.contact is None
    return Lowered(solver=so, emu=eo, settings=settings, accuracy=accuracy, alpha=alpha,
                   error_estimate=(bool(v["error_estimate"]) or accuracy is not None) and method == "emu",
                   fem_correction=bool(fem_correction) and method == "emu")


def _step_test(so, method: str, step: str, accuracy, v: dict, scene):
    """The step test's fields of so: accuracy's (both methods), or EMU Newton-Krylov's
    position_tol; returns position_tol as applied (None: not applied)."""
    if accuracy is not None:
        so.step_tol = float(v["step_fraction"]) * accuracy * bbox_diagonal(scene.points)
        so.step_tol_grad = STEP_GRAD
        so.step_tol_cold_scale = True   # warm starts gate on the cold start's |g| too (STEP_GRAD)
        if method == "fem":   # FEM's stop sees its steps contract (EMU's answers are checked by the estimate)
            so.step_tol_contraction = CERTIFY_CONTRACTION
        return None   # accuracy mode's own step test applies
    if method == "emu" and step == "newton-krylov" and v["position_tol"] > 0:
        # (Newton-Krylov only: its steps contract by at least half, so a
        # short full step bounds the distance left; the Woodbury and L-BFGS
        # steps converge slowly and linearly)
        so.step_tol = float(v["position_tol"]) * bbox_diagonal(scene.points)
        so.step_tol_grad = POSITION_TOL_GRAD
        return v["position_tol"]
    return None


def _emu_options(v: dict, step: str, accuracy, alpha_absolute: float):
    """EMU's core options: the table's ``core="emu"`` fields, alpha in absolute units,
    and the defaults that depend on the step or the accuracy."""
    eo = _core.EmuSolverOptions()
    for o in _TABLE:
        if o.core == "emu":
            setattr(eo, o.name, _as_core(o, v[o.name]))
    eo.alpha = alpha_absolute
    cg_forcing_min = v["cg_forcing_min"]
    if cg_forcing_min is None:
        cg_forcing_min = ACCURACY_CG_FORCING_MIN if accuracy is not None else 0.0
    eo.cg_forcing_min = float(cg_forcing_min)
    refresh = v["preconditioner_refresh"]
    eo.preconditioner_refresh = int(LBFGS_REFRESH if refresh is None and step == "lbfgs" else
                                    3 if refresh is None else refresh)
    single = v["single_precision_preconditioner"]
    if v["single_precision_s0"] is not None:
        if single is not None:
            raise ValueError("single_precision_s0 is the old name of single_precision_preconditioner; "
                             "give only single_precision_preconditioner")
        warnings.warn("single_precision_s0 is now single_precision_preconditioner (it rounds the "
                      "block inverses too); use that name", DeprecationWarning, stacklevel=4)
        single = v["single_precision_s0"]
    eo.single_precision_preconditioner = True if single is None else bool(single)
    return eo
