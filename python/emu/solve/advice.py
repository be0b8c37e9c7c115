"""Which method is faster for a scene, by the measured crossover.

EMU's work grows with the soft tets (nine unknowns each); FEM's with the
factorisation of its Newton matrix over the soft vertices, which grows
faster. Measured as a user runs them (bench/shipped.py: setup + solve at
accuracy=0.01, estimates included, 1 thread; docs/DESIGN.md, "Where EMU
wins"), EMU beat the faster FEM baseline only from the sizes below; under
them the hint names FEM.
"""
from __future__ import annotations

__all__ = ["soft_tets", "faster_method", "method_hint", "EMU_FROM_SOFT_TETS", "MEASURED_UP_TO"]

# soft (muscle and tendon) tets from which EMU as shipped was faster than the
# faster FEM baseline, by scene kind (with or without a bone the muscles
# move) and use (single solves from rest, or the warm frames of a sequence);
# None: EMU was slower at every size measured, up to MEASURED_UP_TO
EMU_FROM_SOFT_TETS = {("muscles", "single"): 40_000, ("muscles", "sequence"): 81_000,
                      ("bones", "single"): 80_000, ("bones", "sequence"): None}
MEASURED_UP_TO = {("muscles", "single"): 585_336, ("muscles", "sequence"): 81_000,
                  ("bones", "single"): 113_724, ("bones", "sequence"): 53_508}


def soft_tets(scene) -> int:
    """The number of muscle and tendon tets (EMU's unknowns are nine per soft tet)."""
    return int(sum(len(p.tets) for p in scene.parts.values() if p.kind != "bone"))


def _key(scene, sequence: bool) -> tuple:
    return ("bones" if scene.movable_bones else "muscles", "sequence" if sequence else "single")


def faster_method(scene, sequence: bool = False) -> str:
    """"emu" or "fem": the method measured faster at this scene's size and kind (see module)."""
    limit = EMU_FROM_SOFT_TETS[_key(scene, sequence)]
    return "emu" if limit is not None and soft_tets(scene) >= limit else "fem"


def method_hint(scene, method: str, sequence: bool = False, dynamics: bool = False) -> str | None:
    """A one-line hint where ``method`` is on the slower side of the measured
    crossover for this scene's size and kind, naming the faster one; None otherwise.
    dynamics: the frames are time steps with inertia, where EMU was slower than FEM
    at every size measured (docs/DESIGN.md, "Dynamics")."""
    if dynamics:
        return None if method == "fem" else (
            "hint: EMU's time steps were slower than FEM's at every size measured (its error estimate "
            "alone costs about a FEM step; 0.30x on the 17k-tet muscle): method='fem', or with lagged_factor=True")
    faster = faster_method(scene, sequence)
    if faster == method:
        return None
    key = _key(scene, sequence)
    n, limit = soft_tets(scene), EMU_FROM_SOFT_TETS[key]
    kind = "with a moving bone" if key[0] == "bones" else "without moving bones"
    what = "frames of a sequence" if sequence else "single solves"
    where = (f"measured crossover for scenes {kind}: {limit:,} soft tets" if limit is not None else
             f"for scenes {kind} EMU was slower at every size measured, up to {MEASURED_UP_TO[key]:,} soft tets")
    if faster == "fem":
        return (f"hint: at {n:,} soft tets FEM is as fast as EMU or faster for {what} ({where}): "
                "method='fem', or with lagged_factor=True")
    return f"hint: at {n:,} soft tets EMU is faster than FEM for {what} ({where}): method='emu'"
