#pragma once
// A parallel sum with the same bits for any number of threads: sum_i f(i)
// over [0, n) is taken per fixed chunk (kChunks of them, whatever the thread
// count), then over the chunks in order. For the dot products of CG and the
// coarse corrections.
#include <array>

#include <Eigen/Core>

namespace emu {

constexpr int kSumChunks = 64;

template <class F>
double chunked_sum(Eigen::Index n, F&& f) {
  std::array<double, kSumChunks> part{};
#pragma omp parallel for schedule(static)
  for (int c = 0; c < kSumChunks; ++c) {
    const Eigen::Index lo = n * c / kSumChunks, hi = n * (c + 1) / kSumChunks;
    double s = 0;
    for (Eigen::Index i = lo; i < hi; ++i) s += f(i);
    part[c] = s;
  }
  double s = 0;
  for (double p : part) s += p;
  return s;
}

/// The vector form: out = sum of partial(lo, hi, part) over the same fixed
/// chunks [lo, hi) of [0, n), each writing its chunk's m-vector into part,
/// then summed in chunk order (parts: m x kSumChunks work array, resized).
template <class Partial>
void chunked_sum_into(Eigen::Index n, Eigen::Index m, Partial&& partial, Eigen::MatrixXd& parts,
                      Eigen::VectorXd& out) {
  parts.resize(m, kSumChunks);
#pragma omp parallel for schedule(static)
  for (int c = 0; c < kSumChunks; ++c) {
    auto part = parts.col(c);
    partial(n * c / kSumChunks, n * (c + 1) / kSumChunks, part);
  }
  out = parts.col(0);
  for (int c = 1; c < kSumChunks; ++c) out += parts.col(c);
}

/// sum over all entries of a .* b (any two dense Eigen objects of one size).
template <class A, class B>
double chunked_dot(const A& a, const B& b) {
  const double* x = a.data();
  const double* y = b.data();
  return chunked_sum(a.size(), [&](Eigen::Index k) { return x[k] * y[k]; });
}

}  // namespace emu
