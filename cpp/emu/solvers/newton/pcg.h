#pragma once
// Preconditioned conjugate gradients for a Newton step H d = b, truncated the
// Newton-Krylov way: it stops when |r| <= tol, after max_iterations, or at
// the first direction of non-positive curvature (p^T H p <= 0: H is
// indefinite there), keeping the iterate so far (the preconditioned right-hand
// side M^-1 b if that happens at once, which is a descent direction for an SPD
// M). Works on any Eigen dense type (vectors, or 9 x #unknowns blocks);
// inner products are sums over all entries.
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
  bool converged = false;          // |r| <= tol reached
};

template <class Vec>
class Pcg {
 public:
  /// d  the solution (resized, started at zero); product(v, out): out = H v;
  /// precondition(r, out): out = M^-1 r.
  template <class Product, class Precondition>
  PcgResult solve(Product&& product, Precondition&& precondition, const Vec& b, double tol, int max_iterations,
                  Vec& d) {
    PcgResult res;
    d.setZero(b.rows(), b.cols());
    r_ = b;
    precondition(r_, z_);
    p_ = z_;
    const Eigen::Index n = b.size();
    double rz = inner(r_, z_);
    for (int i = 0; i < max_iterations; ++i) {
      product(p_, Hp_);
      const double pHp = inner(p_, Hp_);
      if (!(pHp > 0)) {
        if (i == 0) d = z_;
        res.negative_curvature = true;
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
      if (std::sqrt(rr2) <= tol) {
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
