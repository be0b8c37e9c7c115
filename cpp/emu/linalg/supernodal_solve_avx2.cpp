// The supernodal kernels compiled for AVX2 and FMA (CMake adds -mavx2 -mfma
// to this file only); supernodal_solve_in_place calls them where the CPU has
// both (supernodal_solve_has_avx2).
#include "emu/linalg/supernodal_kernel.inl"

namespace emu {

template <int Lanes, typename Scalar>
void supernodal_solve_avx2(const SupernodalPanels<Scalar>& L, double* W, double* scratch) {
  solve_panels<Lanes, Scalar>(L, W, scratch);
}

template void supernodal_solve_avx2<1, double>(const SupernodalPanels<double>&, double*, double*);
template void supernodal_solve_avx2<2, double>(const SupernodalPanels<double>&, double*, double*);
template void supernodal_solve_avx2<4, double>(const SupernodalPanels<double>&, double*, double*);
template void supernodal_solve_avx2<1, float>(const SupernodalPanels<float>&, double*, double*);
template void supernodal_solve_avx2<2, float>(const SupernodalPanels<float>&, double*, double*);
template void supernodal_solve_avx2<4, float>(const SupernodalPanels<float>&, double*, double*);

}  // namespace emu
