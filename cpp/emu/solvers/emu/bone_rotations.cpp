#include "emu/solvers/emu/bone_rotations.h"

#include <Eigen/Eigenvalues>

#include "emu/energy/joint_spring.h"
#include "emu/linalg/rotation.h"

namespace emu::bone_rotations {

void project_tangent(const Mat9X& F, int num_soft, Mat9X& v) {
  for (Eigen::Index u = num_soft; u < F.cols(); ++u)
    v.col(u) = flatten(project_to_tangent(unflatten(F.col(u)), unflatten(v.col(u))));
}

void retract(const Mat9X& F, const Mat9X& d, double s, int num_soft, Mat9X& out) {
  out = F + s * d;
  for (Eigen::Index u = num_soft; u < F.cols(); ++u) out.col(u) = flatten(nearest_rotation(unflatten(out.col(u))));
}

Mat3 riemannian_block(const Mat3& R, const Mat3& G, const Mat3& V, const Mat3& HV, bool curvature,
                      double spring_stiffness) {
  Mat3 M = HV;
  if (curvature) {
    const Mat3 RtG = R.transpose() * G;
    M -= V * (0.5 * (RtG + RtG.transpose()));
  } else if (spring_stiffness > 0) {
    // For V = R [w]x the spring's curvature is R [C w / 2]x with
    // C = k/2 (tr R I - sym R) (joint_spring::expmap_hessian), clamped PSD.
    const Mat3 C = joint_spring::expmap_hessian(R, spring_stiffness);
    Eigen::SelfAdjointEigenSolver<Mat3> eig(C);
    const Mat3 Cp = eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).asDiagonal() * eig.eigenvectors().transpose();
    const Mat3 W = R.transpose() * V;
    const Vec3 w(0.5 * (W(2, 1) - W(1, 2)), 0.5 * (W(0, 2) - W(2, 0)), 0.5 * (W(1, 0) - W(0, 1)));
    M += R * cross_matrix(0.5 * (Cp * w));
  }
  return project_to_tangent(R, M);
}

void riemannian_columns(const Mat9X& F, const Mat9X& g, const Mat9X& v, bool curvature, int num_soft,
                        const Eigen::VectorXd& spring_stiffness, Mat9X& out) {
  for (Eigen::Index u = num_soft; u < F.cols(); ++u) {
    const Eigen::Index b = u - num_soft;
    const double k = b < spring_stiffness.size() ? spring_stiffness(b) : 0.0;
    out.col(u) = flatten(riemannian_block(unflatten(F.col(u)), unflatten(g.col(u)), unflatten(v.col(u)),
                                          unflatten(out.col(u)), curvature, k));
  }
}

}  // namespace emu::bone_rotations
