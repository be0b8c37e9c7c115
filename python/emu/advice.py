"""Which method is faster for a scene, by the measured crossover.

EMU's work grows with the soft tets (nine unknowns each); FEM's with the
factorisation of its Newton matrix over the soft vertices, which grows
faster. Measured as a user runs them (bench/shipped.py: setup + solve at
accuracy=0.01, estimates included, 1 thread; docs/DESIGN.md, "Where EMU
wins"), EMU beat the faster FEM baseline only from the sizes below; under
them the hint names FEM.
"""
from __future__ import annotations

__all__ = ["soft_tets", "faster_method", "method_hint", "EMU_FROM_SOFT_TETS"]

# soft (muscle and tendon) tets from which EMU as shipped was the faster
# method: single solves from rest, and the warm frames of a sequence
EMU_FROM_SOFT_TETS = {"single": 80_000, "sequence": 80_000}


def soft_tets(scene) -> int:
    """The number of muscle and tendon tets (EMU's unknowns are nine per soft tet)."""
    return int(sum(len(p.tets) for p in scene.parts.values() if p.kind != "bone"))


def faster_method(scene, sequence: bool = False) -> str:
    """"emu" or "fem": the method measured faster at this scene's size (see module)."""
    return "emu" if soft_tets(scene) >= EMU_FROM_SOFT_TETS["sequence" if sequence else "single"] else "fem"


def method_hint(scene, method: str, sequence: bool = False) -> str | None:
    """A one-line hint where ``method`` is on the slower side of the measured
    crossover for this scene's size, naming the faster one; None otherwise."""
    faster = faster_method(scene, sequence)
    if faster == method:
        return None
    n, limit = soft_tets(scene), EMU_FROM_SOFT_TETS["sequence" if sequence else "single"]
    what = "frames of a sequence" if sequence else "single solves"
    if faster == "fem":
        return (f"hint: at {n:,} soft tets FEM is faster than EMU for {what} (measured crossover: {limit:,} "
                "soft tets): method='fem', or with lagged_factor=True")
    return (f"hint: at {n:,} soft tets EMU is faster than FEM for {what} (measured crossover: {limit:,} soft tets): "
            "method='emu'")
