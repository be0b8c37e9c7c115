#include "emu/solvers/fem/fem_solver_testing.h"

#include "emu/model/model.h"

namespace emu {

double FemSolverTesting::energy(const FemSolver& s, const LoadCase& load, const Eigen::MatrixX3d& x) {
  validate_load(s.model_, load);
  return s.energy_with(x, tet_activation(s.model_, load), load) + s.contact_energy(x);
}

Eigen::MatrixX3d FemSolverTesting::gradient(const FemSolver& s, const LoadCase& load, const Eigen::MatrixX3d& x) {
  validate_load(s.model_, load);
  Eigen::VectorXd g;
  s.free_gradient(load, x, tet_activation(s.model_, load), g);
  Eigen::MatrixX3d out = Eigen::MatrixX3d::Zero(x.rows(), 3);
  const Eigen::MatrixX3d gc = s.contact_gradient(x);
  for (Eigen::Index v = 0; v < x.rows(); ++v)
    if (s.layout_.free_index(v) >= 0) out.row(v) = g.segment<3>(3 * s.layout_.free_index(v)).transpose() + gc.row(v);
  return out;
}

// reduced_energy and reduced_system are in fem_solver.cpp, beside the Newton state they use.

}  // namespace emu
