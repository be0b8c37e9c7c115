#pragma once
// Rest-shape operators of a tetrahedral mesh.
//
// For tet t with vertices x_0..x_3, F_t = D_s D_m^-1 = sum_a x_a b_a^T, where
// b_a are the gradients of the linear shape functions (b_0 = -(b_1+b_2+b_3)).
// So vec F_t = G_t x_t with G_t[i + 3k, 3a + i] = b_a[k] (9 x 12); G_t is never
// formed, the b_a are enough.
#include <vector>

#include <Eigen/Core>

#include "emu/energy/types.h"

namespace emu {

using ShapeGrads = Eigen::Matrix<double, 4, 3>;  // row a is b_a^T

struct TetGeometry {
  Eigen::VectorXd volume;        // #T rest volumes (positive)
  std::vector<ShapeGrads> grad;  // #T shape-function gradients
};

/// X  #V by 3 rest positions;  T  #T by 4 vertex indices (positively oriented).
/// Throws std::invalid_argument if a tet has non-positive volume.
TetGeometry tet_geometry(const Eigen::MatrixX3d& X, const Eigen::MatrixX4i& T);

/// The length of the diagonal of the axis-aligned bounding box of points X (#V by 3).
inline double bbox_diagonal(const Eigen::MatrixX3d& X) {
  return (X.colwise().maxCoeff() - X.colwise().minCoeff()).norm();
}

/// Signed volumes, #T (negative: wrong vertex order).
Eigen::VectorXd signed_volumes(const Eigen::MatrixX3d& X, const Eigen::MatrixX4i& T);

/// F = sum_a x_a b_a^T for the tet's current corner positions.
inline Mat3 deformation_gradient(const ShapeGrads& b, const Eigen::MatrixX3d& x,
                                 const Eigen::MatrixX4i& T, Eigen::Index t) {
  Mat3 F = Mat3::Zero();
  for (int a = 0; a < 4; ++a) F.noalias() += x.row(T(t, a)).transpose() * b.row(a);
  return F;
}

/// Per-corner force-like vectors of a 3x3 stress P: out.segment<3>(3a) = P b_a.
inline Vec12 corner_vectors(const ShapeGrads& b, const Mat3& P) {
  Vec12 g;
  for (int a = 0; a < 4; ++a) g.segment<3>(3 * a) = P * b.row(a).transpose();
  return g;
}

/// 12x12 position Hessian G^T H G of a 9x9 F-space Hessian H (vec(F) column-major):
/// K[3a+i, 3c+j] = sum_{k,l} H[i+3k, j+3l] b_a[k] b_c[l].
/// Formed in two contractions with the shape gradients instead of the dense
/// product with the 9x12 matrix G (mostly zeros): first P = (b (x) I3)^T H,
/// P[3a+i, :] = sum_k b_a[k] H[i+3k, :], then K[:, 3c+j] = sum_l P[:, j+3l] b_c[l]
/// (about 750 multiply-adds against 2,268).
inline Mat12 position_hessian(const ShapeGrads& b, const Mat9& H) {
  Eigen::Matrix<double, 12, 9> P;
  for (int a = 0; a < 4; ++a)
    P.middleRows<3>(3 * a) = b(a, 0) * H.middleRows<3>(0) + b(a, 1) * H.middleRows<3>(3) + b(a, 2) * H.middleRows<3>(6);
  Mat12 K;
  for (int c = 0; c < 4; ++c)
    K.middleCols<3>(3 * c) = b(c, 0) * P.middleCols<3>(0) + b(c, 1) * P.middleCols<3>(3) + b(c, 2) * P.middleCols<3>(6);
  return K;
}

}  // namespace emu
