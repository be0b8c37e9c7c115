#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include "bind.h"
#include "emu/mesh/tet_geometry.h"

namespace py = pybind11;

namespace emu::bindings {
void bind_mesh(py::module_& m) {
  m.def("signed_volumes", &signed_volumes, py::arg("X"), py::arg("T"),
        "X  #V by 3 positions; T  #T by 4 indices -> #T signed volumes");
  m.def(
      "shape_gradients",
      [](const Eigen::MatrixX3d& X, const Eigen::MatrixX4i& T) {
        const TetGeometry g = tet_geometry(X, T);
        Eigen::MatrixXd out(T.rows(), 12);
        for (Eigen::Index t = 0; t < T.rows(); ++t)
          out.row(t) = Eigen::Map<const Eigen::Matrix<double, 1, 12>>(Eigen::Matrix<double, 4, 3, Eigen::RowMajor>(g.grad[t]).data());
        return py::make_tuple(g.volume, out);
      },
      py::arg("X"), py::arg("T"), "(volumes #T, gradients #T by 12: row t = b_0, b_1, b_2, b_3)");
}
}  // namespace emu::bindings
