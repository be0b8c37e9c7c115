#pragma once
// A passive joint spring on a movable bone's rotation R about its rest
// orientation,
//   E(R) = k/2 (3 - tr R) = k (1 - cos theta) ~ k theta^2 / 2   (theta: the turn).
// EMU works on R itself (its unknown F_b, kept in SO(3)): the Euclidean
// gradient is constant and the Euclidean Hessian zero; the curvature on SO(3)
// comes from the Riemannian term -v sym(R^T g) of EmuSolver.
// FEM works on exponential-map increments R(w) = exp([w]_x) R at w = 0:
//   dE/dw   = k/2 axial(R - R^T) = k/2 (R32 - R23, R13 - R31, R21 - R12)
//   d2E/dw2 = k/2 (tr R I - sym R)   (symmetrised second derivative)
#include "emu/energy/types.h"

namespace emu::joint_spring {

inline double energy(const Mat3& R, double k) { return 0.5 * k * (3.0 - R.trace()); }

/// dE/dR (Euclidean, 3x3).
inline Mat3 gradient(double k) { return -0.5 * k * Mat3::Identity(); }

/// dE/dw at w = 0 for R(w) = exp([w]_x) R.
inline Vec3 expmap_gradient(const Mat3& R, double k) {
  return 0.5 * k * Vec3(R(2, 1) - R(1, 2), R(0, 2) - R(2, 0), R(1, 0) - R(0, 1));
}

/// d2E/dw2 at w = 0 for R(w) = exp([w]_x) R.
inline Mat3 expmap_hessian(const Mat3& R, double k) {
  return 0.5 * k * (R.trace() * Mat3::Identity() - 0.5 * (R + R.transpose()));
}

}  // namespace emu::joint_spring
