#pragma once
// One rounding of every entry: the unknowns of an iterate moved up or down by
// one unit in the last place, in a fixed pattern. Whatever is computed from
// the moved copy carries a fresh sample of its rounding errors, so the change
// of a gradient between the two measures the gradient's round-off at that
// iterate (EmuSolver, FemSolver: Problem::gradient_noise).
#include <cmath>
#include <cstdint>
#include <limits>

#include <Eigen/Core>

namespace emu {

/// a (any dense Eigen object) with each entry a_i moved to the next
/// representable value above or below it (the direction a fixed hash of i).
template <class Dense>
void perturb_by_rounding(Dense& a) {
  constexpr double inf = std::numeric_limits<double>::infinity();
  double* p = a.data();
  for (Eigen::Index i = 0; i < a.size(); ++i) {
    const std::uint64_t h = static_cast<std::uint64_t>(i) * 0x9E3779B97F4A7C15ull;  // Fibonacci hashing
    p[i] = std::nextafter(p[i], (h >> 63) ? inf : -inf);
  }
}

}  // namespace emu
