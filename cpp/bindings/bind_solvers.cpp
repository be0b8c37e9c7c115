#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <memory>
#include <stdexcept>
#include <string>

#include "bind.h"
#include "emu/model/model.h"
#include "emu/solvers/emu/emu_solver.h"
#include "emu/solvers/fem/fem_solver.h"
#include "emu/solvers/option_choices.h"

namespace py = pybind11;

namespace emu::bindings {
namespace {
// Ctrl-C: the solvers poll this once per iteration without holding the GIL.
SolverOptions with_interrupt(SolverOptions o) {
  o.interrupted = [] {
    py::gil_scoped_acquire gil;
    return PyErr_CheckSignals() != 0;
  };
  return o;
}

// Run a solve without the GIL; re-raise the KeyboardInterrupt it stopped for,
// or the exception an on_iteration callback raised.
template <class F>
SolveResult run_solve(F&& f) {
  SolveResult r;
  {
    py::gil_scoped_release release;
    r = f();
  }
  if (PyErr_Occurred()) throw py::error_already_set();
  return r;
}

// A Python contact term (emu.contact.ContactTerm: energy, gradient, hessian,
// max_step of #V by 3 positions) as the solvers' PositionTerm. The object is
// held by a shared_ptr whose deleter takes the GIL, so a solver holding it can
// be destroyed without it; each call takes the GIL and lets a Python
// exception propagate (the solvers call it outside OpenMP regions).
PositionTerm python_position_term(const py::object& obj) {
  std::shared_ptr<py::object> o(new py::object(obj), [](py::object* p) {
    py::gil_scoped_acquire gil;
    delete p;
  });
  PositionTerm t;
  t.energy = [o](const Eigen::MatrixX3d& x) {
    py::gil_scoped_acquire gil;
    return o->attr("energy")(Eigen::MatrixX3d(x)).cast<double>();
  };
  t.gradient = [o](const Eigen::MatrixX3d& x) {
    py::gil_scoped_acquire gil;
    return o->attr("gradient")(Eigen::MatrixX3d(x)).cast<Eigen::MatrixX3d>();
  };
  t.hessian = [o](const Eigen::MatrixX3d& x) {
    py::gil_scoped_acquire gil;
    return o->attr("hessian")(Eigen::MatrixX3d(x)).cast<Eigen::SparseMatrix<double>>();
  };
  t.max_step = [o](const Eigen::MatrixX3d& x0, const Eigen::MatrixX3d& x1) {
    py::gil_scoped_acquire gil;
    return o->attr("max_step")(Eigen::MatrixX3d(x0), Eigen::MatrixX3d(x1)).cast<double>();
  };
  t.check_start = [o](const Eigen::MatrixX3d& x) {
    py::gil_scoped_acquire gil;
    o->attr("check_start")(Eigen::MatrixX3d(x));
  };
  return t;
}

// F per tet as Python sees it, (m, 3, 3), from and to the core's m by 9 rows (F row-major per row).
using RowsX9 = Eigen::Matrix<double, Eigen::Dynamic, 9, Eigen::RowMajor>;
py::array_t<double> f_array(const Eigen::MatrixXd& rows) {
  py::array_t<double> a({static_cast<py::ssize_t>(rows.rows()), py::ssize_t(3), py::ssize_t(3)});
  Eigen::Map<RowsX9>(a.mutable_data(), rows.rows(), 9) = rows;  // C order: row t is F_t row-major
  return a;
}
Eigen::MatrixXd f_rows(const py::object& F, Eigen::Index count) {
  const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(F);
  if (!a || a.ndim() != 3 || a.shape(0) != count || a.shape(1) != 3 || a.shape(2) != 3)
    throw std::invalid_argument("F0 must be one 3x3 deformation gradient per tet of the scene, shape (" +
                                std::to_string(count) + ", 3, 3)");
  return Eigen::Map<const RowsX9>(a.data(), count, 9);
}

PositionTerm contact_term(const py::object& term) {
  return term.is_none() ? PositionTerm() : python_position_term(term);
}
constexpr const char* kContactDoc =
    "contact: barriers on the positions (EMU: on its fit), an object with energy(x), gradient(x), hessian(x) "
    "(scipy.sparse, 3n x 3n), max_step(x0, x1) and check_start(x) (emu.contact.ContactTerm); None: no contact";

py::dict record_dict(const IterationRecord& e) {
  py::dict d;
  d["iteration"] = e.iteration;
  d["energy"] = e.energy;
  d["grad_norm"] = e.grad_norm;
  d["step"] = e.step;
  d["time_s"] = e.time_s;
  d["cg_iterations"] = e.cg_iterations;
  d["backtracks"] = e.backtracks;
  return d;
}

// A Python on_iteration(record: dict, positions: (n, 3) array) -> truthy to
// stop, called with the GIL held. An exception it raises stops the solve and
// is re-raised by run_solve (it never crosses the C++ solver).
template <class Solver>
struct IterationCallbackScope {
  Solver& solver;
  IterationCallbackScope(Solver& s, const py::object& fn) : solver(s) {
    if (fn.is_none()) return;
    solver.set_on_iteration([fn](const IterationRecord& rec, const Eigen::MatrixX3d& x) {
      py::gil_scoped_acquire gil;
      if (PyErr_Occurred()) return true;  // an earlier call failed: stop
      try {
        return bool(py::bool_(fn(record_dict(rec), Eigen::MatrixX3d(x))));
      } catch (py::error_already_set& e) {
        e.restore();
        return true;
      }
    });
  }
  ~IterationCallbackScope() { solver.set_on_iteration({}); }
};
Eigen::MatrixXd history_array(const SolveResult& r) {
  Eigen::MatrixXd h(r.history.size(), 7);
  for (size_t i = 0; i < r.history.size(); ++i) {
    const auto& e = r.history[i];
    h.row(i) << e.iteration, e.energy, e.grad_norm, e.step, e.time_s, e.cg_iterations, e.backtracks;
  }
  return h;
}

using gil = py::call_guard<py::gil_scoped_release>;

void bind_options(py::module_& m) {
  py::class_<SolverOptions>(m, "SolverOptions")
      .def(py::init<>())
      .def_readwrite("max_iterations", &SolverOptions::max_iterations)
      .def_readwrite("rtol_grad", &SolverOptions::rtol_grad)
      .def_readwrite("rtol_energy", &SolverOptions::rtol_energy)
      .def_readwrite("noise_factor", &SolverOptions::noise_factor)
      .def_readwrite("armijo", &SolverOptions::armijo)
      .def_readwrite("step_tol", &SolverOptions::step_tol)
      .def_readwrite("step_tol_grad", &SolverOptions::step_tol_grad)
      .def_readwrite("step_tol_cold_scale", &SolverOptions::step_tol_cold_scale)
      .def_readwrite("step_tol_contraction", &SolverOptions::step_tol_contraction)
      .def_readwrite("max_backtracks", &SolverOptions::max_backtracks)
      .def_property(
          "eigen_filter", [](const SolverOptions& o) { return choice_name(kEigenFilters, o.eigen_filter); },
          [](SolverOptions& o, const std::string& s) { o.eigen_filter = parse_choice(kEigenFilters, "eigen_filter", s); })
      .def_readwrite("exact_when_definite", &SolverOptions::exact_when_definite)
      .def_readwrite("negative_curvature", &SolverOptions::negative_curvature)
      .def_readwrite("lagged_cg_iterations", &SolverOptions::lagged_cg_iterations)
      .def_readwrite("lagged_cg_forcing", &SolverOptions::lagged_cg_forcing)
      .def_readwrite("lagged_refresh", &SolverOptions::lagged_refresh);

  m.def(
      "option_choices",
      [] {
        py::dict d;
        d["step"] = py::tuple(py::cast(choice_names(kEmuSteps)));
        d["preconditioner"] = py::tuple(py::cast(choice_names(kEmuPreconditioners)));
        d["eigen_filter"] = py::tuple(py::cast(choice_names(kEigenFilters)));
        return d;
      },
      "{option: (its choices, the default first)} for the options that take one of a few names");

  py::class_<EmuSolverOptions>(m, "EmuSolverOptions")
      .def(py::init<>())
      .def_readwrite("alpha", &EmuSolverOptions::alpha)
      .def_readwrite("modes", &EmuSolverOptions::modes)
      .def_property(
          "step", [](const EmuSolverOptions& o) { return choice_name(kEmuSteps, o.step); },
          [](EmuSolverOptions& o, const std::string& s) { o.step = parse_choice(kEmuSteps, "step", s); })
      .def_readwrite("cg_max_iterations", &EmuSolverOptions::cg_max_iterations)
      .def_readwrite("cg_forcing_max", &EmuSolverOptions::cg_forcing_max)
      .def_readwrite("cg_forcing_exponent", &EmuSolverOptions::cg_forcing_exponent)
      .def_readwrite("cg_forcing_min", &EmuSolverOptions::cg_forcing_min)
      .def_readwrite("cg_model_decrease", &EmuSolverOptions::cg_model_decrease)
      .def_readwrite("preconditioner_refresh", &EmuSolverOptions::preconditioner_refresh)
      .def_property(
          "preconditioner", [](const EmuSolverOptions& o) { return choice_name(kEmuPreconditioners, o.preconditioner); },
          [](EmuSolverOptions& o, const std::string& s) {
            o.preconditioner = parse_choice(kEmuPreconditioners, "preconditioner", s);
          })
      .def_readwrite("bone_coarse_space", &EmuSolverOptions::bone_coarse_space)
      .def_readwrite("joint_coordinates", &EmuSolverOptions::joint_coordinates)
      .def_readwrite("recycled_directions", &EmuSolverOptions::recycled_directions)
      .def_readwrite("single_precision_preconditioner", &EmuSolverOptions::single_precision_preconditioner)
      .def_readwrite("lbfgs_memory", &EmuSolverOptions::lbfgs_memory);
}

void bind_results(py::module_& m) {
  py::class_<PhaseTimes>(m, "PhaseTimes")
      .def_readonly("hessian", &PhaseTimes::hessian)
      .def_readonly("preconditioner", &PhaseTimes::preconditioner)
      .def_readonly("linear_solve", &PhaseTimes::linear_solve)
      .def_readonly("line_search", &PhaseTimes::line_search)
      .def_readonly("step", &PhaseTimes::step);

  py::class_<SolveResult>(m, "SolveResult")
      .def_readonly("phases", &SolveResult::phases)
      .def_readonly("positions", &SolveResult::positions)
      .def_property_readonly(
          "F",
          [](const SolveResult& r) -> py::object {
            return r.F.size() ? py::object(f_array(r.F)) : py::object(py::none());
          },
          "EMU: (#scene tets, 3, 3) F per tet of the scene (identity where a tet has no unknown); FEM: None")
      .def_readonly("converged", &SolveResult::converged)
      .def_readonly("status", &SolveResult::status)
      .def_readonly("iterations", &SolveResult::iterations)
      .def_readonly("cg_iterations", &SolveResult::cg_iterations)
      .def_readonly("filtered_steps", &SolveResult::filtered_steps)
      .def_readonly("exact_attempts_failed", &SolveResult::exact_attempts_failed)
      .def_readonly("factorizations", &SolveResult::factorizations)
      .def_readonly("negative_curvature_steps", &SolveResult::negative_curvature_steps)
      .def_readonly("energy", &SolveResult::energy)
      .def_readonly("grad_norm", &SolveResult::grad_norm)
      .def_readonly("grad_norm0", &SolveResult::grad_norm0)
      .def_readonly("rel_energy_change", &SolveResult::rel_energy_change)
      .def_readonly("time_s", &SolveResult::time_s)
      .def_readonly("neutral_bones", &SolveResult::neutral_bones)
      .def_readonly("neutral_axes", &SolveResult::neutral_axes)
      .def_property_readonly("history", &history_array,
                             "#iterations+1 by 7: iteration, energy, grad_norm, step, time_s, cg_iterations, backtracks");
}

void bind_fem_solver(py::module_& m) {
  py::class_<FemSolver>(m, "FemSolver")
      .def(py::init([](const Model& m, const SolverOptions& o, const py::object& contact) {
             PositionTerm term = contact_term(contact);
             py::gil_scoped_release release;
             return std::make_unique<FemSolver>(m, with_interrupt(o), std::move(term));
           }),
           py::arg("model"), py::arg("options"), py::arg("contact") = py::none(), kContactDoc)
      .def(
          "solve",
          [](FemSolver& s, const LoadCase& l, const py::object& cb) {
            IterationCallbackScope<FemSolver> scope(s, cb);
            return run_solve([&] { return s.solve(l); });
          },
          py::arg("load"), py::arg("on_iteration") = py::none())
      .def(
          "solve_from",
          [](FemSolver& s, const LoadCase& l, const Eigen::MatrixX3d& x0, const py::object& cb) {
            IterationCallbackScope<FemSolver> scope(s, cb);
            return run_solve([&] { return s.solve(l, &x0); });
          },
          py::arg("load"), py::arg("x0"), py::arg("on_iteration") = py::none())
      .def("structures", &FemSolver::structures, "(name, bytes) of the structures this solver built")
      .def_property_readonly("model", &FemSolver::model, py::return_value_policy::copy,
                             "a copy of the model as this solver stores it (tets in its order)")
      .def(
          "newton_correction",
          [](FemSolver& s, const LoadCase& l, const Eigen::MatrixX3d& x0, const std::string& hessian, int max_steps) {
            FemSolver::CorrectionHessian h = FemSolver::CorrectionHessian::LowerEnergy;
            if (hessian == "exact") h = FemSolver::CorrectionHessian::Exact;
            else if (hessian == "filtered") h = FemSolver::CorrectionHessian::Filtered;
            else if (hessian == "lagged-newton") h = FemSolver::CorrectionHessian::LaggedNewton;
            else if (hessian == "newton") h = FemSolver::CorrectionHessian::Newton;
            else if (hessian != "lower-energy")
              throw std::invalid_argument("hessian must be 'lower-energy', 'exact', 'filtered', 'lagged-newton' or "
                                          "'newton', got '" + hessian + "'");
            py::gil_scoped_release release;
            return s.newton_correction(l, x0, h, max_steps);
          },
          py::arg("load"), py::arg("x0"), py::arg("hessian") = "lower-energy", py::arg("max_steps") = 1,
          "Positions after the Newton correction steps of the FEM energy from x0")
      .def_property_readonly("setup_seconds", &FemSolver::setup_seconds)
      .def_property_readonly("factor_nnz", &FemSolver::factor_nnz)
      .def_property_readonly("factorization_flops", &FemSolver::factorization_flops,
                             "floating-point operations of one numeric factorisation of the Newton matrix")
      .def_property_readonly("factorizations", &FemSolver::factorizations,
                             "numeric factorisations of the Newton matrix so far (solves and corrections)")
      .def_property_readonly("refresh_iterations", &FemSolver::refresh_iterations,
                             "with SolverOptions.lagged_refresh: PCG iterations past which the lagged factor has aged")
      .def_property_readonly("pcg_iterations", &FemSolver::pcg_iterations,
                             "PCG iterations on the lagged factor so far (solves and corrections)");
}

void bind_emu_solver(py::module_& m) {
  py::class_<EmuSolver>(m, "EmuSolver")
      .def(py::init([](const Model& m, const SolverOptions& o, const EmuSolverOptions& e, const py::object& contact) {
             PositionTerm term = contact_term(contact);
             py::gil_scoped_release release;
             return std::make_unique<EmuSolver>(m, with_interrupt(o), e, std::move(term));
           }),
           py::arg("model"), py::arg("options"), py::arg("emu_options"), py::arg("contact") = py::none(), kContactDoc)
      .def(
          "solve",
          [](EmuSolver& s, const LoadCase& l, const py::object& cb) {
            IterationCallbackScope<EmuSolver> scope(s, cb);
            return run_solve([&] { return s.solve(l); });
          },
          py::arg("load"), py::arg("on_iteration") = py::none())
      .def(
          "solve_from",
          [](EmuSolver& s, const LoadCase& l, const py::object& F0, const py::object& cb) {
            const Eigen::MatrixXd rows = f_rows(F0, s.model().scene_tet_count());
            IterationCallbackScope<EmuSolver> scope(s, cb);
            return run_solve([&] { return s.solve(l, &rows); });
          },
          py::arg("load"), py::arg("F0"), py::arg("on_iteration") = py::none(),
          "a solve from F0, (#scene tets, 3, 3) as SolveResult.F")
      .def("structures", &EmuSolver::structures, "(name, bytes) of the structures this solver built")
      .def_property_readonly("modes", &EmuSolver::modes)
      .def_property_readonly("bone_coordinates", &EmuSolver::bone_coordinates,
                             "how movable bones turn: 'joint coordinates', 'per bone: <why>', '' without bones")
      .def_property_readonly("bone_forest_error", &EmuSolver::bone_forest_error,
                             "why the movable bones form no tree of joints (a loop, a weld); '' for a tree")
      .def_property_readonly("num_unknowns", &EmuSolver::num_unknowns)
      .def_property_readonly(
          "tet_unknown",
          [](const EmuSolver& s) {
            const Model& m = s.model();
            Eigen::VectorXi out = Eigen::VectorXi::Constant(m.scene_tet_count(), -1);
            for (Eigen::Index t = 0; t < m.tets.rows(); ++t) out(m.scene_index(t)) = s.tet_unknown()(t);
            return out;
          },
          "#scene tets: the F unknown each tet of the scene uses (soft tets in the solver's order, then one per "
          "movable bone; -1: a tet without unknowns)")
      .def_property_readonly("model", &EmuSolver::model, py::return_value_policy::copy,
                             "a copy of the model as this solver stores it (tets in its order)")
      .def_property("alpha", &EmuSolver::alpha, &EmuSolver::set_alpha, "absolute alpha (settable between solves)")
      .def_property("cg_forcing_max", &EmuSolver::cg_forcing_max, &EmuSolver::set_cg_forcing_max,
                    "Eisenstat-Walker cap on the CG forcing term (settable between solves)")
      .def_property_readonly("factor_seconds", &EmuSolver::factor_seconds)
      .def_property_readonly("modes_seconds", &EmuSolver::modes_seconds)
      .def_property_readonly("setup_seconds", &EmuSolver::setup_seconds)
      .def_property_readonly("factor_nnz", &EmuSolver::factor_nnz);
}
}  // namespace

void bind_solvers(py::module_& m) {
  bind_options(m);
  bind_results(m);
  bind_fem_solver(m);
  bind_emu_solver(m);
}
}  // namespace emu::bindings
