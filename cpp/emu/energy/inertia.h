#pragma once
// The inertia of an implicit time step, as an incremental potential on lumped
// vertex masses (the solvers minimise E - W + I):
//   I(x) = (w / 2) sum_v m_v |x_v - y_v|^2,
//   dI/dx_v = w m_v (x_v - y_v),   d2I/dx_v2 = w m_v I3,
// y the step's predicted positions and w = 1 / h_eff^2 (backward Euler: y =
// x_n + h v_n, h_eff = h; BDF2: y = (4 x_n - x_{n-1}) / 3 + h (8 v_n - 2 v_{n-1}) / 9,
// h_eff = 2h / 3; mass-proportional damping folded into w and y by the caller:
// emu.solve.dynamics).
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

namespace emu::inertia {

/// (w / 2) m |x - y|^2: a vertex of mass m at x with predicted position y; w = 1 / h_eff^2.
/// The solvers sum it over the vertices that move (free, or on a movable bone).
inline double vertex_energy(double m, const Eigen::Vector3d& x, const Eigen::Vector3d& y, double w) {
  return 0.5 * w * m * (x - y).squaredNorm();
}

/// dI/dx_v for a vertex of mass m at x with predicted position y.
inline Eigen::Vector3d vertex_gradient(double m, const Eigen::Vector3d& x, const Eigen::Vector3d& y, double w) {
  return w * m * (x - y);
}

/// The vertex's Hessian block is this times the 3 x 3 identity.
inline double vertex_hessian(double m, double w) { return w * m; }

/// I(x) over the vertices v with counted(v) (the others' share is a constant).
/// m  #V masses;  x, y  #V by 3 positions and predicted positions.
template <class Counted>
double energy(const Eigen::VectorXd& m, const Eigen::MatrixX3d& x, const Eigen::MatrixX3d& y, double w,
              Counted counted) {
  double E = 0;
  for (Eigen::Index v = 0; v < x.rows(); ++v)
    if (counted(v)) E += vertex_energy(m(v), x.row(v).transpose(), y.row(v).transpose(), w);
  return E;
}

/// The Hessian of I over the vertices v with counted(v): 3 #V square, diagonal.
template <class Counted>
Eigen::SparseMatrix<double> diagonal_hessian(const Eigen::VectorXd& m, double w, Counted counted) {
  std::vector<Eigen::Triplet<double>> diag;
  for (Eigen::Index v = 0; v < m.size(); ++v)
    if (counted(v))
      for (int k = 0; k < 3; ++k) diag.emplace_back(3 * v + k, 3 * v + k, vertex_hessian(m(v), w));
  Eigen::SparseMatrix<double> H(3 * m.size(), 3 * m.size());
  H.setFromTriplets(diag.begin(), diag.end());
  return H;
}

}  // namespace emu::inertia
