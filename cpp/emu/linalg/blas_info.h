#pragma once
// Which BLAS the process runs on and how many threads it and OpenMP use, so
// every timing can say what it ran on.
#include <string>

namespace emu {

struct BlasInfo {
  std::string library;  // shared object that provides dgemm_
  std::string config;   // openblas_get_config() where available
  int blas_threads;     // -1 when the BLAS does not say
  int omp_threads;
};

BlasInfo blas_info();

/// Set the OpenMP thread count and, for OpenBLAS, its thread count too.
/// n <= 0 leaves both unchanged.
void set_threads(int n);

}  // namespace emu
