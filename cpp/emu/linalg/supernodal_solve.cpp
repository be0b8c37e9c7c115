#include "emu/linalg/supernodal_solve.h"

#include <algorithm>
#include <cstddef>
#include <queue>
#include <stdexcept>
#include <utility>

#include "emu/linalg/supernodal_kernel.inl"

namespace emu {

SupernodalPanels<double> supernodal_panels(const cholmod_factor& L) {
  if (!L.is_super || !L.is_ll || L.xtype != CHOLMOD_REAL || L.dtype != CHOLMOD_DOUBLE || L.itype != CHOLMOD_INT)
    throw std::logic_error("supernodal_panels: needs a real, int-indexed supernodal LL' factor");
  SupernodalPanels<double> p;
  p.n = static_cast<int>(L.n);
  p.nsuper = static_cast<int>(L.nsuper);
  p.super = static_cast<const int*>(L.super);
  p.pi = static_cast<const int*>(L.pi);
  p.px = static_cast<const int*>(L.px);
  p.rows = static_cast<const int*>(L.s);
  p.x = static_cast<const double*>(L.x);
  return p;
}

SupernodalSchedule supernodal_schedule(const SupernodalPanels<double>& L, int max_tasks, double task_entries) {
  SupernodalSchedule o;
  const int ns = L.nsuper;
  o.top_slot.assign(L.n, -1);
  if (ns == 0) return o;
  std::vector<int> col_super(L.n), parent(ns, -1), first(ns), size(ns, 1);
  std::vector<double> work(ns);  // entries of the subtree below and at s
  for (int s = 0; s < ns; ++s)
    for (int c = L.super[s]; c < L.super[s + 1]; ++c) col_super[c] = s;
  bool postordered = true;
  for (int s = 0; s < ns; ++s) {
    const int nscol = L.super[s + 1] - L.super[s], nsrow = L.pi[s + 1] - L.pi[s];
    work[s] = double(nscol) * nsrow;
    o.longest = std::max(o.longest, nsrow - nscol);
    if (nsrow > nscol) parent[s] = col_super[L.rows[L.pi[s] + nscol]];  // the first row below the diagonal block
    postordered = postordered && parent[s] != s && (parent[s] < 0 || parent[s] > s);
    first[s] = s;
  }
  std::vector<std::vector<int>> children(ns);
  for (int s = 0; s < ns && postordered; ++s) {
    const int p = parent[s];
    if (p < 0) continue;
    work[p] += work[s];
    first[p] = std::min(first[p], first[s]);
    size[p] += size[s];
    children[p].push_back(s);
  }
  for (int s = 0; s < ns && postordered; ++s) postordered = size[s] == s - first[s] + 1;  // subtree = first .. s
  if (!postordered)
    throw std::logic_error("supernodal_schedule: the supernodes are not in postorder (CHOLMOD's default)");
  // split the largest subtree at its root while it holds more than 1/tasks of all entries
  double total = 0.0;
  std::priority_queue<std::pair<double, int>> open;  // (subtree entries, root)
  for (int s = 0; s < ns; ++s)
    if (parent[s] < 0) {
      open.push({work[s], s});
      total += work[s];
    }
  const int tasks = std::max(1, std::min(max_tasks, static_cast<int>(total / task_entries)));
  std::vector<int> roots;
  while (!open.empty()) {
    const auto [w, s] = open.top();
    open.pop();
    if (w > total / tasks && !children[s].empty()) {
      o.top.push_back(s);
      for (int c : children[s]) open.push({work[c], c});
    } else {
      roots.push_back(s);
    }
  }
  std::sort(roots.begin(), roots.end());
  std::sort(o.top.begin(), o.top.end());
  for (int r : roots) {
    o.task_first.push_back(first[r]);
    o.task_last.push_back(r);
  }
  for (int s : o.top)
    for (int c = L.super[s]; c < L.super[s + 1]; ++c) o.top_slot[c] = o.top_columns++;
  return o;
}

bool supernodal_solve_has_avx2() {
#if defined(EMU_SUPERNODAL_AVX2) && (defined(__x86_64__) || defined(__i386__))
  static const bool has = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return has;
#else
  return false;
#endif
}

template <int Lanes, typename Scalar>
void supernodal_solve_in_place(const SupernodalPanels<Scalar>& L, const SupernodalSchedule& order, double* W,
                               std::vector<double>& scratch, SupernodalIsa isa) {
  static_assert(Lanes == 1 || Lanes == 2 || Lanes == 4, "Lanes: 1, 2 or 4");
  if (L.nsuper == 0) return;
  const ScheduleView view{static_cast<int>(order.task_first.size()), static_cast<int>(order.top.size()),
                          order.top_columns,         order.longest,
                          order.task_first.data(),   order.task_last.data(),
                          order.top.data(),          order.top_slot.data()};
  if (view.tasks < 1 || static_cast<int>(order.top_slot.size()) != L.n)
    throw std::logic_error("supernodal_solve_in_place: a schedule of another factor");
  const std::size_t need = static_cast<std::size_t>(view.tasks) * (view.top_columns + view.longest) * Lanes;
  if (scratch.size() < need) scratch.resize(need);
  if (isa == SupernodalIsa::best && supernodal_solve_has_avx2()) isa = SupernodalIsa::avx2;
  if (isa == SupernodalIsa::avx2) {
#ifdef EMU_SUPERNODAL_AVX2
    if (!supernodal_solve_has_avx2()) throw std::logic_error("supernodal_solve_in_place: this CPU has no AVX2 and FMA");
    supernodal_solve_avx2<Lanes, Scalar>(L, view, W, scratch.data());
    return;
#else
    throw std::logic_error("supernodal_solve_in_place: built without the AVX2 kernel");
#endif
  }
  solve_panels<Lanes, Scalar>(L, view, W, scratch.data());
}

#define EMU_SUPERNODAL_SOLVE(Lanes, Scalar)                                                                    \
  template void supernodal_solve_in_place<Lanes, Scalar>(const SupernodalPanels<Scalar>&, const SupernodalSchedule&, \
                                                         double*, std::vector<double>&, SupernodalIsa);
EMU_SUPERNODAL_SOLVE(1, double)
EMU_SUPERNODAL_SOLVE(2, double)
EMU_SUPERNODAL_SOLVE(4, double)
EMU_SUPERNODAL_SOLVE(1, float)
EMU_SUPERNODAL_SOLVE(2, float)
EMU_SUPERNODAL_SOLVE(4, float)
#undef EMU_SUPERNODAL_SOLVE

}  // namespace emu
