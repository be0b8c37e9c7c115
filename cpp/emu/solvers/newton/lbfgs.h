#pragma once
// Limited-memory BFGS (Nocedal and Wright, Algorithm 7.4): the two-loop
// recursion applies the inverse-Hessian approximation built from the last m
// steps s_k and gradient changes y_k on top of an initial inverse H0 (for
// EMU: the Woodbury preconditioner, which may change between steps). A pair
// with s.y <= 1e-12 |s| |y| (no positive curvature along the step) is not
// kept, so the approximation stays positive definite when H0 is.
// Works on any Eigen dense type; inner products are chunk-ordered sums (the
// same bits for any thread count).
#include <deque>

#include <Eigen/Core>

#include "emu/linalg/chunked_sum.h"

namespace emu {

template <class Vec>
class LbfgsMemory {
 public:
  explicit LbfgsMemory(int m) : m_(m) {}

  /// Keeps the pair (s, y) if it has positive curvature; drops the oldest beyond m.
  void push(Vec s, Vec y) {
    const double sy = chunked_dot(s, y);
    if (!(sy > 1e-12 * s.norm() * y.norm())) return;
    pairs_.push_back({std::move(s), std::move(y), 1.0 / sy});
    if (static_cast<int>(pairs_.size()) > m_) pairs_.pop_front();
  }
  void clear() { pairs_.clear(); }
  int size() const { return static_cast<int>(pairs_.size()); }

  /// out = H_k g, with h0(in, out): out = H0 in.
  template <class InitialInverse>
  void apply(const Vec& g, InitialInverse&& h0, Vec& out) const {
    const int n = size();
    std::vector<double> a(n);
    Vec q = g;
    for (int i = n - 1; i >= 0; --i) {  // newest first
      a[i] = pairs_[i].rho * chunked_dot(pairs_[i].s, q);
      q -= a[i] * pairs_[i].y;
    }
    h0(q, out);
    for (int i = 0; i < n; ++i) {  // oldest first
      const double b = pairs_[i].rho * chunked_dot(pairs_[i].y, out);
      out += (a[i] - b) * pairs_[i].s;
    }
  }

 private:
  struct Pair {
    Vec s, y;
    double rho;  // 1 / s.y
  };
  int m_;
  std::deque<Pair> pairs_;
};

}  // namespace emu
