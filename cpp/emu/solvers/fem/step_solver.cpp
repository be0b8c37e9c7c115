#include "emu/solvers/fem/step_solver.h"

#include <algorithm>
#include <utility>

#include <Eigen/Cholesky>

#include "emu/linalg/negative_curvature.h"
#include "emu/linalg/symmetric_product.h"
#include "emu/mesh/tet_geometry.h"

namespace emu {
namespace {
// add_negative_curvature: power iterations to kCurvatureRtol; taken where
// v^T H v <= (1 - kCurvatureMin) v^T H+ v (clearly negative); its largest
// vertex move kCurvatureLength of the mesh diagonal (the outcome is
// insensitive to it; docs/stability.md).
constexpr double kCurvatureRtol = 1e-3, kCurvatureMin = 1.01, kCurvatureLength = 1e-2;
constexpr int kCurvatureIterations = 40;
}  // namespace

FemSolver::StepSolver::StepSolver(FemSolver& s, const Eigen::VectorXd& act, const Eigen::MatrixX3d& x,
                                  const BonePoses& poses, const Eigen::MatrixX3d& fv, const Eigen::VectorXd& gs,
                                  const Eigen::VectorXd& gb, Eigen::VectorXd& ds, Eigen::VectorXd& db)
    : s_(s), nd_(s.bones_.dofs()), act_(act), x_(x), fv_(fv), poses_(poses), gs_(gs), gb_(gb), ds_(ds), db_(db) {}

void FemSolver::StepSolver::border(bool exact, Eigen::MatrixXd& Hsb, Eigen::MatrixXd& Hbb) {
  s_.bones_.assemble_border(poses_, s_.element_, x_, fv_, exact, Hsb, Hbb);
  if (s_.has_contact()) s_.bones_.add_vertex_hessian(poses_, x_, s_.contact_H_, Hsb, Hbb);
  if (s_.bone_inertia_.size()) s_.bones_.add_vertex_hessian(poses_, x_, s_.bone_inertia_, Hsb, Hbb);
}

// The Newton direction from the assembled soft block and the bone border;
// false if the matrix is not positive definite.
bool FemSolver::StepSolver::newton_direction(bool exact) {
  ++s_.factorizations_;
  s_.lag_.valid = s_.lag_.aged = false;  // the factor is being replaced
  if (!s_.factorize_newton_matrix()) return false;
  const CholmodFactor& factor = s_.newton_factor();
  y_.resize(gs_.size());
  factor.solve(gs_.data(), y_.data(), 1);
  if (!nd_) {
    ds_ = -y_;
    s_.lag_.valid = !s_.use_merged_;
    return true;
  }
  border(exact, Hsb_, Hbb_);
  Wsb_.resize(Hsb_.rows(), nd_);
  factor.solve(Hsb_.data(), Wsb_.data(), nd_);
  Eigen::MatrixXd S = Hbb_ - Hsb_.transpose() * Wsb_;
  S = 0.5 * (S + S.transpose()).eval();
  const Eigen::VectorXd rb = -gb_ + Hsb_.transpose() * y_;
  last_S_ = S;
  last_S_poses_ = poses_;
  if (!s_.bones_.solve_schur(poses_, S, rb, exact, db_, neutral_)) return false;
  ds_ = -y_ - Wsb_ * db_;
  keep_bone_border(S);
  return true;
}

// The bone border of the factorisation just made, for lagged_direction; a
// singular bone Schur complement (a neutral mode) leaves no preconditioner.
void FemSolver::StepSolver::keep_bone_border(const Eigen::MatrixXd& S) {
  Eigen::LLT<Eigen::MatrixXd> llt(S);
  if (llt.info() != Eigen::Success || !neutral_.empty() || s_.use_merged_) return;
  s_.lag_.Hsb = Hsb_;
  s_.lag_.Wsb = Wsb_;
  s_.lag_.S_inv = llt.solve(Eigen::MatrixXd::Identity(nd_, nd_));
  s_.lag_.valid = true;
}

// Newton-CG with the lagged factor as preconditioner (SolverOptions::
// lagged_cg_iterations): PCG on the current Newton matrix (soft block K from
// the assembled values, bone border Hsb, Hbb) to |r| <= tol, the inverse of
// the factorised matrix applied by block elimination:
//   y_s = K_lag^-1 r_s,  z_b = S_lag^-1 (r_b - Hsb_lag^T y_s),  z_s = y_s - K_lag^-1 Hsb_lag z_b.
// False (nothing changed) if it does not converge within the cap or meets
// negative curvature (lagged_indefinite_: the matrix is not definite, and
// newton_correction then factorises only the filtered one): the caller
// factorises instead.
bool FemSolver::StepSolver::lagged_direction(bool exact_border, double tol, int& cg_iterations) {
  const FemSolver::LaggedFactor& lag = s_.lag_;
  lagged_indefinite_ = false;
  if (!lag.valid) return false;
  const Eigen::Index ns = gs_.size();
  if (nd_) border(exact_border, Hsb_, Hbb_);
  auto product = [&](const Eigen::VectorXd& v, Eigen::VectorXd& out) {
    out.resize(v.size());
    const BlockPattern& P = s_.pattern_;
    symmetric_upper_product(P.rows(), P.col_ptr().data(), P.row_index().data(), s_.values_.data(), v.data(),
                            out.data());
    if (!nd_) return;
    out.head(ns).noalias() += Hsb_ * v.tail(nd_);
    out.tail(nd_).noalias() = Hsb_.transpose() * v.head(ns) + Hbb_ * v.tail(nd_);
  };
  auto precondition = [&](const Eigen::VectorXd& r, Eigen::VectorXd& z) {
    z.resize(r.size());
    s_.factor_.solve(r.data(), z.data(), 1);
    if (!nd_) return;
    const Eigen::VectorXd zb = lag.S_inv * (r.tail(nd_) - lag.Hsb.transpose() * z.head(ns));
    z.head(ns).noalias() -= lag.Wsb * zb;
    z.tail(nd_) = zb;
  };
  Eigen::VectorXd b(ns + nd_), d;
  b.head(ns) = -gs_;
  if (nd_) b.tail(nd_) = -gb_;
  const PcgResult cg = pcg_.solve(product, precondition, b, tol, s_.options_.lagged_cg_iterations, d);
  cg_iterations = cg.iterations;
  s_.pcg_iterations_ += cg.iterations;
  lagged_indefinite_ = cg.negative_curvature;
  if (!cg.converged) return false;
  if (s_.options_.lagged_refresh && cg.iterations > s_.refresh_iterations_) s_.lag_.aged = true;
  ds_ = d.head(ns);
  if (nd_) db_ = d.tail(nd_);
  return true;
}

// Near a stationary point where the exact Hessian H is indefinite (a saddle:
// a symmetric shape about to buckle) the filtered Newton step barely moves
// along H's negative curvature, and leaving the saddle waits for round-off
// to grow the asymmetry, which is slow (docs/DESIGN.md, "Saddles: FEM's
// negative-curvature step").
// Add the direction of H's most negative curvature relative to the filtered
// matrix H+ just factorised (linalg/negative_curvature.h: power iteration on
// H+^-1 N, N = H+ - H), pointing downhill, one hundredth of the mesh
// diagonal long at its largest vertex move; the line search scales the sum.
// Returns 1 if it did (movable bones: not yet, their border is left out).
int FemSolver::StepSolver::add_negative_curvature() {
  const BlockPattern& P = s_.pattern_;
  std::vector<double> plus = s_.values_;  // H+ as factorised (with any diagonal shift)
  s_.assemble_hessian(x_, act_, true);
  std::vector<double>& filtered_away = s_.values_;  // N = H+ - H: PSD
  for (size_t k = 0; k < plus.size(); ++k) filtered_away[k] = plus[k] - filtered_away[k];
  auto product = [&P](const std::vector<double>& values) {
    return [&P, &values](const Eigen::VectorXd& v, Eigen::VectorXd& y) {
      y.resize(v.size());
      symmetric_upper_product(P.rows(), P.col_ptr().data(), P.row_index().data(), values.data(), v.data(),
                              y.data());
    };
  };
  const CurvatureDirection c = most_negative_curvature(
      gs_.size(), product(filtered_away), product(plus),
      [&](const Eigen::VectorXd& r, Eigen::VectorXd& z) {
        z.resize(r.size());
        s_.factor_.solve(r.data(), z.data(), 1);
      },
      kCurvatureIterations, kCurvatureRtol);
  s_.values_.swap(plus);  // the factorised matrix again
  if (!(c.mu >= kCurvatureMin)) return 0;
  Eigen::VectorXd v = gs_.dot(c.v) > 0 ? Eigen::VectorXd(-c.v) : c.v;
  double largest = 0;
  for (Eigen::Index i = 0; i < v.size() / 3; ++i) largest = std::max(largest, v.segment<3>(3 * i).norm());
  if (!(largest > 0)) return 0;
  ds_ += (kCurvatureLength * bbox_diagonal(s_.model_.rest) / largest) * v;
  return 1;
}

// Projected element Hessians make H PSD; a pinned scene makes it definite.
// Round-off can still break the Cholesky: shift the diagonal and retry.
bool FemSolver::StepSolver::filtered_direction() {
  if (newton_direction(false)) return true;
  const BlockPattern& P = s_.pattern_;
  double shift = 0;
  for (int retry = 0; retry < 8; ++retry) {
    double dmax = 0;
    for (int j = 0; j < P.rows(); ++j) dmax = std::max(dmax, s_.values_[P.col_ptr()[j + 1] - 1]);
    const double add = (shift == 0 ? 1e-10 * dmax : shift * 9.0);
    for (int j = 0; j < P.rows(); ++j) s_.values_[P.col_ptr()[j + 1] - 1] += add;
    shift += add;
    if (newton_direction(false)) return true;
  }
  return false;
}

}  // namespace emu
