#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include <stdexcept>

#include "bind.h"
#include "emu/linalg/blas_info.h"
#include "emu/linalg/rotation.h"

namespace py = pybind11;

namespace emu::bindings {
void bind_linalg(py::module_& m) {
  m.def("blas_info", [] {
    const BlasInfo b = blas_info();
    py::dict d;
    d["library"] = b.library;
    d["config"] = b.config;
    d["kernel"] = b.kernel;
    d["blas_threads"] = b.blas_threads;
    d["omp_threads"] = b.omp_threads;
    return d;
  });
  m.def(
      "best_rotation",
      [](const Eigen::MatrixX3d& X, const Eigen::MatrixX3d& Y) {
        if (X.rows() != Y.rows() || X.rows() == 0)
          throw std::invalid_argument("best_rotation needs two (n, 3) point arrays of the same n > 0");
        return Eigen::Matrix3d(best_rotation(X, Y));
      },
      py::arg("X"), py::arg("Y"),
      "The rotation R minimising sum |R (X_i - Xc) - (Y_i - Yc)|^2 (Kabsch) for (n, 3) point sets X, Y; "
      "the same fit FEM uses to start its rigid bones");
  m.def("set_threads", &set_threads, py::arg("n"), "set OpenMP and OpenBLAS thread counts (n > 0)");
}
}  // namespace emu::bindings
