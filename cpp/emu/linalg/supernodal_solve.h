#pragma once
// Forward and back substitution with a CHOLMOD supernodal LL' factor for a
// few right-hand sides at once, reading each factor entry once per pass.
//
// Why not cholmod_solve2: with 2-4 right-hand sides CHOLMOD calls dtrsm and
// dgemm per supernode, and OpenBLAS packs (copies) the supernode's panel
// before every such thin product, which on a large ACAP factor costs as much
// as the products themselves (docs/DESIGN.md, "The cost of an iteration").
#include <vector>

#include <cholmod.h>

namespace emu {

/// A supernodal LL' factor's panels (CHOLMOD's layout): supernode s holds
/// columns super[s] .. super[s+1]-1 as a column-major panel of
/// pi[s+1]-pi[s] rows at x + px[s], its row indices at rows + pi[s] (the
/// diagonal block's first). Scalar: double (CHOLMOD's own values) or float
/// (a rounded copy: half the bytes to stream).
template <typename Scalar>
struct SupernodalPanels {
  int n = 0, nsuper = 0;
  const int *super = nullptr, *pi = nullptr, *px = nullptr, *rows = nullptr;
  const Scalar* x = nullptr;
};

/// The same layout with other values x (a rounded copy of p.x).
template <typename To, typename From>
SupernodalPanels<To> with_values(const SupernodalPanels<From>& p, const To* x) {
  SupernodalPanels<To> q;
  q.n = p.n;
  q.nsuper = p.nsuper;
  q.super = p.super;
  q.pi = p.pi;
  q.px = p.px;
  q.rows = p.rows;
  q.x = x;
  return q;
}

/// The panels of a factorised CHOLMOD factor; throws std::logic_error unless
/// it is a real, int-indexed supernodal LL' factor.
SupernodalPanels<double> supernodal_panels(const cholmod_factor& L);

/// The order of a parallel solve: independent subtrees of the supernodal
/// elimination tree (tasks, each a contiguous range of supernodes, as
/// CHOLMOD postorders them) and the supernodes above them (top). A task's
/// forward updates to the top columns go into its own buffer, summed in task
/// order afterwards, so the result does not depend on the thread count.
struct SupernodalSchedule {
  std::vector<int> task_first, task_last;  // task t: supernodes task_first[t] .. task_last[t]
  std::vector<int> top;                    // the other supernodes, ascending
  std::vector<int> top_slot;               // per column: its row in a task's buffer (top columns), else -1
  int top_columns = 0;
  int longest = 0;                         // the longest off-diagonal block (rows)
};

/// A schedule of subtrees of similar work (entries): with k = entries /
/// task_entries between 1 and max_tasks, the largest subtree is split at its
/// root while it holds more than 1/k of the factor; each tree of the forest
/// and each child of a split root left below that is a task (so a small
/// connected factor is one task, the serial order, without buffers; there
/// can be more than max_tasks tasks). Made from the factor alone, never from
/// the thread count. Throws std::logic_error where the supernodes are not in
/// postorder (CHOLMOD postorders them by default).
SupernodalSchedule supernodal_schedule(const SupernodalPanels<double>& L, int max_tasks = 16,
                                       double task_entries = 131072);

/// Which build of the kernel: the best this CPU runs (AVX2 and FMA where
/// present and compiled in), or one of them (tests run both).
enum class SupernodalIsa { best, baseline, avx2 };

/// True where the AVX2 + FMA kernel is compiled in and this CPU runs it.
bool supernodal_solve_has_avx2();

/// Solves L L^T Y = W in place, Lanes right-hand sides side by side.
///   L        the factor's panels
///   W        n by Lanes, row-major: row i holds entry i of every right-hand
///            side in L's permuted order (P b; the caller applies L.Perm)
///   order    supernodal_schedule(L's panels): tasks run in parallel (OpenMP)
///   scratch  resized as needed (per task: its buffers of top columns and the
///            longest off-diagonal block, times Lanes)
/// Lanes is 1, 2 or 4 (pad three right-hand sides with a zero fourth: the
/// lanes of a row are one SIMD-friendly unit). Each entry of L is read once
/// by the forward and once by the backward pass; arithmetic is in double.
/// Throws std::logic_error for isa = avx2 where the CPU or build lacks it.
template <int Lanes, typename Scalar>
void supernodal_solve_in_place(const SupernodalPanels<Scalar>& L, const SupernodalSchedule& order, double* W,
                               std::vector<double>& scratch, SupernodalIsa isa = SupernodalIsa::best);

/// The schedule as plain arrays (the kernels' translation units use no std::vector).
struct ScheduleView {
  int tasks, ntop, top_columns, longest;
  const int *task_first, *task_last, *top, *top_slot;
};

/// The AVX2 + FMA build (supernodal_solve_avx2.cpp; scratch sized by the caller).
template <int Lanes, typename Scalar>
void supernodal_solve_avx2(const SupernodalPanels<Scalar>& L, const ScheduleView& order, double* W, double* scratch);

}  // namespace emu
