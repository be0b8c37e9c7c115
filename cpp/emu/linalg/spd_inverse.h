#pragma once
// The inverse of a small symmetric positive definite matrix through its
// Cholesky factor, in loops of compile-time length: A = L L^T, W = L^-1 by
// forward substitution, A^-1 = W^T W (each entry summed in the same order as
// its mirror: the result is exactly symmetric). For the 9x9 per-unknown
// blocks of the Newton-Krylov preconditioners, one inversion per unknown and
// rebuild: Eigen's LLT<Mat9>::solve(Identity) goes through its general
// triangular-solve kernels, slower at this size (docs/DESIGN.md, "The cost
// of an iteration").
#include <cmath>
#include <vector>

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

/// The inverses of L blocks at once: lane l of every operation works on
/// block l. The nine pivots' square roots and divisions form one chain of
/// dependent operations per block; L blocks side by side fill the vector
/// lanes and overlap those latencies, and with the lanes innermost the loops
/// can stop where the triangles end (a third of spd_inverse's multiply-adds:
/// the lower triangle of the trailing update, W = L^-1 lower triangular, one
/// triangle of W^T W mirrored). Each entry sums the same nonzero terms in the
/// same order as spd_inverse, which only adds exact zeros besides: the same
/// bits (tested). ok[l]: block l was positive definite (else inv[l] is
/// unspecified). A, inv: L blocks each (docs/DESIGN.md, "The cost of an
/// iteration").
template <int N, int L>
void spd_inverse_lanes(const Eigen::Matrix<double, N, N>* A, Eigen::Matrix<double, N, N>* inv, bool* ok) {
  double a[N][N][L], Lf[N][N][L], W[N][N][L], rinv[N][L];
  bool good[L];
  for (int l = 0; l < L; ++l) good[l] = true;
  for (int i = 0; i < N; ++i)
    for (int k = 0; k <= i; ++k)
      for (int l = 0; l < L; ++l) a[i][k][l] = A[l](i, k);
  for (int j = 0; j < N; ++j) {  // right-looking: column j of L, then the trailing lower triangle
    for (int l = 0; l < L; ++l) {
      const double d = a[j][j][l];
      good[l] = good[l] && d > 0 && std::isfinite(d);
      const double r = std::sqrt(good[l] ? d : 1.0);  // a failed lane goes on with 1: no NaN, no trap
      rinv[j][l] = 1.0 / r;
      Lf[j][j][l] = r;
    }
    for (int i = j + 1; i < N; ++i)
      for (int l = 0; l < L; ++l) Lf[i][j][l] = a[i][j][l] * rinv[j][l];
    for (int i = j + 1; i < N; ++i)
      for (int k = j + 1; k <= i; ++k)
        for (int l = 0; l < L; ++l) a[i][k][l] -= Lf[i][j][l] * Lf[k][j][l];
  }
  for (int i = 0; i < N; ++i) {  // row i of W = L^-1 (columns c <= i)
    double row[N][L];
    for (int c = 0; c <= i; ++c)
      for (int l = 0; l < L; ++l) row[c][l] = c == i ? 1.0 : 0.0;
    for (int k = 0; k < i; ++k)
      for (int c = 0; c <= k; ++c)
        for (int l = 0; l < L; ++l) row[c][l] -= Lf[i][k][l] * W[k][c][l];
    for (int c = 0; c <= i; ++c)
      for (int l = 0; l < L; ++l) W[i][c][l] = row[c][l] * rinv[i][l];
  }
  double out[N][N][L];  // lower triangle: out[i][c] = sum_{k >= i} W[k][i] W[k][c], c <= i
  for (int i = 0; i < N; ++i)
    for (int c = 0; c <= i; ++c)
      for (int l = 0; l < L; ++l) out[i][c][l] = 0.0;
  for (int k = 0; k < N; ++k)
    for (int i = 0; i <= k; ++i)
      for (int c = 0; c <= i; ++c)
        for (int l = 0; l < L; ++l) out[i][c][l] += W[k][i][l] * W[k][c][l];
  for (int l = 0; l < L; ++l) {
    ok[l] = good[l];
    for (int i = 0; i < N; ++i)
      for (int c = 0; c <= i; ++c) inv[l](i, c) = inv[l](c, i) = out[i][c][l];
  }
}

/// store(u, inv, ok) for every block u of A (#blocks N x N, SPD expected):
/// inv = A[u]^-1 where ok. Four blocks per spd_inverse_lanes call, in
/// parallel (store runs inside the parallel loop: it must not throw), the
/// last partial group one by one. The same bits as spd_inverse per block.
/// Returns the number of blocks that were not positive definite (ok false).
template <int N, class Store>
long invert_spd_blocks(const std::vector<Eigen::Matrix<double, N, N>>& A, Store&& store) {
  using Block = Eigen::Matrix<double, N, N>;
  constexpr long kLanes = 4;
  const long n = static_cast<long>(A.size()), groups = n / kLanes;
  long refused = 0;
#pragma omp parallel for schedule(static) reduction(+ : refused)
  for (long g = 0; g < groups; ++g) {
    Block inv[kLanes];
    bool ok[kLanes];
    spd_inverse_lanes<N, kLanes>(A.data() + g * kLanes, inv, ok);
    for (long l = 0; l < kLanes; ++l) {
      store(g * kLanes + l, inv[l], ok[l]);
      refused += !ok[l];
    }
  }
  for (long u = groups * kLanes; u < n; ++u) {
    Block inv;
    const bool ok = spd_inverse<N>(A[u], inv);
    store(u, inv, ok);
    refused += !ok;
  }
  return refused;
}

}  // namespace emu
