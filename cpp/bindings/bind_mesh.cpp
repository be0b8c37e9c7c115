#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include "bind.h"
#include "emu/mesh/connected_components.h"
#include "emu/mesh/harmonic_field.h"
#include "emu/mesh/near_surface.h"
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
  m.def("harmonic_field", &harmonic_field, py::arg("X"), py::arg("T"), py::arg("fixed"), py::arg("values"),
        py::call_guard<py::gil_scoped_release>(),
        "P1 Laplace solve on tets T with values fixed at vertex ids -> #V field");
  m.def("connected_components", &connected_components, py::arg("num_vertices"), py::arg("T"),
        "#V, T  #T by 4 indices -> #V labels: the smallest vertex id of each vertex's piece");
  m.def(
      "near_surface",
      [](const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const Eigen::MatrixX3d& Q, double max_distance) {
        Eigen::VectorXd distance;
        Eigen::VectorXi nearest;
        {
          py::gil_scoped_release release;
          near_surface(V, F, Q, max_distance, distance, nearest);
        }
        return py::make_tuple(distance, nearest);
      },
      py::arg("V"), py::arg("F"), py::arg("Q"), py::arg("max_distance"),
      "V  #V by 3, F  #F by 3 triangles, Q  #Q by 3 queries -> (#Q distances to the nearest triangle, "
      "+inf beyond max_distance; #Q triangle ids, -1 where none)");
  m.def("tet_gradients", &tet_gradients, py::arg("X"), py::arg("T"), py::arg("phi"),
        "per-tet gradient of a P1 field -> #T by 3");
}
}  // namespace emu::bindings
