#pragma once
// Which BLAS the process runs on and how many threads it and OpenMP use, so
// every timing can say what it ran on.
#include <string>

namespace emu {

struct BlasInfo {
  std::string library;  // shared object that provides dgemm_
  std::string config;   // openblas_get_config() where available
  std::string kernel;   // openblas_get_corename(): the kernel OpenBLAS runs ("" for another BLAS)
  int blas_threads;     // -1 when the BLAS does not say
  int omp_threads;
};

BlasInfo blas_info();

/// Set the OpenMP thread count and, for OpenBLAS, its thread count too.
/// n <= 0 leaves both unchanged.
void set_threads(int n);

/// OpenBLAS's thread count (-1 for another BLAS) and a setter (a no-op for
/// another BLAS or n <= 0). The count is process-wide; the setter (and
/// set_threads) also records n as the count asked for.
int blas_threads();
void set_blas_threads(int n);

/// While alive, OpenBLAS runs on n threads (n <= 0: unchanged). After, the
/// count last asked for through set_threads / set_blas_threads is restored
/// (the count found on entry if none was), so a set_threads from another
/// thread meanwhile is not undone. For BLAS work too small to gain from
/// threads, where OpenBLAS's worker would only contend with the OpenMP team
/// (DESIGN.md, "OpenBLAS's threads on small factors").
class BlasThreadsScope {
 public:
  explicit BlasThreadsScope(int n);
  ~BlasThreadsScope();
  BlasThreadsScope(const BlasThreadsScope&) = delete;
  BlasThreadsScope& operator=(const BlasThreadsScope&) = delete;

 private:
  int saved_ = -1;
};

}  // namespace emu
