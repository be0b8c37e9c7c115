#pragma once
// FemSolver's pieces one at a time, for tests: not part of the solver's
// interface (the Python bindings put them in _core.testing). Positions x, x0
// are #V by 3.
#include <Eigen/Core>

#include "emu/solvers/fem/fem_solver.h"

namespace emu {

struct FemSolverTesting {
  /// Total energy E_FEM(x) (no rest offset) and its gradient over all vertices
  /// (#V by 3, zero rows at pinned vertices), contact included.
  static double energy(const FemSolver& s, const LoadCase& load, const Eigen::MatrixX3d& x);
  static Eigen::MatrixX3d gradient(const FemSolver& s, const LoadCase& load, const Eigen::MatrixX3d& x);

  /// The Newton system in the solver's reduced unknowns z = (displacements of
  /// the free soft vertices, 3 #free; then the bone increments: exponential-map
  /// turns, translations of free bones) about the start state x0 (each bone at
  /// the best rigid fit of its rows, on its joints): the energy at increment z,
  /// and the gradient and dense Hessian (exact, or PSD-filtered) at z = 0.
  /// Small meshes only (the Hessian is dense).
  static double reduced_energy(FemSolver& s, const LoadCase& load, const Eigen::MatrixX3d& x0,
                               const Eigen::VectorXd& z);
  static void reduced_system(FemSolver& s, const LoadCase& load, const Eigen::MatrixX3d& x0, bool exact,
                             Eigen::VectorXd& gradient, Eigen::MatrixXd& hessian);
};

}  // namespace emu
