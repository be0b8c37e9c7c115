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
// d and r with |r|^2, and r.z after the preconditioner), with dot products
// summed per fixed chunk and then in chunk order: the same bits for any
// number of threads.
#include <algorithm>
#include <array>
#include <cmath>

#include <Eigen/Core>

namespace emu {

struct PcgResult {
  int iterations = 0;              // products with H that moved the iterate
  bool negative_curvature = false;
};

namespace pcg_detail {
constexpr int kChunks = 64;

/// sum_i f(i) over [0, n), summed per fixed chunk, then in chunk order.
template <class F>
double chunked_sum(Eigen::Index n, F&& f) {
  std::array<double, kChunks> part{};
#pragma omp parallel for schedule(static)
  for (int c = 0; c < kChunks; ++c) {
    const Eigen::Index lo = n * c / kChunks, hi = n * (c + 1) / kChunks;
    double s = 0;
    for (Eigen::Index i = lo; i < hi; ++i) s += f(i);
    part[c] = s;
  }
  double s = 0;
  for (double p : part) s += p;
  return s;
}
}  // namespace pcg_detail

template <class Vec>
class Pcg {
 public:
  /// d  the solution (resized, started at zero); product(v, out): out = H v;
  /// precondition(r, out): out = M^-1 r.
  template <class Product, class Precondition>
  PcgResult solve(Product&& product, Precondition&& precondition, const Vec& b, double tol, int max_iterations,
                  Vec& d) {
    using pcg_detail::chunked_sum;
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
      if (std::sqrt(rr2) <= tol) break;
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
  static double inner(const Vec& a, const Vec& b) {
    const double* x = a.data();
    const double* y = b.data();
    return pcg_detail::chunked_sum(a.size(), [&](Eigen::Index k) { return x[k] * y[k]; });
  }
  Vec r_, z_, p_, Hp_;
};

}  // namespace emu
