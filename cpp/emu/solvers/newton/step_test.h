#pragma once
// SolverOptions::step_tol's stop: a full Newton step this short leaves about
// as short a distance to the answer where Newton converges at least linearly
// at rate <= 1/2 (assumed, or seen with step_tol_contraction: two steps in a
// row of the exact Hessian, each at most that fraction of the shorter of the
// two before it),
// once |g| <= step_tol_grad g_ref (near equilibrium on the load's scale).
// docs/DESIGN.md, "Stopping rule" and "A short step is evidence only when it
// is an accurate Newton step".
#include <algorithm>

#include "emu/solvers/solver_options.h"

namespace emu {

class StepTest {
 public:
  /// After a step: whether the solve stops. exact: the step's direction came
  /// from the exact Hessian; step: its largest vertex move; full: the line
  /// search took the full step; gn: |g| after it; g_ref: the gate's scale.
  bool passes(const SolverOptions& o, bool exact, double step, bool full, double gn, double g_ref) {
    // against both steps before it: along a softly resisted turn Newton's steps
    // alternate (long, short, long: 3.2e-3, 1.1e-3, 2.6e-4 after 1.4e-3), and a
    // short step after a long one is no contraction when the one before was short too
    const double shortest = before2_ >= 0 ? std::min(before_, before2_) : before_;
    const bool contracts = exact && before_ >= 0 && step <= o.step_tol_contraction * shortest;
    const bool seen = o.step_tol_contraction <= 0 || (contracts && contracted_before_);
    before2_ = before_;
    before_ = step;
    contracted_before_ = contracts;
    return full && gn <= o.step_tol_grad * g_ref && step <= o.step_tol && seen;
  }

 private:
  double before_ = -1.0;           // the last step's largest vertex move (-1: none yet)
  double before2_ = -1.0;          // the one before it (-1: none yet)
  bool contracted_before_ = false;  // the last step was exact and at most step_tol_contraction of its own before
};

}  // namespace emu
