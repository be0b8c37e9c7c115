#pragma once
// An energy of the vertex positions evaluated outside the core: contact
// (python/emu/model/contact.py: IPC barriers between part surfaces from ipctk).
//
// The solvers call it from serial code only (never inside an OpenMP region),
// so a callback may take the Python GIL and may throw; the exception leaves
// the solve.
#include <cmath>
#include <functional>
#include <stdexcept>

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

  // What both solvers call: the callbacks with their results checked.
  /// gradient(x), required finite and #V by 3.
  Eigen::MatrixX3d checked_gradient(const Eigen::MatrixX3d& x) const {
    Eigen::MatrixX3d g = gradient(x);
    if (g.rows() != x.rows() || !g.allFinite()) throw std::runtime_error("the contact gradient must be finite and #V by 3");
    return g;
  }
  /// hessian(x), required 3 #V by 3 #V, compressed.
  Eigen::SparseMatrix<double> checked_hessian(const Eigen::MatrixX3d& x) const {
    Eigen::SparseMatrix<double> H = hessian(x);
    const Eigen::Index n3 = 3 * x.rows();
    if (H.rows() != n3 || H.cols() != n3) throw std::runtime_error("the contact Hessian must be 3 #V by 3 #V");
    H.makeCompressed();
    return H;
  }
  /// A solve's start: check_start(x) where given, then its total energy E must be finite.
  void check_start_state(const Eigen::MatrixX3d& x, double E) const {
    if (check_start) check_start(x);
    if (!std::isfinite(E))
      throw std::invalid_argument(
          "the start state has a non-finite energy: with contact, surfaces that touch or intersect (move "
          "the pins or bones in smaller steps between solves, or start from positions without contact)");
  }
};

}  // namespace emu
