#include "emu/linalg/supernodal_solve.h"

#include <algorithm>
#include <cstddef>
#include <stdexcept>

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

bool supernodal_solve_has_avx2() {
#if defined(EMU_SUPERNODAL_AVX2) && (defined(__x86_64__) || defined(__i386__))
  static const bool has = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return has;
#else
  return false;
#endif
}

template <int Lanes, typename Scalar>
void supernodal_solve_in_place(const SupernodalPanels<Scalar>& L, double* W, std::vector<double>& scratch,
                               SupernodalIsa isa) {
  static_assert(Lanes == 1 || Lanes == 2 || Lanes == 4, "Lanes: 1, 2 or 4");
  int longest = 0;
  for (int s = 0; s < L.nsuper; ++s)
    longest = std::max(longest, (L.pi[s + 1] - L.pi[s]) - (L.super[s + 1] - L.super[s]));
  if (scratch.size() < static_cast<std::size_t>(longest) * Lanes)
    scratch.resize(static_cast<std::size_t>(longest) * Lanes);
  if (isa == SupernodalIsa::best && supernodal_solve_has_avx2()) isa = SupernodalIsa::avx2;
  if (isa == SupernodalIsa::avx2) {
#ifdef EMU_SUPERNODAL_AVX2
    if (!supernodal_solve_has_avx2()) throw std::logic_error("supernodal_solve_in_place: this CPU has no AVX2 and FMA");
    supernodal_solve_avx2<Lanes, Scalar>(L, W, scratch.data());
    return;
#else
    throw std::logic_error("supernodal_solve_in_place: built without the AVX2 kernel");
#endif
  }
  solve_panels<Lanes, Scalar>(L, W, scratch.data());
}

#define EMU_SUPERNODAL_SOLVE(Lanes, Scalar)                                                                    \
  template void supernodal_solve_in_place<Lanes, Scalar>(const SupernodalPanels<Scalar>&, double*, std::vector<double>&, \
                                                         SupernodalIsa);
EMU_SUPERNODAL_SOLVE(1, double)
EMU_SUPERNODAL_SOLVE(2, double)
EMU_SUPERNODAL_SOLVE(4, double)
EMU_SUPERNODAL_SOLVE(1, float)
EMU_SUPERNODAL_SOLVE(2, float)
EMU_SUPERNODAL_SOLVE(4, float)
#undef EMU_SUPERNODAL_SOLVE

}  // namespace emu
