#pragma once
// Project a symmetric 9x9 element Hessian onto the PSD cone by clamping its
// negative eigenvalues to zero. A matrix that is already PSD (checked by a
// Cholesky attempt, far cheaper than the eigen-decomposition) is returned
// unchanged, bit for bit. Fixed size: never allocates.
#include <Eigen/Eigenvalues>

#include "emu/energy/types.h"

namespace emu {

template <int N>
inline Eigen::Matrix<double, N, N> psd_project(const Eigen::Matrix<double, N, N>& H) {
  using M = Eigen::Matrix<double, N, N>;
  Eigen::LLT<M> llt(H);
  if (llt.info() == Eigen::Success) return H;
  Eigen::SelfAdjointEigenSolver<M> es(H);
  Eigen::Matrix<double, N, 1> lam = es.eigenvalues().cwiseMax(0.0);
  return es.eigenvectors() * lam.asDiagonal() * es.eigenvectors().transpose();
}

}  // namespace emu
