#pragma once
// Small rotation utilities shared by the solvers (fixed size, no allocation).
#include <cmath>

#include <Eigen/SVD>

#include "emu/energy/types.h"

namespace emu {

/// exp([w]_x) by Rodrigues' formula (second-order series near w = 0).
inline Mat3 rotation_exp(const Vec3& w) {
  const double th = w.norm();
  const Mat3 W = cross_matrix(w);
  if (th < 1e-8) return Mat3::Identity() + W + 0.5 * W * W;
  return Mat3::Identity() + std::sin(th) / th * W + (1 - std::cos(th)) / (th * th) * W * W;
}

/// The rotation nearest to M in the Frobenius norm (polar decomposition);
/// a reflection is turned into the nearest proper rotation.
inline Mat3 nearest_rotation(const Mat3& M) {
  Eigen::JacobiSVD<Mat3> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 U = svd.matrixU();
  if ((U * svd.matrixV().transpose()).determinant() < 0) U.col(2) *= -1.0;
  return U * svd.matrixV().transpose();
}

/// Rotation R minimising sum_i |R (X_i - Xc) - (Y_i - Yc)|^2 (Kabsch), for
/// point sets X, Y (#points by 3) with centroids Xc, Yc. The translation of
/// the best rigid fit is then Yc - R Xc.
inline Mat3 best_rotation(const Eigen::MatrixX3d& X, const Eigen::MatrixX3d& Y) {
  const Eigen::RowVector3d xc = X.colwise().mean(), yc = Y.colwise().mean();
  const Mat3 H = (X.rowwise() - xc).transpose() * (Y.rowwise() - yc);
  Eigen::JacobiSVD<Mat3> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 D = Mat3::Identity();
  if ((svd.matrixV() * svd.matrixU().transpose()).determinant() < 0) D(2, 2) = -1;
  return svd.matrixV() * D * svd.matrixU().transpose();
}

/// The smallest rotation taking unit vector a to unit vector b.
inline Mat3 rotation_between(const Vec3& a, const Vec3& b) {
  const Vec3 v = a.cross(b);
  const double c = a.dot(b), s = v.norm();
  if (s < 1e-14) {
    if (c > 0) return Mat3::Identity();
    return rotation_exp(M_PI * a.unitOrthogonal());
  }
  return rotation_exp(std::atan2(s, c) / s * v);
}

/// The tangent-space projection at rotation R: P_T(M) = R skew(R^T M).
inline Mat3 project_to_tangent(const Mat3& R, const Mat3& M) {
  const Mat3 K = R.transpose() * M;
  return R * (0.5 * (K - K.transpose()));
}

}  // namespace emu
