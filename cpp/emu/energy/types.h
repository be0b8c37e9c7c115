#pragma once
// Fixed-size types shared by the element kernels. vec(F) is column-major:
// vec(F)[i + 3 j] = F(i, j), so column j of F is entries 3j..3j+2.
#include <Eigen/Dense>

namespace emu {
using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Vec9 = Eigen::Matrix<double, 9, 1>;
using Mat9 = Eigen::Matrix<double, 9, 9>;
using Vec12 = Eigen::Matrix<double, 12, 1>;
using Mat12 = Eigen::Matrix<double, 12, 12>;

inline Vec9 flatten(const Mat3& F) { return Eigen::Map<const Vec9>(F.data()); }
inline Mat3 unflatten(const Vec9& f) { return Eigen::Map<const Mat3>(f.data()); }

/// [v]_x, the matrix with [v]_x w = v x w.
inline Mat3 cross_matrix(const Vec3& v) {
  Mat3 m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}
}  // namespace emu
