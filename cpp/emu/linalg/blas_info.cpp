#include "emu/linalg/blas_info.h"

#include <dlfcn.h>
#include <omp.h>

extern "C" void dgemm_(const char*, const char*, const int*, const int*, const int*, const double*,
                       const double*, const int*, const double*, const int*, const double*, double*,
                       const int*);

namespace emu {
namespace {
void* blas_handle() {
  Dl_info info;
  if (!dladdr(reinterpret_cast<void*>(&dgemm_), &info) || !info.dli_fname) return nullptr;
  return dlopen(info.dli_fname, RTLD_LAZY | RTLD_NOLOAD);
}
}  // namespace

BlasInfo blas_info() {
  BlasInfo r;
  Dl_info info;
  r.library = (dladdr(reinterpret_cast<void*>(&dgemm_), &info) && info.dli_fname) ? info.dli_fname : "unknown";
  r.blas_threads = -1;
  r.omp_threads = omp_get_max_threads();
  if (void* h = blas_handle()) {
    using config_fn = char* (*)();
    using threads_fn = int (*)();
    if (auto f = reinterpret_cast<config_fn>(dlsym(h, "openblas_get_config"))) r.config = f();
    if (auto f = reinterpret_cast<threads_fn>(dlsym(h, "openblas_get_num_threads"))) r.blas_threads = f();
    dlclose(h);
  }
  if (r.config.empty()) r.config = "not OpenBLAS (reference or other BLAS)";
  return r;
}

void set_threads(int n) {
  if (n <= 0) return;
  omp_set_num_threads(n);
  if (void* h = blas_handle()) {
    using set_fn = void (*)(int);
    if (auto f = reinterpret_cast<set_fn>(dlsym(h, "openblas_set_num_threads"))) f(n);
    dlclose(h);
  }
}

}  // namespace emu
