#include "emu/solvers/emu/emu_solver_testing.h"

#include <stdexcept>
#include <string>

#include "emu/solvers/emu/constant_schur.h"
#include "emu/solvers/emu/schur_preconditioner.h"

namespace emu {

double EmuSolverTesting::energy(const EmuSolver& s, const LoadCase& load, const Eigen::MatrixXd& Frows) {
  const EmuSolver::Context c = s.make_context(load);
  const Mat9X F = s.to_cols(Frows);
  Eigen::MatrixX3d x;
  Mat9X Fx;
  s.fit_into(c, F, x, Fx);
  return s.energy_along(c, F, Fx, nullptr, nullptr, 0.0) - s.load_work(c, x) + s.position_energy(c, x);
}

Eigen::MatrixXd EmuSolverTesting::gradient(const EmuSolver& s, const LoadCase& load, const Eigen::MatrixXd& Frows) {
  const EmuSolver::Context c = s.make_context(load);
  const Mat9X F = s.to_cols(Frows);
  Eigen::MatrixX3d x;
  Mat9X Fx, g;
  s.fit_into(c, F, x, Fx);
  s.gradient_into(c, F, Fx, g);
  s.add_position_gradient(c, x, g);
  return g.transpose();
}

Eigen::MatrixX3d EmuSolverTesting::fit_positions(const EmuSolver& s, const LoadCase& load,
                                                 const Eigen::MatrixXd& Frows) {
  const EmuSolver::Context c = s.make_context(load);
  Eigen::MatrixX3d x;
  Mat9X Fx;
  s.fit_into(c, s.to_cols(Frows), x, Fx);
  return x;
}

Eigen::MatrixXd EmuSolverTesting::hessian_product(const EmuSolver& s, const LoadCase& load,
                                                  const Eigen::MatrixXd& Frows, const Eigen::MatrixXd& Vrows,
                                                  bool exact) {
  const EmuSolver::Context c = s.make_context(load);
  std::vector<Mat9> A, A_exact;
  const Mat9X F = s.to_cols(Frows), V = s.to_cols(Vrows);
  s.blocks_into(c, F, &A, &A_exact);
  Mat9X out;
  s.hessian_product_into(exact ? A_exact : A, V, out);
  if (s.has_position_terms(c)) {  // J^T H_x J v at the fit of F (contact, inertia)
    Eigen::MatrixX3d x;
    Mat9X Fx;
    s.fit_into(c, F, x, Fx);
    s.jacobian_->add_hessian_product(s.position_hessian(c, x), V, out);
  }
  return out.transpose();
}

Eigen::MatrixXd EmuSolverTesting::riemannian_hessian_product(const EmuSolver& s, const LoadCase& load,
                                                             const Eigen::MatrixXd& Frows,
                                                             const Eigen::MatrixXd& Vrows, bool exact) {
  const EmuSolver::Context c = s.make_context(load);
  std::vector<Mat9> A, A_exact;
  const Mat9X F = s.to_cols(Frows);
  Mat9X V = s.to_cols(Vrows), x_F, g, out;
  s.project_tangent(F, V);
  s.blocks_into(c, F, &A, &A_exact);
  Eigen::MatrixX3d x;
  s.fit_into(c, F, x, x_F);
  s.gradient_into(c, F, x_F, g);
  s.riemannian_product(exact ? A_exact : A, F, g, V, exact, out);
  return out.transpose();
}

Eigen::MatrixXd EmuSolverTesting::project_tangent(const EmuSolver& s, const Eigen::MatrixXd& Frows,
                                                  const Eigen::MatrixXd& Vrows) {
  Mat9X V = s.to_cols(Vrows);
  s.project_tangent(s.to_cols(Frows), V);
  return V.transpose();
}

Eigen::MatrixXd EmuSolverTesting::retract(const EmuSolver& s, const Eigen::MatrixXd& Frows,
                                          const Eigen::MatrixXd& Drows, double step) {
  Mat9X out;
  s.retract(s.to_cols(Frows), s.to_cols(Drows), step, out);
  return out.transpose();
}

Eigen::MatrixXd EmuSolverTesting::block_hessians(const EmuSolver& s, const LoadCase& load,
                                                 const Eigen::MatrixXd& Frows, bool exact) {
  const EmuSolver::Context c = s.make_context(load);
  std::vector<Mat9> A_filtered, A_exact;
  s.blocks_into(c, s.to_cols(Frows), &A_filtered, &A_exact);
  const std::vector<Mat9>& A = exact ? A_exact : A_filtered;
  Eigen::MatrixXd out(A.size(), 81);
  for (size_t t = 0; t < A.size(); ++t) out.row(t) = Eigen::Map<const Eigen::Matrix<double, 1, 81>>(A[t].data());
  return out;
}

Eigen::MatrixXd EmuSolverTesting::woodbury_solve(const EmuSolver& s, const LoadCase& load,
                                                 const Eigen::MatrixXd& Frows, const Eigen::MatrixXd& Rrows) {
  const EmuSolver::Context c = s.make_context(load);
  std::vector<Mat9> A;
  s.blocks_into(c, s.to_cols(Frows), &A, nullptr);
  Woodbury w = woodbury_of(s);  // a copy: the solver's own is left as it was
  w.update(A);
  if (!w.low_rank_term()) throw std::runtime_error("Woodbury system X is not positive definite");
  Mat9X out;
  w.apply(s.to_cols(Rrows), out);
  return out.transpose();
}

template <class Preconditioner>
Eigen::MatrixXd EmuSolverTesting::preconditioner_solve(EmuSolver& s, Preconditioner& pc, const LoadCase& load,
                                                       const Eigen::MatrixXd& Frows, const Eigen::MatrixXd& Rrows,
                                                       const char* not_spd) {
  const EmuSolver::Context c = s.make_context(load);
  std::vector<Mat9> A;
  s.blocks_into(c, s.to_cols(Frows), &A, nullptr);
  if (!pc.update(A)) throw std::runtime_error(not_spd);
  Mat9X out;
  pc.apply(s.to_cols(Rrows), out);
  return out.transpose();
}

Eigen::MatrixXd EmuSolverTesting::schur_solve(EmuSolver& s, const LoadCase& load, const Eigen::MatrixXd& Frows,
                                              const Eigen::MatrixXd& Rrows) {
  auto* pc = dynamic_cast<SchurPreconditioner*>(s.preconditioner_.get());
  if (!pc) throw std::invalid_argument("this solver has no Schur-complement preconditioner (preconditioner='schur')");
  return preconditioner_solve(s, *pc, load, Frows, Rrows, "the Schur complement S is not positive definite");
}

Eigen::MatrixXd EmuSolverTesting::constant_schur_solve(EmuSolver& s, const LoadCase& load,
                                                       const Eigen::MatrixXd& Frows, const Eigen::MatrixXd& Rrows) {
  auto* pc = dynamic_cast<ConstantSchur*>(s.preconditioner_.get());
  if (!pc) throw std::invalid_argument("this solver has no constant Schur preconditioner (preconditioner='constant-schur')");
  pc->set_inertia(load.inertia_weight);
  return preconditioner_solve(s, *pc, load, Frows, Rrows,
                              "a filtered Hessian block is not positive definite");
}

double EmuSolverTesting::constant_schur_inertia(const EmuSolver& s) {
  auto* pc = dynamic_cast<const ConstantSchur*>(s.preconditioner_.get());
  if (!pc) throw std::invalid_argument("this solver has no constant Schur preconditioner (preconditioner='constant-schur')");
  return pc->inertia();
}

Woodbury& EmuSolverTesting::woodbury_of(const EmuSolver& s) {
  auto* w = dynamic_cast<Woodbury*>(s.preconditioner_.get());
  if (!w) throw std::invalid_argument("this solver has no Woodbury preconditioner (preconditioner='woodbury')");
  return *w;
}

template <int N>
std::array<std::pair<Eigen::MatrixXd, Eigen::MatrixXd>, N> EmuSolverTesting::turns_at(const EmuSolver& s,
                                                                                      const LoadCase& load,
                                                                                      const Eigen::MatrixXd& Frows,
                                                                                      int bone,
                                                                                      const std::array<Mat3, N>& M,
                                                                                      bool exact) {
  const int bones = s.turn_fits_ ? s.turn_fits_->bones() : 0;
  if (bone < 0 || bone >= bones)
    throw std::invalid_argument("bone_turn: bone " + std::to_string(bone) + " is not a movable bone of a solver " +
                                "with the bone coarse space (" + std::to_string(bones) + " such bones)");
  const EmuSolver::Context c = s.make_context(load);
  std::vector<Mat9> A, A_exact;
  s.blocks_into(c, s.to_cols(Frows), &A, &A_exact);
  std::array<Mat9X, N> Z, HZ;  // the coarse space's path
  s.turn_fits_->turns<N>(exact ? A_exact : A, bone, M, s.emu_.alpha, s.acap_->weight_volume(), Z, HZ);
  std::array<std::pair<Eigen::MatrixXd, Eigen::MatrixXd>, N> out;
  for (int k = 0; k < N; ++k) out[k] = {Z[k].transpose(), HZ[k].transpose()};
  return out;
}

std::pair<Eigen::MatrixXd, Eigen::MatrixXd> EmuSolverTesting::bone_turn(const EmuSolver& s, const LoadCase& load,
                                                                        const Eigen::MatrixXd& F, int bone,
                                                                        const Eigen::Matrix3d& M, bool exact) {
  return turns_at<1>(s, load, F, bone, {M}, exact)[0];
}

std::array<std::pair<Eigen::MatrixXd, Eigen::MatrixXd>, 3> EmuSolverTesting::bone_turns(
    const EmuSolver& s, const LoadCase& load, const Eigen::MatrixXd& F, int bone,
    const std::array<Eigen::Matrix3d, 3>& M, bool exact) {
  return turns_at<3>(s, load, F, bone, M, exact);
}

}  // namespace emu
