#pragma once
// Project a symmetric 9x9 element Hessian onto the PSD cone by clamping its
// negative eigenvalues to zero. A matrix that is already PSD (checked by a
// Cholesky attempt, far cheaper than the eigen-decomposition) is returned
// unchanged, bit for bit. Fixed size: never allocates.
#include <Eigen/Eigenvalues>

#include "emu/energy/types.h"

namespace emu {

/// How negative eigenvalues are filtered: Clamp sets them to 0 (the classic
/// projection), Abs flips their sign (Chen et al. 2024, "Trust-region
/// eigenvalue filtering for projected Newton": as safe, and it keeps curvature
/// the clamp throws away, so fewer iterations near equilibrium).
enum class EigenFilter { Clamp, Abs };

template <int N>
inline Eigen::Matrix<double, N, N> psd_project(const Eigen::Matrix<double, N, N>& H,
                                               EigenFilter filter = EigenFilter::Clamp) {
  using M = Eigen::Matrix<double, N, N>;
  Eigen::LLT<M> llt(H);
  if (llt.info() == Eigen::Success) return H;
  Eigen::SelfAdjointEigenSolver<M> es(H);
  Eigen::Matrix<double, N, 1> lam = es.eigenvalues();
  lam = filter == EigenFilter::Clamp ? Eigen::Matrix<double, N, 1>(lam.cwiseMax(0.0))
                                     : Eigen::Matrix<double, N, 1>(lam.cwiseAbs());
  return es.eigenvectors() * lam.asDiagonal() * es.eigenvectors().transpose();
}

}  // namespace emu
