#pragma once
// The scale-aware stopping test shared by both solvers.
//
// Energies carry no rest offset, so relative tests are meaningful: converged
// when the last decrease is at most rtol_energy times the total decrease so far
//   E_{k-1} - E_k <= rtol_energy (E_0 - E_k)
// and the gradient norm is at most rtol_grad times the first one
//   |g_k| <= rtol_grad |g_0|.
// A gradient below `floor` (a round-off bound from the problem's own scales)
// counts as zero, which is how an already-converged start stops at once; a
// start also counts as converged below `start_floor` (a problem's measured
// round-off at an exact equilibrium, which may exceed the scale bound).
#include <algorithm>

namespace emu {

struct Convergence {
  double rtol_grad, rtol_energy, E0, g0, floor;
  double start_floor = 0;
  double rel_energy_change = 0;
  bool initial() const { return g0 <= std::max(floor, start_floor); }
  bool test(double E_prev, double E, double g) {
    const double total = E0 - E;
    rel_energy_change = total > 0 ? (E_prev - E) / total : 0.0;
    if (g <= floor) return true;
    return g <= rtol_grad * g0 && (E_prev - E) <= rtol_energy * std::max(total, 0.0);
  }
};

}  // namespace emu
