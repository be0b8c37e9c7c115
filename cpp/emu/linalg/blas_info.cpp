#include "emu/linalg/blas_info.h"

#include <atomic>

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
  r.blas_threads = blas_threads();
  r.omp_threads = omp_get_max_threads();
  if (void* h = blas_handle()) {
    using config_fn = char* (*)();
    if (auto f = reinterpret_cast<config_fn>(dlsym(h, "openblas_get_config"))) r.config = f();
    if (auto f = reinterpret_cast<config_fn>(dlsym(h, "openblas_get_corename"))) r.kernel = f();
    dlclose(h);
  }
  if (r.config.empty()) r.config = "not OpenBLAS (reference or other BLAS)";
  return r;
}

namespace {
// OpenBLAS's thread getter and setter, looked up once (null for another BLAS).
struct OpenBlasThreads {
  int (*get)() = nullptr;
  void (*set)(int) = nullptr;
  OpenBlasThreads() {
    if (void* h = blas_handle()) {
      get = reinterpret_cast<int (*)()>(dlsym(h, "openblas_get_num_threads"));
      set = reinterpret_cast<void (*)(int)>(dlsym(h, "openblas_set_num_threads"));
      dlclose(h);  // RTLD_NOLOAD: the library stays loaded (dgemm_ comes from it)
    }
  }
};
const OpenBlasThreads& openblas_threads() {
  static const OpenBlasThreads f;
  return f;
}

// The count last asked for by set_blas_threads (0: never), which a
// BlasThreadsScope restores.
std::atomic<int> requested_blas_threads{0};

void set_openblas(int n) {
  const auto& f = openblas_threads();
  if (n > 0 && f.set) f.set(n);
}
}  // namespace

int blas_threads() {
  const auto& f = openblas_threads();
  return f.get ? f.get() : -1;
}

void set_blas_threads(int n) {
  if (n <= 0) return;
  requested_blas_threads.store(n);
  set_openblas(n);
}

void set_threads(int n) {
  if (n <= 0) return;
  omp_set_num_threads(n);
  set_blas_threads(n);
}

BlasThreadsScope::BlasThreadsScope(int n) {
  if (n <= 0) return;
  const int now = blas_threads();
  if (now <= 0 || now == n) return;
  saved_ = now;
  set_openblas(n);
}

BlasThreadsScope::~BlasThreadsScope() {
  if (saved_ <= 0) return;
  const int asked = requested_blas_threads.load();
  set_openblas(asked > 0 ? asked : saved_);
}

}  // namespace emu
