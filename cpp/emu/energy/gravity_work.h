#pragma once
// The work of gravity on lumped vertex masses, W(x) = sum_v m_v g . x_v
// (the solvers minimise E - W). Linear in x:
//   dW/dx_v = m_v g,   d2W/dx2 = 0.
// EMU evaluates it at the fitted positions x*(F); its F-gradient does not drop
// out by the envelope theorem (x* does not minimise W): it is
// -(dx*/dF)^T dW/dx, one constant solve per load (EmuSolver's load context).
#include <Eigen/Core>

namespace emu::gravity_work {

/// mass  #V lumped masses;  x  #V by 3 positions;  g  acceleration.
inline double energy(const Eigen::VectorXd& mass, const Eigen::MatrixX3d& x, const Eigen::Vector3d& g) {
  return (mass.transpose() * x).dot(g.transpose());
}

/// dW/dx_v for a vertex of mass m.
inline Eigen::Vector3d vertex_gradient(double m, const Eigen::Vector3d& g) { return m * g; }

}  // namespace emu::gravity_work
