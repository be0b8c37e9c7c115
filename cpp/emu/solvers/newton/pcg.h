#pragma once
// Preconditioned conjugate gradients for a Newton step H d = b, truncated the
// Newton-Krylov way: it stops when |r| <= tol, after max_iterations, or at
// the first direction of non-positive curvature (p^T H p <= 0: H is
// indefinite there), keeping the iterate so far (the preconditioned right-hand
// side M^-1 b if that happens at once, which is a descent direction for an SPD
// M). Works on any Eigen dense type (vectors, or 9 x #unknowns blocks);
// inner products are sums over all entries.
#include <Eigen/Core>

namespace emu {

struct PcgResult {
  int iterations = 0;              // products with H that moved the iterate
  bool negative_curvature = false;
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
      d += a * p_;
      r_ -= a * Hp_;
      ++res.iterations;
      if (r_.norm() <= tol) break;
      precondition(r_, z_);
      const double rz_new = inner(r_, z_);
      p_ = z_ + (rz_new / rz) * p_;
      rz = rz_new;
    }
    return res;
  }

 private:
  static double inner(const Vec& a, const Vec& b) { return a.cwiseProduct(b).sum(); }
  Vec r_, z_, p_, Hp_;
};

}  // namespace emu
