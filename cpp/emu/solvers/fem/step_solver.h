#pragma once
// The linear algebra of one FEM Newton step, apart from the iterate it serves:
// the factorised Newton matrix with the movable bones' border eliminated by
// their dense Schur complement (its neutral modes; the border kept as the
// lagged factor's), Newton-CG on the lagged factor, the diagonal-shift
// retries of the filtered matrix, and the negative-curvature step at a saddle.
// Private to fem_solver.cpp (FemSolver::NewtonProblem holds one).
#include <vector>

#include <Eigen/Core>

#include "emu/solvers/fem/fem_solver.h"
#include "emu/solvers/newton/pcg.h"

namespace emu {

class FemSolver::StepSolver {
 public:
  /// The load's per-tet activation act, the problem's iterate (positions x, bone poses, vertex forces fv for the
  /// bones' rotation term), its reduced gradient (gs, gb) and the direction
  /// (ds, db) it reads: kept by reference (the problem's members).
  StepSolver(FemSolver& s, const Eigen::VectorXd& act, const Eigen::MatrixX3d& x, const BonePoses& poses,
             const Eigen::MatrixX3d& fv, const Eigen::VectorXd& gs, const Eigen::VectorXd& gb, Eigen::VectorXd& ds,
             Eigen::VectorXd& db);

  /// (ds, db) from a factorisation of the assembled soft block and the bone
  /// border; false if the matrix is not positive definite.
  bool newton_direction(bool exact);
  /// Projected element Hessians make the matrix PSD and a pinned scene makes
  /// it definite; round-off can still break the Cholesky: the diagonal is
  /// shifted and the factorisation retried. False: no direction.
  bool filtered_direction();
  /// Newton-CG with the lagged factor as preconditioner to |r| <= tol (see
  /// the definition); false (nothing changed) where it does not converge within
  /// SolverOptions::lagged_cg_iterations or meets negative curvature (then
  /// lagged_indefinite()).
  bool lagged_direction(bool exact_border, double tol, int& cg_iterations);
  bool lagged_indefinite() const { return lagged_indefinite_; }
  /// Adds the direction of the exact Hessian's most negative curvature to ds
  /// after a filtered factorisation (see the definition); 1 if it did.
  int add_negative_curvature();
  /// The bones' border of the Newton matrix at the iterate (Hsb: #soft rows by
  /// #bone unknowns, Hbb square), contact's included.
  void border(bool exact, Eigen::MatrixXd& Hsb, Eigen::MatrixXd& Hbb);
  /// The neutral modes of the last factorised step, cleared.
  std::vector<NeutralMode> take_neutral() { return std::move(neutral_); }
  /// The bone Schur complement of the last factorised step (empty: none yet) and its poses.
  const Eigen::MatrixXd& last_bone_schur() const { return last_S_; }
  const BonePoses& last_schur_poses() const { return last_S_poses_; }

 private:
  void keep_bone_border(const Eigen::MatrixXd& S);

  FemSolver& s_;
  const int nd_;
  const Eigen::VectorXd& act_;  // per-tet activation of the load
  const Eigen::MatrixX3d &x_, &fv_;
  const BonePoses& poses_;
  const Eigen::VectorXd &gs_, &gb_;
  Eigen::VectorXd &ds_, &db_;
  Eigen::VectorXd y_;
  Eigen::MatrixXd Hsb_, Wsb_, Hbb_;
  Pcg<Eigen::VectorXd> pcg_;
  bool lagged_indefinite_ = false;  // the last lagged PCG met p^T H p <= 0
  std::vector<NeutralMode> neutral_;
  Eigen::MatrixXd last_S_;
  BonePoses last_S_poses_;
};

}  // namespace emu
