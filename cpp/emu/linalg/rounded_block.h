#pragma once
// A symmetric positive definite 9x9 block kept in single precision for a
// preconditioner: half the bytes a CG iteration streams per block pass
// (docs/DESIGN.md, "The block inverses in single precision").
//
// Rounding each entry of an SPD B moves it by E with |E_ij| <= u |B_ij|
// (u = 2^-24), so ||E||_2 <= ||E||_F <= 9 u max|B_ij|: an ill-conditioned B
// (condition above about 1 / (9 u), 2e6) could round to an indefinite matrix,
// and CG needs a definite preconditioner. The stored block is
//   B~ = fl(B + delta I),  delta = 10 u max|B_ij|,
// so B~ - B = delta I + E' with ||E'||_2 < delta (the diagonal's rounding of
// B_ii + delta included): B~ >= B in the Loewner order, definite whenever B
// is, and exactly symmetric. Products cast the block back to double: the
// preconditioner stays one fixed linear map.
#include <cmath>

#include <Eigen/Core>

#include "emu/energy/types.h"

namespace emu {

using Mat9f = Eigen::Matrix<float, 9, 9>;

/// out = fl(B + delta I), delta = 10 u max|B_ij| (above). B: symmetric.
inline void round_spd_block(const Mat9& B, Mat9f& out) {
  const double delta = 10.0 * std::ldexp(1.0, -24) * B.cwiseAbs().maxCoeff();
  Mat9 shifted = B;
  shifted.diagonal().array() += delta;
  out = shifted.cast<float>();
}

/// B x for a block stored in double or (rounded) in single precision.
template <class Vec>
inline Vec9 block_times(const Mat9& B, const Vec& x) {
  return B.lazyProduct(x);
}
template <class Vec>
inline Vec9 block_times(const Mat9f& B, const Vec& x) {
  return B.cast<double>().lazyProduct(x);
}

}  // namespace emu
