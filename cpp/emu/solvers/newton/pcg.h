#pragma once
// Preconditioned conjugate gradients for a Newton step H d = b, truncated the
// Newton-Krylov way: it stops when |r| <= tol and, if model_decrease c > 0,
// the quadratic model has stopped falling fast (Nash and Sofer's truncation
// test, below), after max_iterations, or at the first direction of
// non-positive curvature (p^T H p <= 0: H is indefinite there), keeping the
// iterate so far (the preconditioned right-hand side M^-1 b if that happens
// at once, which is a descent direction for an SPD M). Works on any Eigen
// dense type (vectors, or 9 x #unknowns blocks); inner products are sums over
// all entries.
//
// The model q(d) = 1/2 d^T H d - b^T d falls by 1/2 a_k r_k^T z_k in
// iteration k (p_k^T r_k = z_k^T r_k), so q_k = -1/2 sum_{j<=k} a_j r_j^T z_j
// costs nothing. The truncation test k (q_{k-1} - q_k) <= c |q_k| asks that
// the last iteration add less than c/k of the decrease so far. A residual
// test alone stops after one or two iterations while |g| is large, though
// the model still falls fast along the smooth modes that carry the vertex
// error (docs/DESIGN.md, "Newton-Krylov details").
//
// The vector work of an iteration runs in two parallel passes (the update of
// d and r with |r|^2; r.z and the update of p after the preconditioner), the
// dot products by chunked_sum: the same bits for any number of threads.
#include <cmath>

#include <Eigen/Core>

#include "emu/linalg/chunked_sum.h"

namespace emu {

struct PcgResult {
  int iterations = 0;              // products with H that moved the iterate
  bool negative_curvature = false;
  bool converged = false;          // |r| <= tol reached (and the truncation test, if asked)
  double model = 0.0;              // q(d) = 1/2 d^T H d - b^T d at CG's last iterate (0 after negative curvature at once)
};

template <class Vec>
class Pcg {
 public:
  /// d  the solution (resized, started at zero); product(v, out): out = H v;
  /// precondition(r, out): out = M^-1 r; model_decrease c: 0 for the residual
  /// test alone, else also k (q_{k-1} - q_k) <= c |q_k| (Nash-Sofer: 0.5).
  template <class Product, class Precondition>
  PcgResult solve(Product&& product, Precondition&& precondition, const Vec& b, double tol, int max_iterations,
                  Vec& d, double model_decrease = 0.0) {
    PcgResult res;
    d.setZero(b.rows(), b.cols());
    r_ = b;
    precondition(r_, z_);
    p_ = z_;
    const Eigen::Index n = b.size();
    double rz = inner(r_, z_);
    bool residual_met = false;  // |r| <= tol held at an earlier iterate
    for (int i = 0; i < max_iterations; ++i) {
      product(p_, Hp_);
      const double pHp = inner(p_, Hp_);
      if (!(pHp > 0)) {
        if (i == 0) d = z_;
        // past the residual test (r at round-off, or an indefinite H met while
        // the model test asked for more) the iterate is a converged one
        if (residual_met) res.converged = true;
        else res.negative_curvature = true;
        break;
      }
      const double a = rz / pHp;
      double* dd = d.data();
      double* rr = r_.data();
      const double* pp = p_.data();
      const double* hp = Hp_.data();
      // d += a p, r -= a Hp and |r|^2 in one pass
      const double rr2 = chunked_sum(n, [&](Eigen::Index k) {
        dd[k] += a * pp[k];
        rr[k] -= a * hp[k];
        return rr[k] * rr[k];
      });
      ++res.iterations;
      const double fall = 0.5 * a * rz;  // q_{k-1} - q_k
      res.model -= fall;
      residual_met = std::sqrt(rr2) <= tol;
      if (residual_met && (!(model_decrease > 0) || res.iterations * fall <= -model_decrease * res.model)) {
        res.converged = true;
        break;
      }
      precondition(r_, z_);
      const double rz_new = inner(r_, z_);
      const double beta = rz_new / rz;
      double* pw = p_.data();
      const double* zz = z_.data();
#pragma omp parallel for schedule(static)
      for (Eigen::Index k = 0; k < n; ++k) pw[k] = zz[k] + beta * pw[k];
      rz = rz_new;
    }
    return res;
  }

 private:
  static double inner(const Vec& a, const Vec& b) { return chunked_dot(a, b); }
  Vec r_, z_, p_, Hp_;
};

}  // namespace emu
