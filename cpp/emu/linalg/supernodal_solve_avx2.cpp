// The supernodal kernels compiled for AVX2 and FMA (CMake adds -mavx2 -mfma
// to this file only); supernodal_solve_in_place calls them where the CPU has
// both (supernodal_solve_has_avx2).
#include "emu/linalg/supernodal_kernel.inl"

namespace emu {

template <int Lanes, typename Scalar>
void supernodal_solve_avx2(const SupernodalPanels<Scalar>& L, const ScheduleView& order, double* W, double* scratch) {
  solve_panels<Lanes, Scalar>(L, order, W, scratch);
}

template void supernodal_solve_avx2<1, double>(const SupernodalPanels<double>&, const ScheduleView&, double*, double*);
template void supernodal_solve_avx2<2, double>(const SupernodalPanels<double>&, const ScheduleView&, double*, double*);
template void supernodal_solve_avx2<4, double>(const SupernodalPanels<double>&, const ScheduleView&, double*, double*);
template void supernodal_solve_avx2<1, float>(const SupernodalPanels<float>&, const ScheduleView&, double*, double*);
template void supernodal_solve_avx2<2, float>(const SupernodalPanels<float>&, const ScheduleView&, double*, double*);
template void supernodal_solve_avx2<4, float>(const SupernodalPanels<float>&, const ScheduleView&, double*, double*);

}  // namespace emu
