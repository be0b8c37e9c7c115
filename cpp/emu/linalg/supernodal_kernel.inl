// The supernodal forward and back substitution kernels (supernodal_solve.h),
// included by two translation units: supernodal_solve.cpp (the baseline ISA)
// and supernodal_solve_avx2.cpp (-mavx2 -mfma, chosen at run time). Everything
// here has internal linkage and calls only baseline code (OpenMP's runtime,
// memset), so no function compiled for AVX2 can be picked by the linker for
// the baseline path.
#include <cstddef>

#include "emu/linalg/supernodal_solve.h"

namespace emu {
namespace {

// One supernode s of L: columns k1 .. k1 + nscol - 1, stored column-major as
// an nsrow by nscol panel (leading dimension nsrow) whose first nscol rows are
// the lower-triangular diagonal block L11 and the other nrect = nsrow - nscol
// rows the off-diagonal block L21, on the rows rows[nscol .. nsrow - 1].
template <typename Scalar>
struct Supernode {
  const Scalar* panel;
  const int* rows;
  int nsrow, nscol;
  std::size_t k1;
};

// The lanes of one row of W (entry k of every right-hand side): one GCC
// vector (one AVX register for 4 lanes, two SSE2 ones without AVX), so that
// each panel entry scales a whole row at once. aligned(8), may_alias: a row
// is read and written in place in W's doubles.
template <int Lanes>
struct LaneOf;
template <>
struct LaneOf<1> {
  using type = double;
};
template <>
struct LaneOf<2> {
  typedef double type __attribute__((vector_size(16), aligned(8), may_alias));
};
template <>
struct LaneOf<4> {
  typedef double type __attribute__((vector_size(32), aligned(8), may_alias));
};
template <int Lanes>
using Lane = typename LaneOf<Lanes>::type;
template <int Lanes>
inline Lane<Lanes>& lane(double* W, std::size_t k) {
  return *reinterpret_cast<Lane<Lanes>*>(W + k * Lanes);
}

// The two sweeps every pass is made of, over `count` rows of four panel
// columns (c, c + ld, c + 2 ld, c + 3 ld, from one row on): each panel entry
// is read once and each row of lanes loaded and stored once per four columns.
// dst_k -= sum_m c_m[k] y_m   (y: four rows of lanes, loaded before the sweep)
template <int Lanes, typename Scalar>
inline void subtract_columns4(const Scalar* c, std::size_t ld, double* y, int count, double* dst) {
  using Row = Lane<Lanes>;
  const Scalar* __restrict c0 = c;
  const Scalar* __restrict c1 = c0 + ld;
  const Scalar* __restrict c2 = c1 + ld;
  const Scalar* __restrict c3 = c2 + ld;
  const Row y0 = lane<Lanes>(y, 0), y1 = lane<Lanes>(y, 1), y2 = lane<Lanes>(y, 2), y3 = lane<Lanes>(y, 3);
  for (int k = 0; k < count; ++k)
    lane<Lanes>(dst, k) -= double(c0[k]) * y0 + double(c1[k]) * y1 + double(c2[k]) * y2 + double(c3[k]) * y3;
}
// out_m -= sum_k c_m[k] x_k   (x: count rows of lanes; out: four rows of lanes)
template <int Lanes, typename Scalar>
inline void subtract_dots4(const Scalar* c, std::size_t ld, double* x, int count, double* out) {
  using Row = Lane<Lanes>;
  const Scalar* __restrict c0 = c;
  const Scalar* __restrict c1 = c0 + ld;
  const Scalar* __restrict c2 = c1 + ld;
  const Scalar* __restrict c3 = c2 + ld;
  Row s0 = Row{}, s1 = Row{}, s2 = Row{}, s3 = Row{};
  for (int k = 0; k < count; ++k) {
    const Row xk = lane<Lanes>(x, k);
    s0 += double(c0[k]) * xk;
    s1 += double(c1[k]) * xk;
    s2 += double(c2[k]) * xk;
    s3 += double(c3[k]) * xk;
  }
  lane<Lanes>(out, 0) -= s0;
  lane<Lanes>(out, 1) -= s1;
  lane<Lanes>(out, 2) -= s2;
  lane<Lanes>(out, 3) -= s3;
}

// Forward: y = L11^-1 w_s, then w_rows -= L21 y. -L21 y is summed four
// columns at a time into a local buffer (acc), so each panel entry is read
// once and a row of W is updated once per supernode. Rows from `limit` on
// (the top columns, outside a task's subtree) are updated in the task's
// buffer outside[top_slot[row]] instead of W.
template <int Lanes, typename Scalar>
void forward(const Supernode<Scalar>& s, double* W, double* acc, int limit, double* outside, const int* top_slot) {
  using Row = Lane<Lanes>;
  double* Wd = W + s.k1 * Lanes;
  auto column = [&s](int j) { return s.panel + static_cast<std::size_t>(j) * s.nsrow; };
  // one column of L11 y = w: y_j, then the rows below it up to `end`
  auto solve_column = [&](int j, int end) {
    const Scalar* __restrict c = column(j);
    const Row y = lane<Lanes>(Wd, j) / double(c[j]);
    lane<Lanes>(Wd, j) = y;
    for (int i = j + 1; i < end; ++i) lane<Lanes>(Wd, i) -= double(c[i]) * y;
  };
  // L11 y = w, four columns at a time: their 4x4 triangle, then the rows
  // below it within the block
  int j = 0;
  for (; j + 4 <= s.nscol; j += 4) {
    for (int jj = j; jj < j + 4; ++jj) solve_column(jj, j + 4);
    subtract_columns4<Lanes>(column(j) + j + 4, s.nsrow, Wd + j * Lanes, s.nscol - j - 4, Wd + (j + 4) * Lanes);
  }
  for (; j < s.nscol; ++j) solve_column(j, s.nscol);
  const int nrect = s.nsrow - s.nscol;
  if (nrect == 0) return;
  for (std::size_t k = 0; k < static_cast<std::size_t>(nrect) * Lanes; ++k) acc[k] = 0.0;
  for (j = 0; j + 4 <= s.nscol; j += 4)
    subtract_columns4<Lanes>(column(j) + s.nscol, s.nsrow, Wd + j * Lanes, nrect, acc);
  for (; j < s.nscol; ++j) {
    const Scalar* __restrict c = column(j) + s.nscol;
    const Row y = lane<Lanes>(Wd, j);
    for (int i = 0; i < nrect; ++i) lane<Lanes>(acc, i) -= double(c[i]) * y;
  }
  for (int i = 0; i < nrect; ++i) {
    const int row = s.rows[s.nscol + i];
    if (row < limit) lane<Lanes>(W, row) += lane<Lanes>(acc, i);
    else lane<Lanes>(outside, top_slot[row]) += lane<Lanes>(acc, i);
  }
}

// Backward: w_s -= L21^T x_rows (the rows gathered into xr once, four
// columns' dot products per sweep over them), then x_s = L11^-T w_s.
template <int Lanes, typename Scalar>
void backward(const Supernode<Scalar>& s, double* W, double* xr) {
  using Row = Lane<Lanes>;
  double* Wd = W + s.k1 * Lanes;
  auto column = [&s](int j) { return s.panel + static_cast<std::size_t>(j) * s.nsrow; };
  const int nrect = s.nsrow - s.nscol;
  for (int i = 0; i < nrect; ++i) lane<Lanes>(xr, i) = lane<Lanes>(W, s.rows[s.nscol + i]);
  int j = 0;
  for (; j + 4 <= s.nscol && nrect > 0; j += 4)
    subtract_dots4<Lanes>(column(j) + s.nscol, s.nsrow, xr, nrect, Wd + j * Lanes);
  for (; j < s.nscol && nrect > 0; ++j) {
    const Scalar* __restrict c = column(j) + s.nscol;
    Row sj = Row{};
    for (int i = 0; i < nrect; ++i) sj += double(c[i]) * lane<Lanes>(xr, i);
    lane<Lanes>(Wd, j) -= sj;
  }
  // L11^T x = w, four columns at a time from the last: the single columns
  // past the last multiple of four, then per block the dot products of its
  // columns with the rows solved below it, then its 4x4 triangle
  auto solve_column = [&](int jj, int end) {
    const Scalar* __restrict c = column(jj);
    Row x = lane<Lanes>(Wd, jj);
    for (int i = jj + 1; i < end; ++i) x -= double(c[i]) * lane<Lanes>(Wd, i);
    lane<Lanes>(Wd, jj) = x / double(c[jj]);
  };
  const int whole = s.nscol - s.nscol % 4;
  for (int jj = s.nscol - 1; jj >= whole; --jj) solve_column(jj, s.nscol);
  for (int jb = whole - 4; jb >= 0; jb -= 4) {
    subtract_dots4<Lanes>(column(jb) + jb + 4, s.nsrow, Wd + (jb + 4) * Lanes, s.nscol - jb - 4, Wd + jb * Lanes);
    for (int jj = jb + 3; jj >= jb; --jj) solve_column(jj, jb + 4);
  }
}

// L L^T Y = W in place in the order of a schedule: forward, the tasks in
// parallel (each with its slice of scratch: a buffer for the top columns,
// then room for the longest off-diagonal block), their buffers summed into W
// in task order, then the top supernodes; backward, the top supernodes, then
// the tasks in parallel. The same bits for any thread count.
template <int Lanes, typename Scalar>
void solve_panels(const SupernodalPanels<Scalar>& L, const ScheduleView& o, double* W, double* scratch) {
  const std::size_t slice = static_cast<std::size_t>(o.top_columns + o.longest) * Lanes;
  const std::size_t buffer = static_cast<std::size_t>(o.top_columns) * Lanes;
  auto node = [&L](int s) {
    return Supernode<Scalar>{L.x + L.px[s], L.rows + L.pi[s], L.pi[s + 1] - L.pi[s], L.super[s + 1] - L.super[s],
                             static_cast<std::size_t>(L.super[s])};
  };
#pragma omp parallel for schedule(dynamic, 1) if (o.tasks > 1)
  for (int t = 0; t < o.tasks; ++t) {
    double* outside = scratch + t * slice;
    for (std::size_t k = 0; k < buffer; ++k) outside[k] = 0.0;
    const int limit = L.super[o.task_last[t] + 1];
    for (int s = o.task_first[t]; s <= o.task_last[t]; ++s)
      forward<Lanes>(node(s), W, outside + buffer, limit, outside, o.top_slot);
  }
  for (int t = 0; t < o.tasks; ++t) {
    double* outside = scratch + t * slice;
    for (int q = 0; q < o.ntop; ++q)
      for (int c = L.super[o.top[q]]; c < L.super[o.top[q] + 1]; ++c)
        lane<Lanes>(W, c) += lane<Lanes>(outside, o.top_slot[c]);
  }
  double* acc = scratch + buffer;  // task 0's block room, free again
  for (int q = 0; q < o.ntop; ++q) forward<Lanes>(node(o.top[q]), W, acc, L.n, nullptr, o.top_slot);
  for (int q = o.ntop - 1; q >= 0; --q) backward<Lanes>(node(o.top[q]), W, acc);
#pragma omp parallel for schedule(dynamic, 1) if (o.tasks > 1)
  for (int t = 0; t < o.tasks; ++t) {
    double* xr = scratch + t * slice + buffer;
    for (int s = o.task_last[t]; s >= o.task_first[t]; --s) backward<Lanes>(node(s), W, xr);
  }
}

}  // namespace
}  // namespace emu
