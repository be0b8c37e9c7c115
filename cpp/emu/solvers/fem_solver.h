#pragma once
// The reference: Newton on vertex positions with PSD-projected element
// Hessians, assembled deterministically into a fixed pattern and factorised
// by CHOLMOD every iteration (symbolic analysis once), Armijo backtracking.
//
// Movable bones are rigid bodies: x_v = R_b (X_v - P_b) + p_b. Their unknowns
// are exponential-map increments, re-linearised every iteration
// (R <- exp(omega^) R): a free bone has omega and a translation (6), a bone on
// a ball joint (one vertex shared with a pinned vertex or fixed bone) turns
// about it (omega, 3), a hinge (two or more collinear shared vertices) about
// its axis (1). The bone rows border the soft-vertex matrix: per iteration one
// factorisation of the soft block, #bone-dof back-substitutions and a small
// dense Schur complement. The Newton matrix includes the rotation's second-
// order term sum_v [ (f_v r_v^T + r_v f_v^T)/2 - (f_v . r_v) I ] (f = dE/dx,
// r = x - p). Joints between two movable bones are not supported here.
#include <memory>

#include "emu/linalg/cholmod_factor.h"
#include "emu/mesh/block_pattern.h"
#include "emu/model/model.h"
#include "emu/solvers/solve_types.h"

namespace emu {

class FemSolver {
 public:
  FemSolver(const Model& model, const SolverOptions& options);

  /// initial  #V by 3 start positions (nullptr: rest); pinned rows are replaced by the load's.
  SolveResult solve(const LoadCase& load, const Eigen::MatrixX3d* initial = nullptr);

  /// Total energy E_FEM(x) (no rest offset) and its gradient over all vertices (#V by 3,
  /// zero rows at pinned vertices) for positions x (#V by 3).
  double energy(const LoadCase& load, const Eigen::MatrixX3d& x) const;
  Eigen::MatrixX3d gradient(const LoadCase& load, const Eigen::MatrixX3d& x) const;

  double setup_seconds() const { return setup_seconds_; }
  const Model& model() const { return model_; }
  double factor_nnz() const { return factor_.factor_nnz(); }

 private:
  void free_gradient(const LoadCase& load, const Eigen::MatrixX3d& x, const Eigen::VectorXd& act,
                     Eigen::VectorXd& g) const;
  double energy_with(const Eigen::MatrixX3d& x, const Eigen::VectorXd& act, const Eigen::Vector3d& grav) const;
  void assemble_hessian(const Eigen::MatrixX3d& x, const Eigen::VectorXd& act, bool exact);
  /// dE/dx at the vertices that move with a bone, from the corner forces of the
  /// last free_gradient call (#V by 3, zero elsewhere).
  void vertex_forces(const Eigen::Vector3d& grav, Eigen::MatrixX3d& f) const;

  Model model_;
  Discretization disc_;
  SolverOptions options_;
  BlockPattern pattern_;
  CholmodFactor factor_;
  std::vector<double> element_, values_;
  std::vector<int> bone_touching_;  // soft tets with a corner on a movable bone
  mutable std::vector<double> corner_, tet_energy_;
  double setup_seconds_ = 0;
};

}  // namespace emu
