#include <pybind11/stl.h>

#include "bind.h"
#include "emu/linalg/blas_info.h"

namespace py = pybind11;

namespace emu::bindings {
void bind_linalg(py::module_& m) {
  m.def("blas_info", [] {
    const BlasInfo b = blas_info();
    py::dict d;
    d["library"] = b.library;
    d["config"] = b.config;
    d["blas_threads"] = b.blas_threads;
    d["omp_threads"] = b.omp_threads;
    return d;
  });
  m.def("set_threads", &set_threads, py::arg("n"), "set OpenMP and OpenBLAS thread counts (n > 0)");
}
}  // namespace emu::bindings
