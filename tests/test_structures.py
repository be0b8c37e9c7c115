"""Solver.structures(): a scene pays only for what it uses. A pinned muscle
builds no bone, joint or Schur structures; each appears with the feature."""
from __future__ import annotations

import emu
from emu.build.scenes import arm, fusiform


def test_pinned_muscle_builds_only_the_acap_factor_and_its_preconditioner():
    s = fusiform(2, warn=False)
    solver = emu.Solver(s, "emu", error_estimate=False, alpha=100)   # the constant-Schur default
    solver.solve({"belly": 5e4})
    built = solver.structures()
    assert set(built) == {"ACAP factor", "constant Schur preconditioner"}, built
    # its own factor (the ACAP matrix's pattern) and one 9x9 inverse per tet, in
    # single precision by default (4 bytes per entry of both)
    # (S0's factor has the ACAP factor's pattern: 8 + 4 bytes per entry)
    assert built["constant Schur preconditioner"] == 1.5 * built["ACAP factor"] + 81 * 4 * len(s.tets), built
    double = emu.Solver(s, "emu", error_estimate=False, alpha=100, single_precision_preconditioner=False).structures()
    assert double["constant Schur preconditioner"] >= double["ACAP factor"] + 81 * 8 * len(s.tets)
    # one tissue (no tendons): S0 is a multiple of K and K's factor serves, only the blocks are its own
    # (and K's single-precision copy, unless single_precision_preconditioner=False)
    one = fusiform(2, tendon_fraction=0.0, warn=False)
    own = emu.Solver(one, "emu", error_estimate=False, alpha=100, single_precision_preconditioner=False).structures()
    assert own["constant Schur preconditioner"] == 81 * 8 * len(one.tets), own
    rounded = emu.Solver(one, "emu", error_estimate=False, alpha=100).structures()
    assert rounded["constant Schur preconditioner"] == 81 * 4 * len(one.tets) + rounded["ACAP factor"] / 2, rounded
    woodbury = emu.Solver(s, "emu", error_estimate=False, alpha=100, preconditioner="woodbury")
    woodbury.solve({"belly": 5e4})
    built = woodbury.structures()
    assert set(built) == {"ACAP factor", "ACAP modes", "Woodbury block inverses"}, built
    assert built["Woodbury block inverses"] >= 81 * 8 * len(s.tets)   # one 9x9 inverse per tet
    assert all(b > 0 for b in built.values())


def test_each_feature_adds_its_own_structures():
    s = fusiform(2, warn=False)
    schur = emu.Solver(s, "emu", preconditioner="schur", error_estimate=False, alpha=100).structures()
    assert "Schur preconditioner" in schur and "ACAP modes" not in schur and "Woodbury block inverses" not in schur
    est = emu.Solver(s, "emu")           # the default estimates its error: FEM's system, built at the first solve
    assert not any(k.startswith("error estimate") for k in est.structures())
    est.solve({"belly": 5e4})
    assert "error estimate: Hessian factor" in est.structures()
    a = arm(1)
    bones = emu.Solver(a, "emu", error_estimate=False, alpha=100).structures()
    assert "movable bones and their coarse space" in bones and "joints" in bones
    plain = emu.Solver(a, "emu", error_estimate=False, alpha=100, bone_coarse_space=False).structures()
    assert "movable bones and their coarse space" not in plain and "joints" in plain


def test_fem_lists_bones_only_where_a_bone_moves():
    assert "movable bones" not in emu.Solver(fusiform(2, warn=False), "fem").structures()
    assert "movable bones" in emu.Solver(arm(1), "fem").structures()
