#pragma once
// Backtracking (Armijo) line search on a scalar function of the step length,
// and the round-off rule for when no step lowers the energy.
#include <cmath>

#include "emu/solvers/solver_options.h"

namespace emu {

struct LineSearchResult {
  double step = 0, energy = 0;
  int backtracks = 0;
  bool success = false;
};

/// Halves s from s0 until E(s) <= E0 + armijo s slope and E(s) < E0.
/// energy_at(s) may return a non-finite value: that step is rejected.
template <class EnergyAt>
LineSearchResult armijo_backtracking(EnergyAt&& energy_at, double E0, double slope, const SolverOptions& o,
                                     double s0 = 1.0) {
  LineSearchResult r;
  double s = s0;
  for (int b = 0; b <= o.max_backtracks; ++b) {
    const double E = energy_at(s);
    // Strict decrease as well: at round-off the Armijo bound rounds to E0 and
    // would accept zero-length progress forever.
    if (std::isfinite(E) && E <= E0 + o.armijo * s * slope && E < E0) {
      r.step = s;
      r.energy = E;
      r.backtracks = b;
      r.success = true;
      return r;
    }
    s *= 0.5;
  }
  r.backtracks = o.max_backtracks;
  return r;
}

/// When no step lowers the energy, the energy has hit round-off: it can no
/// longer rank steps, but the gradient can. Accept the full step if it leaves
/// the energy unchanged to round-off and lowers the gradient norm.
inline bool accept_at_roundoff(double E_full, double g_full, double E, double g, double E0) {
  return std::abs(E_full - E) <= 1e-11 * (std::abs(E) + std::abs(E0 - E)) && g_full < g;
}

}  // namespace emu
