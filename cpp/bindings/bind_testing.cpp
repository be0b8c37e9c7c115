// _core.testing: the solvers' pieces one at a time (emu_solver_testing.h,
// fem_solver_testing.h), for tests and diagnostics only. energy and gradient
// take either solver (F for EMU, positions for FEM).
#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include "bind.h"
#include "emu/model/model.h"
#include "emu/solvers/emu/emu_solver_testing.h"
#include "emu/solvers/fem/fem_solver_testing.h"

namespace py = pybind11;

namespace emu::bindings {
namespace {
using gil = py::call_guard<py::gil_scoped_release>;

void bind_emu_testing(py::module_& t) {
  t.def("energy", &EmuSolverTesting::energy, py::arg("solver"), py::arg("load"), py::arg("F"), gil());
  t.def("gradient", &EmuSolverTesting::gradient, py::arg("solver"), py::arg("load"), py::arg("F"), gil(),
        "the Euclidean gradient, #unknowns by 9");
  t.def("fit_positions", &EmuSolverTesting::fit_positions, py::arg("solver"), py::arg("load"), py::arg("F"), gil());
  t.def("hessian_product", &EmuSolverTesting::hessian_product, py::arg("solver"), py::arg("load"), py::arg("F"),
        py::arg("V"), py::arg("exact") = false, gil());
  t.def("riemannian_hessian_product", &EmuSolverTesting::riemannian_hessian_product, py::arg("solver"),
        py::arg("load"), py::arg("F"), py::arg("V"), py::arg("exact") = false, gil());
  t.def("project_tangent", &EmuSolverTesting::project_tangent, py::arg("solver"), py::arg("F"), py::arg("V"), gil());
  t.def("retract", &EmuSolverTesting::retract, py::arg("solver"), py::arg("F"), py::arg("D"), py::arg("step"), gil());
  t.def("block_hessians", &EmuSolverTesting::block_hessians, py::arg("solver"), py::arg("load"), py::arg("F"),
        py::arg("exact") = false, gil());
  t.def("woodbury_solve", &EmuSolverTesting::woodbury_solve, py::arg("solver"), py::arg("load"), py::arg("F"),
        py::arg("R"), gil());
  t.def("schur_solve", &EmuSolverTesting::schur_solve, py::arg("solver"), py::arg("load"), py::arg("F"),
        py::arg("R"), gil());
  t.def("constant_schur_solve", &EmuSolverTesting::constant_schur_solve, py::arg("solver"), py::arg("load"),
        py::arg("F"), py::arg("R"), gil());
  t.def("constant_schur_inertia", &EmuSolverTesting::constant_schur_inertia, py::arg("solver"),
        "the inertia weight the constant Schur preconditioner's S0 holds (each solve sets it)");
  t.def("bone_turn", &EmuSolverTesting::bone_turn, py::arg("solver"), py::arg("load"), py::arg("F"), py::arg("bone"),
        py::arg("M"), py::arg("exact") = false, gil(),
        "(Z, H Z): the bone coarse space's turn of a movable bone by the tangent M, from its unit-turn fits");
  t.def("mode_matrix", &EmuSolverTesting::mode_matrix, py::arg("solver"));
  t.def("mode_values", &EmuSolverTesting::mode_values, py::arg("solver"));
}

void bind_fem_testing(py::module_& t) {
  t.def("energy", &FemSolverTesting::energy, py::arg("solver"), py::arg("load"), py::arg("x"), gil(),
        "E_FEM(x), contact included (no rest offset)");
  t.def("gradient", &FemSolverTesting::gradient, py::arg("solver"), py::arg("load"), py::arg("x"), gil(),
        "dE_FEM/dx, #V by 3 (zero rows at pinned vertices)");
  t.def("reduced_energy", &FemSolverTesting::reduced_energy, py::arg("solver"), py::arg("load"), py::arg("x0"),
        py::arg("z"), gil(),
        "Energy at increment z of the reduced unknowns (free soft displacements, bone increments) about x0");
  t.def(
      "reduced_system",
      [](FemSolver& s, const LoadCase& l, const Eigen::MatrixX3d& x0, bool exact) {
        Eigen::VectorXd g;
        Eigen::MatrixXd H;
        {
          py::gil_scoped_release release;
          FemSolverTesting::reduced_system(s, l, x0, exact, g, H);
        }
        return py::make_tuple(g, H);
      },
      py::arg("solver"), py::arg("load"), py::arg("x0"), py::arg("exact") = true,
      "(gradient, dense Hessian) of the reduced unknowns at x0 (small meshes only)");
}
}  // namespace

void bind_testing(py::module_& m) {
  py::module_ t = m.def_submodule("testing", "the solvers' pieces one at a time, for tests and diagnostics");
  bind_emu_testing(t);
  bind_fem_testing(t);
}
}  // namespace emu::bindings
