#pragma once
// The inverse of a small symmetric positive definite matrix through its
// Cholesky factor, in loops of compile-time length: A = L L^T, W = L^-1 by
// forward substitution, A^-1 = W^T W (each entry summed in the same order as
// its mirror: the result is exactly symmetric). For the 9x9 per-unknown
// blocks of the Newton-Krylov preconditioners, one inversion per unknown and
// rebuild: Eigen's LLT<Mat9>::solve(Identity) goes through its general
// triangular-solve kernels at this size (docs/DESIGN.md, "The cost of an
// iteration": measured in bench/micro/bench_kernels).
#include <cmath>

#include <Eigen/Core>

namespace emu {

/// inv = A^-1 from A's lower triangle; false (inv unspecified) when A is not
/// positive definite (a pivot <= 0 or not finite).
template <int N>
bool spd_inverse(const Eigen::Matrix<double, N, N>& A, Eigen::Matrix<double, N, N>& inv) {
  // The loops run over whole rows of N (zeros where a triangle ends) so that
  // they vectorise: more multiply-adds than the triangles need, no branches.
  double a[N][N], L[N][N] = {}, W[N][N] = {}, rinv[N];
  for (int i = 0; i < N; ++i)
    for (int k = 0; k < N; ++k) a[i][k] = A(i, k);
  for (int j = 0; j < N; ++j) {  // right-looking: column j of L, then the trailing update
    const double d = a[j][j];
    if (!(d > 0) || !std::isfinite(d)) return false;
    const double l = std::sqrt(d);
    rinv[j] = 1.0 / l;
    L[j][j] = l;
    for (int i = j + 1; i < N; ++i) L[i][j] = a[i][j] * rinv[j];
    for (int i = j + 1; i < N; ++i)
      for (int k = 0; k < N; ++k) a[i][k] -= L[i][j] * L[k][j];  // L[k][j] = 0 above row j
  }
  for (int i = 0; i < N; ++i) {  // row i of W = L^-1: (e_i - sum_{k<i} L_ik W_k) / L_ii
    double row[N] = {};
    row[i] = 1.0;
    for (int k = 0; k < i; ++k)
      for (int c = 0; c < N; ++c) row[c] -= L[i][k] * W[k][c];
    for (int c = 0; c < N; ++c) W[i][c] = row[c] * rinv[i];
  }
  double out[N][N] = {};  // A^-1 = W^T W = sum_k (row k of W)^T (row k of W)
  for (int k = 0; k < N; ++k)
    for (int i = 0; i < N; ++i)
      for (int c = 0; c < N; ++c) out[i][c] += W[k][i] * W[k][c];
  for (int i = 0; i < N; ++i)
    for (int c = 0; c < N; ++c) inv(i, c) = out[i][c];
  return true;
}

}  // namespace emu
