#pragma once
// The analytic eigensystem of the Stable Neo-Hookean Hessian (Smith, de Goes,
// Kim 2019, "Analytic Eigensystems for Isotropic Distortion Energies") and the
// PSD projection built from it, in place of a numerical 9x9 eigen-decomposition.
//
// With the rotation-variant SVD F = U diag(s) V^T (U, V rotations; s_2 < 0
// when F is inverted), write Psi in the invariants I_C = |F|^2 and J = det F:
//   Psi = mu/2 (I_C - 3) - mu/2 log(I_C + 1) + lambda/2 (J - beta)^2,
// so d2Psi/dF2 = 2 Psi_C I_9 + Psi_CC g_C g_C^T + Psi_J d2J/dF2 + Psi_JJ g_J g_J^T
// with base = 2 Psi_C = mu (1 - 1/(I_C+1)), Psi_J = lambda (J - beta).
// Its nine eigenpairs (q = vec(U D V^T), D of unit norm):
//   twist k (D = (e_j e_i^T - e_i e_j^T)/sqrt2, {i,j,k} a cycle):  base + Psi_J s_k
//   flip  k (D = (e_j e_i^T + e_i e_j^T)/sqrt2):                   base - Psi_J s_k
//   scaling (D = diag(e), e an eigenvector of the 3x3 matrix of d2Psi/ds2)
//     A = base I + 2 mu/(I_C+1)^2 s s^T + lambda c c^T + Psi_J [0 s3 s2; s3 0 s1; s2 s1 0],
//     c = dJ/ds = (s2 s3, s1 s3, s1 s2)
// (the twist and flip modes are orthogonal to g_C = 2 vec F and g_J = vec cof F,
// which are diagonal in the U, V frame; d2J/dF2 acts as +-s_k on them).
#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include "emu/energy/psd_project.h"
#include "emu/energy/stable_neo_hookean.h"
#include "emu/energy/types.h"

namespace emu::snh {

struct Eigensystem {
  Mat3 U, V;     // rotations
  Vec3 sigma;    // signed singular values: F = U diag(sigma) V^T
  Vec3 twist, flip;           // eigenvalues of the modes opposite axis k
  Vec3 scaling;               // eigenvalues of the diagonal (scaling) modes
  Mat3 scaling_directions;    // column m: the diagonal of D for scaling eigenvalue m
};

/// F = U diag(sigma) V^T with U and V rotations (the sign of det F on sigma_2),
/// sigma_0 >= sigma_1 >= |sigma_2|. Fast path: V from the closed-form
/// eigen-decomposition of F^T F, u_i = F v_i / sigma_i for the two largest
/// (u_1 re-orthogonalised against u_0), u_2 = u_0 x u_1 and the signed sigma_2 =
/// u_2^T F v_2; the Jacobi SVD where the second singular value is too small for
/// that division or the result does not reproduce F.
inline void rotation_variant_svd(const Mat3& F, Mat3& U, Vec3& sigma, Mat3& V) {
  Eigen::SelfAdjointEigenSolver<Mat3> eig;
  eig.computeDirect(F.transpose() * F);
  const Vec3 ev = eig.eigenvalues();  // increasing
  if (ev(2) > 0 && ev(1) > 1e-6 * ev(2)) {
    V.col(0) = eig.eigenvectors().col(2);
    V.col(2) = V.col(0).cross(eig.eigenvectors().col(1)).normalized();
    V.col(1) = V.col(2).cross(V.col(0));
    const Vec3 f0 = F * V.col(0), f1 = F * V.col(1);
    U.col(0) = f0.normalized();
    U.col(1) = (f1 - U.col(0).dot(f1) * U.col(0)).normalized();
    U.col(2) = U.col(0).cross(U.col(1));
    const Mat3 D = U.transpose() * F * V;  // diag(sigma) up to the error of V
    const double off = D.squaredNorm() - D.diagonal().squaredNorm();
    if (off <= 1e-22 * F.squaredNorm() && D(1, 1) >= std::abs(D(2, 2))) {
      sigma = D.diagonal();
      return;
    }
  }
  const Eigen::JacobiSVD<Mat3> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  U = svd.matrixU();
  V = svd.matrixV();
  sigma = svd.singularValues();
  if (U.determinant() < 0) {
    U.col(2) = -U.col(2);
    sigma(2) = -sigma(2);
  }
  if (V.determinant() < 0) {
    V.col(2) = -V.col(2);
    sigma(2) = -sigma(2);
  }
}

/// The singular values, rotations and twist / flip eigenvalues of es, and the
/// 3x3 matrix A of the scaling modes (its eigen-decomposition left to the caller).
inline Mat3 eigensystem_without_scaling(const Mat3& F, double mu, double lambda, Eigensystem& es) {
  rotation_variant_svd(F, es.U, es.sigma, es.V);
  const Vec3& s = es.sigma;
  const double ic1 = 4.0 + ic_minus_3(F);                    // I_C + 1
  const double base = mu * (1.0 - 1.0 / ic1);                 // 2 Psi_C
  const double psi_j = lambda * det_minus_1(F) - 0.75 * mu;   // lambda (J - beta), no O(lambda) cancellation
  for (int k = 0; k < 3; ++k) {
    es.twist(k) = base + psi_j * s(k);
    es.flip(k) = base - psi_j * s(k);
  }
  const Vec3 c(s(1) * s(2), s(0) * s(2), s(0) * s(1));
  Mat3 A = base * Mat3::Identity() + (2.0 * mu / (ic1 * ic1)) * s * s.transpose() + lambda * c * c.transpose();
  A(0, 1) += psi_j * s(2);
  A(1, 0) += psi_j * s(2);
  A(0, 2) += psi_j * s(1);
  A(2, 0) += psi_j * s(1);
  A(1, 2) += psi_j * s(0);
  A(2, 1) += psi_j * s(0);
  return A;
}

inline Eigensystem eigensystem(const Mat3& F, double mu, double lambda) {
  Eigensystem es;
  const Eigen::SelfAdjointEigenSolver<Mat3> eig(eigensystem_without_scaling(F, mu, lambda, es));
  es.scaling = eig.eigenvalues();
  es.scaling_directions = eig.eigenvectors();
  return es;
}

/// The unit eigenvector vec(U D V^T) of a twist (flip = false) or flip mode opposite axis k.
inline Vec9 twist_flip_mode(const Eigensystem& es, int k, bool flip) {
  const int i = (k + 1) % 3, j = (k + 2) % 3;
  const double r = std::sqrt(0.5);
  const Mat3 Q = r * (es.U.col(j) * es.V.col(i).transpose() +
                      (flip ? 1.0 : -1.0) * es.U.col(i) * es.V.col(j).transpose());
  return flatten(Q);
}

/// The unit eigenvector vec(U diag(e_m) V^T) of scaling mode m.
inline Vec9 scaling_mode(const Eigensystem& es, int m) {
  return flatten(Mat3(es.U * es.scaling_directions.col(m).asDiagonal() * es.V.transpose()));
}

/// The Stable Neo-Hookean Hessian H = hessian(F, mu, lambda) made PSD: each
/// negative eigenvalue lam of the analytic eigensystem replaced by 0 (Clamp)
/// or -lam (Abs), as psd_project<9>(H) does numerically; H itself (bit for
/// bit) when no eigenvalue is negative. Only the negative modes are formed:
///   H_psd = H + sum_{lam_m < 0} (filter(lam_m) - lam_m) q_m q_m^T.
inline Mat9 project_hessian(const Mat9& H, const Mat3& F, double mu, double lambda,
                            EigenFilter filter = EigenFilter::Clamp) {
  Mat9 P = H;
  Eigensystem es;
  const Mat3 A = eigensystem_without_scaling(F, mu, lambda, es);
  const double gain = filter == EigenFilter::Clamp ? -1.0 : -2.0;  // filter(lam) - lam = gain * lam
  auto lift = [&](double lam, const Vec9& q) { P.noalias() += (gain * lam) * q * q.transpose(); };
  for (int k = 0; k < 3; ++k) {
    if (es.twist(k) < 0) lift(es.twist(k), twist_flip_mode(es, k, false));
    if (es.flip(k) < 0) lift(es.flip(k), twist_flip_mode(es, k, true));
  }
  // The scaling modes are decomposed only when A is not positive definite
  // (a 3x3 Cholesky decides: rare, mostly under strong compression).
  if (Eigen::LLT<Mat3>(A).info() != Eigen::Success) {
    const Eigen::SelfAdjointEigenSolver<Mat3> eig(A);
    es.scaling = eig.eigenvalues();
    es.scaling_directions = eig.eigenvectors();
    for (int m = 0; m < 3; ++m)
      if (es.scaling(m) < 0) lift(es.scaling(m), scaling_mode(es, m));
  }
  return P;
}

/// hessian(F, mu, lambda) made PSD in closed form (see project_hessian).
inline Mat9 hessian_psd(const Mat3& F, double mu, double lambda, EigenFilter filter = EigenFilter::Clamp) {
  return project_hessian(hessian(F, mu, lambda), F, mu, lambda, filter);
}

}  // namespace emu::snh
