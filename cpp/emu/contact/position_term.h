#pragma once
// An energy of the vertex positions evaluated outside the core: contact
// (python/emu/contact.py: IPC barriers between part surfaces from ipctk).
//
// The solvers call it from serial code only (never inside an OpenMP region),
// so a callback may take the Python GIL and may throw; the exception leaves
// the solve.
#include <functional>

#include <Eigen/Core>
#include <Eigen/SparseCore>

namespace emu {

struct PositionTerm {
  /// Value at x (#V by 3 positions).
  std::function<double(const Eigen::MatrixX3d& x)> energy;
  /// Gradient at x: #V by 3 (zero rows where the term does not act).
  std::function<Eigen::MatrixX3d(const Eigen::MatrixX3d& x)> gradient;
  /// PSD Hessian at x: 3 #V by 3 #V, dof 3 v + i of vertex v, coordinate i;
  /// both triangles stored.
  std::function<Eigen::SparseMatrix<double>(const Eigen::MatrixX3d& x)> hessian;
  /// The largest s in [0, 1] such that the straight path from x0 to
  /// x0 + s (x1 - x0) creates no intersection (continuous collision detection).
  std::function<double(const Eigen::MatrixX3d& x0, const Eigen::MatrixX3d& x1)> max_step;
  /// Called with a solve's start positions; throws if they are not admissible
  /// (surfaces already intersecting). Optional.
  std::function<void(const Eigen::MatrixX3d& x)> check_start;

  bool active() const { return static_cast<bool>(energy); }
};

}  // namespace emu
