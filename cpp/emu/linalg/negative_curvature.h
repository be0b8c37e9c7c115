#pragma once
// The direction of most negative curvature of an indefinite Hessian H,
// measured against the PSD matrix M it was filtered to (M = H + N, N PSD: the
// curvature the eigenvalue filter added back).
//
// v^T H v = v^T M v - v^T N v = (1 - mu) v^T M v, so the most negative
// curvature relative to M is the largest mu of the generalised problem
// N v = mu M v, found by power iteration on M^-1 N (self-adjoint in the M
// inner product, its eigenvalues mu >= 0): one product with N and one solve
// with M's factor per iteration. H is indefinite along v when mu > 1.
#include <cmath>
#include <cstdint>

#include <Eigen/Core>

namespace emu {

struct CurvatureDirection {
  Eigen::VectorXd v;  // unit (Euclidean) direction
  double mu = 0;      // N-over-M Rayleigh quotient of v: v^T H v = (1 - mu) v^T M v
  int iterations = 0;
};

/// A deterministic start for the power iteration (an LCG in [-1/2, 1/2)): the
/// same vector every run, so a solve repeats bit for bit.
inline Eigen::VectorXd pseudo_random_vector(Eigen::Index n) {
  Eigen::VectorXd v(n);
  std::uint64_t state = 0x9E3779B97F4A7C15ull;
  for (Eigen::Index i = 0; i < n; ++i) {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    v(i) = double(state >> 11) * 0x1.0p-53 - 0.5;
  }
  return v;
}

/// apply_n(x, y): y = N x;  apply_m(x, y): y = M x;  solve_m(r, z): z = M^-1 r.
/// Stops after max_iterations or once mu changes by less than rtol of itself.
template <class ApplyN, class ApplyM, class SolveM>
CurvatureDirection most_negative_curvature(Eigen::Index n, ApplyN&& apply_n, ApplyM&& apply_m, SolveM&& solve_m,
                                           int max_iterations, double rtol) {
  CurvatureDirection out;
  Eigen::VectorXd v = pseudo_random_vector(n), Nv(n), Mv(n), w(n);
  v.normalize();
  double mu_prev = -1.0;
  for (int it = 1; it <= max_iterations; ++it) {
    apply_n(v, Nv);
    apply_m(v, Mv);
    const double vMv = v.dot(Mv);
    out.mu = vMv > 0 ? v.dot(Nv) / vMv : 0.0;
    out.iterations = it;
    if (!(std::isfinite(out.mu)) || std::abs(out.mu - mu_prev) <= rtol * std::abs(out.mu)) break;
    mu_prev = out.mu;
    solve_m(Nv, w);
    const double norm = w.norm();
    if (!(norm > 0) || !std::isfinite(norm)) break;  // N v = 0: no curvature was filtered along v
    v = w / norm;
  }
  out.v = v;
  return out;
}

}  // namespace emu
