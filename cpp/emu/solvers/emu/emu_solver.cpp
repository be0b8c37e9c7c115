#include "emu/solvers/emu/emu_solver.h"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "emu/energy/acap_coupling.h"
#include "emu/energy/gravity_work.h"
#include "emu/energy/inertia.h"
#include "emu/energy/joint_spring.h"
#include "emu/linalg/rotation.h"
#include "emu/model/tet_order.h"
#include "emu/solvers/emu/bone_coarse_space.h"
#include "emu/solvers/emu/bone_rotations.h"
#include "emu/solvers/emu/bone_turn_fits.h"
#include "emu/solvers/emu/constant_schur.h"
#include "emu/solvers/elastic_term.h"
#include "emu/solvers/emu/fit_jacobian.h"
#include "emu/solvers/newton/newton_driver.h"
#include "emu/solvers/newton/lbfgs.h"
#include "emu/solvers/newton/pcg.h"
#include "emu/solvers/newton/rounding_perturbation.h"
#include "emu/solvers/emu/schur_preconditioner.h"
#include "emu/solvers/emu/step_solver.h"
#include "emu/solvers/emu/woodbury.h"

namespace emu {

EmuSolver::EmuSolver(const Model& model, const SolverOptions& options, const EmuSolverOptions& emu_options,
                     PositionTerm contact)
    : model_(along_curve(model)),
      layout_(model_),
      options_(options),
      emu_(emu_options),
      contact_(std::move(contact)) {
  if (!(emu_.alpha > 0) || !std::isfinite(emu_.alpha)) throw std::invalid_argument("alpha must be positive and finite");
  if (emu_.modes < 0) throw std::invalid_argument("the number of modes must be >= 0");
  if (emu_.lbfgs_memory < 1) throw std::invalid_argument("lbfgs_memory must be >= 1");
  if (!(emu_.cg_forcing_min >= 0 && emu_.cg_forcing_min < 1))
    throw std::invalid_argument("cg_forcing_min must lie in [0, 1)");
  if (layout_.num_bones && emu_.step == EmuStep::NewtonKrylov && emu_.preconditioner == EmuPreconditioner::Schur)
    throw std::invalid_argument("the Schur-complement preconditioner does not handle movable bones; "
                                "use preconditioner='woodbury'");
  auto t0 = Clock::now();
  acap_ = std::make_unique<AcapOperator>(model_, layout_);
  jacobian_ = std::make_unique<FitJacobian>(model_, layout_, *acap_);
  factor_seconds_ = seconds_since(t0);
  build_preconditioner();
  tet_energy_.resize(model_.tets.rows());
  if (layout_.num_bones) set_bone_coordinates();
  if (layout_.num_bones && emu_.bone_coarse_space) {  // setup: counted with the factorisations
    t0 = Clock::now();
    turn_fits_ = std::make_unique<BoneTurnFits>(layout_, *jacobian_);
    factor_seconds_ += seconds_since(t0);
  }
  {  // the gradient's round-off at an exact equilibrium (see rest_gradient_per_alpha_)
    LoadCase rest;
    rest.activation = Eigen::VectorXd::Zero(model_.num_muscles);
    rest_gradient_per_alpha_ = cold_gradient_norm(make_context(rest)) / emu_.alpha;
  }
}

void EmuSolver::set_bone_coordinates() {
  std::unique_ptr<BoneForest> forest;
  try {
    forest = std::make_unique<BoneForest>(layout_, bbox_diagonal(model_.rest));
  } catch (const std::invalid_argument& e) {  // a loop or weld: the fit's joint rows hold it
    bone_forest_error_ = e.what();
    bone_coordinates_ = "per bone: " + bone_forest_error_;
    return;
  }
  if (!emu_.joint_coordinates) {
    bone_coordinates_ = "per bone: joint_coordinates is off";
    return;
  }
  // Only a hinge between two moving bones curves the set of joint-consistent
  // rotations; a bone's own turns keep a ball joint, or a hinge on something
  // that does not turn, exactly (a geodesic of SO(3)): such scenes keep them.
  const bool chained_hinge = std::any_of(forest->bones.begin(), forest->bones.end(), [](const BoneForest::Node& B) {
    return B.kind == BoneForest::Kind::Hinge && B.parent >= 0;
  });
  if (!chained_hinge) {
    bone_coordinates_ = "per bone: no hinge joins two movable bones";
    return;
  }
  joints_ = std::make_unique<JointCoordinates>(std::move(*forest), layout_.num_soft);
  bone_coordinates_ = "joint coordinates";
}

void EmuSolver::build_preconditioner() {
  const bool krylov = emu_.step == EmuStep::NewtonKrylov;
  const EmuPreconditioner kind = krylov ? emu_.preconditioner : EmuPreconditioner::Woodbury;
  const auto t0 = Clock::now();
  if (kind == EmuPreconditioner::Schur) {
    preconditioner_ = std::make_unique<SchurPreconditioner>(model_, layout_, *acap_, emu_.alpha);
    factor_seconds_ += seconds_since(t0);
  } else if (kind == EmuPreconditioner::ConstantSchur) {
    preconditioner_ =
        std::make_unique<ConstantSchur>(model_, layout_, *acap_, emu_.alpha, emu_.single_precision_preconditioner);
    factor_seconds_ += seconds_since(t0);
  } else {  // modes only where the Woodbury approximation uses them (leave out what the solve does not need)
    const Modes modes = acap_modes((emu_.modes + 2) / 3);
    modes_seconds_ = seconds_since(t0);
    auto woodbury = std::make_unique<Woodbury>(model_, layout_, *acap_, modes, emu_.alpha);
    modes_ = woodbury->k();
    preconditioner_ = std::move(woodbury);
  }
}

Modes EmuSolver::acap_modes(int ks) const {
  if (!acap_->has_bones()) return lowest_modes(acap_->factor(), std::min(ks, layout_.num_free));
  const auto solve = [&](const double* in, double* out) {
    Eigen::MatrixXd R = Eigen::Map<const Eigen::VectorXd>(in, acap_->dofs());
    Eigen::MatrixXd Z;
    acap_->solve(R, Z);
    Eigen::Map<Eigen::VectorXd>(out, acap_->dofs()) = Z.col(0);
  };
  return lowest_modes_of_inverse(acap_->dofs(), solve, ks, acap_->constraint_rank());
}

std::vector<std::pair<std::string, double>> EmuSolver::structures() const {
  std::vector<std::pair<std::string, double>> out;
  out.emplace_back("ACAP factor", 8.0 * acap_->factor().factor_nnz());
  preconditioner_->add_structures(out);
  if (layout_.num_bones && emu_.bone_coarse_space) {
    // H Z (3 turns per bone and the recycled directions, at most) and the
    // recycled directions' columns of Z over all unknowns, rebuilt every
    // Newton step; Z's turns are the unit-turn fits' follow fields, below
    const double vectors = 3.0 * layout_.num_bones + 2.0 * emu_.recycled_directions;
    out.emplace_back("movable bones and their coarse space", vectors * 9.0 * layout_.num_unknowns * 8);
    out.emplace_back("bones' unit-turn fits", turn_fits_->bytes());
  }
  if (!layout_.joints.empty()) out.emplace_back("joints", sizeof(JointPoint) * double(layout_.joints.size()));
  return out;
}

void EmuSolver::set_alpha(double alpha) {
  if (!(alpha > 0) || !std::isfinite(alpha)) throw std::invalid_argument("alpha must be positive and finite");
  emu_.alpha = alpha;
  preconditioner_->set_alpha(alpha);
}

void EmuSolver::set_cg_forcing_max(double eta_max) {
  if (!(eta_max > 0 && eta_max < 1)) throw std::invalid_argument("cg_forcing_max must lie in (0, 1)");
  emu_.cg_forcing_max = eta_max;
}

EmuSolver::Context EmuSolver::make_context(const LoadCase& load) const {
  validate_load(model_, load);
  Context c;
  c.act = tet_activation(model_, load);
  c.x_pinned = pinned_positions(model_, load);
  Eigen::MatrixX3d f = Eigen::MatrixX3d::Zero(model_.rest.rows(), 3);
  for (Eigen::Index v = 0; v < c.x_pinned.rows(); ++v)
    if (layout_.moves(v)) {
      c.x_pinned.row(v).setZero();
      f.row(v) = gravity_work::vertex_gradient(layout_.lumped_mass(v), load.gravity).transpose();
    }
  deformation_gradients(layout_, model_.tets, c.x_pinned, c.F_pinned);
  c.h = acap_->joint_targets(pinned_positions(model_, load), load.joint_targets);
  c.gravity = load.gravity;
  c.has_gravity = load.gravity.squaredNorm() > 0;
  if (load.inertia_weight > 0) {
    // on the vertices that move with F (free, or on a movable bone), as gravity
    c.inertia_weight = load.inertia_weight;
    c.inertia_target = load.inertia_target;
    c.inertia_hessian = inertia::diagonal_hessian(layout_.lumped_mass, c.inertia_weight,
                                                  [&](Eigen::Index v) { return layout_.moves(v); });
  }
  if (c.has_gravity) {
    // d W(x*(F)) / dF = C^T K_c^-1 S^T f: one constant solve per load.
    jacobian_->force_fit(f, c.F_gravity);
  }
  return c;
}

void EmuSolver::fit_into(const Context& c, const Mat9X& F, Eigen::MatrixX3d& x, Mat9X& Fx) const {
  Mat9X buf;
  x = c.x_pinned;
  acap_->fit(per_tet_view(layout_, F, buf), &c.F_pinned, &c.h, x);
  deformation_gradients(layout_, model_.tets, x, Fx);
}

void EmuSolver::fit_linear_into(const Mat9X& D, Eigen::MatrixX3d& dx, Mat9X& Fd) const { jacobian_->apply(D, dx, Fd); }

void EmuSolver::project_tangent(const Mat9X& F, Mat9X& v) const {
  if (joints_) joints_->project(F, v);
  else bone_rotations::project_tangent(F, layout_.num_soft, v);
}

void EmuSolver::retract(const Mat9X& F, const Mat9X& d, double s, Mat9X& out) const {
  if (joints_) joints_->retract(F, d, s, out);
  else bone_rotations::retract(F, d, s, layout_.num_soft, out);
}

void EmuSolver::riemannian_product(const std::vector<Mat9>& A, const Mat9X& F, const Mat9X& g, const Mat9X& v,
                                   bool curvature, Mat9X& out) const {
  hessian_product_into(A, v, out);
  riemannian_bone_columns(F, g, v, curvature, out);
}

void EmuSolver::riemannian_bone_columns(const Mat9X& F, const Mat9X& g, const Mat9X& v, bool curvature,
                                        Mat9X& out) const {
  if (!joints_) {
    bone_rotations::riemannian_columns(F, g, v, curvature, layout_.num_soft, model_.bone_stiffness, out);
    return;
  }
  // In joint coordinates the whole rotation term (SO(3)'s, the chain's, the
  // springs' through g) is one small matrix, clamped PSD for the filtered model.
  joints_->project(F, out);
  joints_->add_rotation_product(F, joints_->rotation_term(F, g, !curvature), v, out);
}

double EmuSolver::total_energy(const Context& c, const Mat9X& F, const Mat9X& Fx, const Eigen::MatrixX3d& x) const {
  return energy_along(c, F, Fx, nullptr, nullptr, 0.0) - load_work(c, x) + position_energy(c, x);
}

double EmuSolver::energy_along(const Context& c, const Mat9X& F, const Mat9X& Fx, const Mat9X* D,
                               const Mat9X* Fd, double s) const {
  const Eigen::Index m = model_.tets.rows();
  const ElasticTerm elastic(model_, layout_, c.act);
  const auto& wv = acap_->weight_volume();
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    const int u = layout_.tet_unknown(t);
    Vec9 f = F.col(u), fx = Fx.col(t);
    if (D) {
      f += s * D->col(u);
      fx += s * Fd->col(t);
    }
    tet_energy_[t] = elastic.energy(t, unflatten(f)) + acap_coupling::energy(f, fx, emu_.alpha, wv(t));
  }
  double E = 0;
  for (Eigen::Index t = 0; t < m; ++t) E += tet_energy_[t];
  for (int b = 0; b < model_.bone_stiffness.size(); ++b) {
    const int u = layout_.num_soft + b;
    const Mat3 Fb = unflatten(D ? Vec9(F.col(u) + s * D->col(u)) : Vec9(F.col(u)));
    E += joint_spring::energy(Fb, model_.bone_stiffness(b));
  }
  return E;
}

void EmuSolver::gradient_into(const Context& c, const Mat9X& F, const Mat9X& Fx, Mat9X& g) const {
  const Eigen::Index m = model_.tets.rows();
  const ElasticTerm elastic(model_, layout_, c.act);
  const auto& V = layout_.geometry.volume;
  const auto& wv = acap_->weight_volume();
  Mat9X per_tet(9, m);
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    const auto Fu = F.col(layout_.tet_unknown(t));
    Vec9 gt = acap_coupling::gradient(Fu, Fx.col(t), emu_.alpha, wv(t));
    if (elastic.active(t)) gt += V(t) * flatten(elastic.stress(t, unflatten(Fu)));
    if (c.has_gravity) gt -= wv(t) * c.F_gravity.col(t);
    per_tet.col(t) = gt;
  }
  reduce_to_unknowns(layout_, per_tet, g);
  for (int b = 0; b < model_.bone_stiffness.size(); ++b)
    g.col(layout_.num_soft + b) += flatten(joint_spring::gradient(model_.bone_stiffness(b)));
}

void EmuSolver::blocks_into(const Context& c, const Mat9X& F, std::vector<Mat9>* A,
                            std::vector<Mat9>* A_exact) const {
  // A_u = V_t d2Psi/dF2 + d2E_C/dF2 (alpha w_t V_t I): PSD-filtered (A) and/or
  // unfiltered (A_exact); a bone's block is the coupling of all its tets
  // (rigid: no material).
  const EigenFilter filter = options_.eigen_filter;
  const ElasticTerm elastic(model_, layout_, c.act);
  const int nu = layout_.num_unknowns, ns = layout_.num_soft;
  const auto& V = layout_.geometry.volume;
  const auto& wv = acap_->weight_volume();
  if (A) A->resize(nu);
  if (A_exact) A_exact->resize(nu);
  for (int u = ns; u < nu; ++u) {
    double w = 0;
    for (int i = layout_.unknown_ptr[u]; i < layout_.unknown_ptr[u + 1]; ++i) w += wv(layout_.unknown_tets[i]);
    const Mat9 Ab = acap_coupling::hessian_diagonal(emu_.alpha, w) * Mat9::Identity();
    if (A) (*A)[u] = Ab;
    if (A_exact) (*A_exact)[u] = Ab;
  }
#pragma omp parallel for schedule(static)
  for (int u = 0; u < ns; ++u) {
    const int t = layout_.unknown_tets[u];
    Mat9 H_psd, H;
    elastic.hessians(t, unflatten(F.col(u)), filter, A ? &H_psd : nullptr, A_exact ? &H : nullptr);
    const double coupling = acap_coupling::hessian_diagonal(emu_.alpha, wv(t));
    if (A) {
      (*A)[u] = V(t) * H_psd;
      (*A)[u].diagonal().array() += coupling;
    }
    if (A_exact) {
      (*A_exact)[u] = V(t) * H;
      (*A_exact)[u].diagonal().array() += coupling;
    }
  }
}

void EmuSolver::hessian_product_into(const std::vector<Mat9>& A, const Mat9X& v, Mat9X& out) const {
  // H v = A v - alpha C^T K_c^-1 C v, and C^T K_c^-1 C v = w V F_t(x*(v)) with x*(v)
  // the homogeneous fit: one back-substitution.
  Eigen::MatrixX3d dx;
  Mat9X Fd;
  fit_linear_into(v, dx, Fd);
  hessian_product_from_fit(A, v, Fd, out);
}

void EmuSolver::hessian_product_from_fit(const std::vector<Mat9>& A, const Mat9X& v, const Mat9X& Fd,
                                         Mat9X& out) const {
  const auto& wv = acap_->weight_volume();
  const Eigen::Index m = model_.tets.rows();
  if (layout_.num_bones == 0) {  // one unknown per tet: one fused pass
    out.resize(9, m);
#pragma omp parallel for schedule(static)
    for (Eigen::Index t = 0; t < m; ++t) out.col(t) = A[t].lazyProduct(v.col(t)) - (emu_.alpha * wv(t)) * Fd.col(t);
    return;
  }
  // A soft unknown is one tet; a bone sums the fit's pull over its tets (in
  // the layout's order, as reduce_to_unknowns): one pass, no per-tet copy.
  const int ns = layout_.num_soft, nu = layout_.num_unknowns;
  const double alpha = emu_.alpha;
  out.resize(9, nu);
#pragma omp parallel for schedule(static)
  for (int u = 0; u < ns; ++u) {
    const int t = layout_.unknown_tets[layout_.unknown_ptr[u]];
    out.col(u) = A[u].lazyProduct(v.col(u)) - (alpha * wv(t)) * Fd.col(t);
  }
  for (int u = ns; u < nu; ++u) {
    Vec9 pull = Vec9::Zero();
    for (int i = layout_.unknown_ptr[u]; i < layout_.unknown_ptr[u + 1]; ++i) {
      const int t = layout_.unknown_tets[i];
      pull += (alpha * wv(t)) * Fd.col(t);
    }
    out.col(u) = A[u].lazyProduct(v.col(u)) - pull;
  }
}

Mat9X EmuSolver::to_cols(const Eigen::MatrixXd& rows) const {
  if (rows.rows() != layout_.num_unknowns || rows.cols() != 9)
    throw std::invalid_argument("expected a #unknowns by 9 array (one vec(F) per soft tet, then per bone; " +
                                std::to_string(layout_.num_unknowns) + " rows), got " +
                                std::to_string(rows.rows()) + " by " + std::to_string(rows.cols()));
  if (!rows.allFinite()) throw std::invalid_argument("deformation gradients contain NaN or infinite values");
  return rows.transpose();
}

double EmuSolver::position_energy(const Context& c, const Eigen::MatrixX3d& x) const {
  double E = contact_energy(x);
  if (c.inertia_weight > 0)  // the vertices that move with F only
    E += inertia::energy(layout_.lumped_mass, x, c.inertia_target, c.inertia_weight,
                         [&](Eigen::Index v) { return layout_.moves(v); });
  return E;
}

Eigen::SparseMatrix<double> EmuSolver::position_hessian(const Context& c, const Eigen::MatrixX3d& x) const {
  if (!has_contact()) return c.inertia_hessian;
  Eigen::SparseMatrix<double> H = contact_.checked_hessian(x);
  if (c.inertia_weight > 0) H += c.inertia_hessian;
  return H;
}

void EmuSolver::add_position_gradient(const Context& c, const Eigen::MatrixX3d& x, Mat9X& g) const {
  if (!has_position_terms(c)) return;
  Eigen::MatrixX3d gx = has_contact() ? contact_.checked_gradient(x) : Eigen::MatrixX3d::Zero(x.rows(), 3);
  if (c.inertia_weight > 0)
    for (Eigen::Index v = 0; v < x.rows(); ++v)
      if (layout_.moves(v))
        gx.row(v) += inertia::vertex_gradient(layout_.lumped_mass(v), x.row(v).transpose(),
                                              c.inertia_target.row(v).transpose(), c.inertia_weight)
                         .transpose();
  if (gx.isZero(0.0)) return;
  Mat9X gF;
  jacobian_->transpose_apply(gx, gF);
  g += gF;
}

double EmuSolver::load_work(const Context& c, const Eigen::MatrixX3d& x) const {
  return c.has_gravity ? gravity_work::energy(layout_.lumped_mass, x, c.gravity) : 0.0;
}

double EmuSolver::gradient_floor(const Context& c) const {
  // 1e-13 of the summed moduli V (alpha w + mu + lambda + a) of the soft tets:
  // round-off in P(F) scales with lambda, in the coupling with alpha w. A bone
  // unknown's gradient sums its tets' coupling terms, whose round-off errors
  // add like random ones: the root of their summed squares (their plain sum
  // would make the floor the stopping test at large alpha; docs/DESIGN.md,
  // "Stopping and round-off").
  double soft = 0, bone_sq = 0;
  for (Eigen::Index t = 0; t < model_.tets.rows(); ++t) {
    const double v = layout_.geometry.volume(t);
    if (layout_.is_bone_tet(t))
      bone_sq += std::pow(v * emu_.alpha * model_.acap_weight(t), 2);
    else
      soft += v * (emu_.alpha * model_.acap_weight(t) + model_.mu(t) + model_.lambda(t) + c.act(t));
  }
  return 1e-13 * (soft + std::sqrt(bone_sq));
}

double EmuSolver::cold_gradient_norm(const Context& c) const {
  Mat9X F = start_unknowns(nullptr);
  if (joints_) joints_->project_onto_joints(F, c.h);
  Eigen::MatrixX3d x;
  Mat9X Fx, g;
  fit_into(c, F, x, Fx);
  gradient_into(c, F, Fx, g);
  if (layout_.num_bones) project_tangent(F, g);
  return g.norm();
}

Mat9X EmuSolver::start_unknowns(const Eigen::MatrixXd* F0) const {
  const int nu = layout_.num_unknowns;
  Mat9X F(9, nu);
  if (!F0) {
    for (int u = 0; u < nu; ++u) F.col(u) = flatten(Mat3::Identity());
    return F;
  }
  const Eigen::Index count = model_.scene_tet_count();
  if (F0->rows() != count || F0->cols() != 9)
    throw std::invalid_argument("the start F must be one F per tet of the scene (" + std::to_string(count) +
                                " by 9, F row-major per row), got " + std::to_string(F0->rows()) + " by " +
                                std::to_string(F0->cols()));
  if (!F0->allFinite()) throw std::invalid_argument("the start F contains NaN or infinite values");
  // a row holds F row-major: vec(F^T) column-major
  for (int u = 0; u < nu; ++u) {
    const Eigen::Index row = model_.scene_index(layout_.unknown_tets[layout_.unknown_ptr[u]]);
    F.col(u) = flatten(unflatten(F0->row(row).transpose()).transpose());
  }
  for (int u = layout_.num_soft; u < nu; ++u) F.col(u) = flatten(nearest_rotation(unflatten(F.col(u))));
  return F;
}

Eigen::MatrixXd EmuSolver::scene_rows(const Mat9X& F) const {
  Eigen::MatrixXd rows(model_.scene_tet_count(), 9);
  rows.rowwise() = Eigen::RowVectorXd::Map(Mat3::Identity().eval().data(), 9);  // tets without unknowns
  for (Eigen::Index t = 0; t < model_.tets.rows(); ++t)  // F row-major: vec(F^T)
    rows.row(model_.scene_index(t)) = flatten(unflatten(F.col(layout_.tet_unknown(t))).transpose()).transpose();
  return rows;
}

void EmuSolver::base_precondition(const Mat9X& F, const Mat9X& in, Mat9X& out) const {
  preconditioner_->apply(in, out);
  if (layout_.num_bones) project_tangent(F, out);
}

// One EMU solve as the Newton driver sees it. The iterate is F (9 x
// #unknowns) with its fit x = x*(F), Fx = F_t(x), the Euclidean gradient g and
// the Riemannian one gR (bone columns projected to the tangent space).
class EmuSolver::NewtonProblem {
 public:
  NewtonProblem(EmuSolver& s, const Context& c, Mat9X F)
      : s_(s),
        c_(c),
        bones_(s.layout_.num_bones > 0),
        F_(std::move(F)),
        step_(s, c, F_, g_, gR_, gn_, g0_, d_) {
    s_.fit_into(c_, F_, x_, Fx_);
    E_ = s_.total_energy(c_, F_, Fx_, x_);
    if (s_.has_contact()) s_.contact_.check_start_state(x_, E_);
    update_gradient();
  }

  double energy() const { return E_; }
  double grad_norm() const { return gn_; }
  /// The fit of the current iterate.
  const Eigen::MatrixX3d& positions() const { return x_; }
  const std::vector<NeutralMode>& neutral_modes() const { return step_.neutral_modes(); }

  // A step's direction (StepSolver: the blocks, the preconditioner, the bone
  // coarse space, the step's kind and a descent check), its fit along the
  // line, and a cap where contact's collision detection allows less than the
  // full step.
  SearchDirection direction(int it, PhaseTimes& time) {
    SearchDirection dir;
    const bool exact = exact_allowed_ && exact_ok_;
    if (exact_allowed_ && !exact) ++dir.filtered;
    if (!step_.direction(it, exact, x_, dir, time)) return dir;
    {
      ScopedSeconds timer(time.linear_solve);  // the direction's fit
      prepare_line();
    }
    if (s_.has_contact() && !cap_at_contact(dir, time)) return dir;
    exact_step_ = exact;
    dir_cg_ = dir.cg_iterations;
    return dir;
  }

  double trial_energy(double s) {
    trial_s_ = s;
    if (!bones_) {
      // total_energy along the straight line F + s d: its fit and the load's work are linear in s
      const double E = s_.energy_along(c_, F_, Fx_, &d_, &Fd_, s) - Wx_ - s * Wdx_;
      return s_.has_position_terms(c_) ? E + s_.position_energy(c_, x_ + s * dx_) : E;
    }
    s_.retract(F_, d_, s, Ftrial_);
    s_.fit_into(c_, Ftrial_, xtrial_, Fxtrial_);
    // the fit's path along a bone's retraction is not straight: its CCD is checked per trial
    if (s_.has_contact() && s_.contact_.max_step(x_, xtrial_) < 1.0)
      return std::numeric_limits<double>::infinity();
    return s_.total_energy(c_, Ftrial_, Fxtrial_, xtrial_);
  }

  double trial_grad_norm() {
    Mat9X g1;
    if (bones_) {  // the retracted trial point and its fit, from trial_energy
      s_.gradient_into(c_, Ftrial_, Fxtrial_, g1);
      s_.add_position_gradient(c_, xtrial_, g1);
      s_.project_tangent(Ftrial_, g1);
    } else {
      const Mat9X F1 = F_ + trial_s_ * d_, Fx1 = Fx_ + trial_s_ * Fd_;
      s_.gradient_into(c_, F1, Fx1, g1);
      if (s_.has_position_terms(c_)) s_.add_position_gradient(c_, x_ + trial_s_ * dx_, g1);
    }
    return g1.norm();
  }

  double take_step(int it, double s, double E_trial) {
    if (bones_) {
      if (s != trial_s_) trial_energy(s);  // the driver steps to its last trial point: reuse its fit
      F_.swap(Ftrial_);
      x_.swap(xtrial_);
      Fx_.swap(Fxtrial_);
      E_ = E_trial;
    } else if (it % 50 == 0) {  // x*(F) is linear in F; refit now and then against drift
      F_ += s * d_;
      s_.fit_into(c_, F_, x_, Fx_);
      E_ = s_.total_energy(c_, F_, Fx_, x_);
    } else {
      F_ += s * d_;
      x_ += s * dx_;
      Fx_ += s * Fd_;
      E_ = E_trial;
    }
    // L-BFGS's pair of this step: s d (tangent at the old bones) and the change of
    // the tangent gradient (no vector transport: the bones turn little per step)
    const Mat9X g_old = s_.emu_.step == EmuStep::Lbfgs ? gR_ : Mat9X();
    update_gradient();
    step_.stepped(s, dir_cg_, s_.emu_.step == EmuStep::Lbfgs ? Mat9X(gR_ - g_old) : Mat9X());
    // CG on an indefinite exact Hessian need not meet negative curvature: its
    // step can be long and mostly cut by the line search. After such a step
    // (s < 1/2) the filtered Hessian is used until a full step is taken again,
    // as FEM does after a failed Cholesky.
    if (exact_allowed_) exact_ok_ = exact_step_ ? s >= 0.5 : s == 1.0;
    return E_;
  }

  /// The solve's output: positions of the final fit and F per tet.
  void finish(SolveResult& res) {
    res.set_neutral_modes(neutral_modes());
    s_.fit_into(c_, F_, x_, Fx_);
    res.positions = x_;
    res.F = s_.scene_rows(F_);
  }

 private:
  // Without bones x*(F + s d) = x + s dx: one fit per direction. A bone's
  // path R + s d is retracted to rotations, so each trial refits.
  void prepare_line() {
    if (bones_) return;
    s_.fit_linear_into(d_, dx_, Fd_);
    Wx_ = s_.load_work(c_, x_);
    Wdx_ = s_.load_work(c_, dx_);
  }

  // Contact: d_ scaled to the largest collision-free step when that is < 1.
  // False: dir has failed (no step is free).
  bool cap_at_contact(SearchDirection& dir, PhaseTimes& time) {
    ScopedSeconds timer(time.line_search);
    const double smax = collision_free_step();
    if (!(smax > 0)) {
      dir.fail("contact: continuous collision detection allows no step along the Newton direction "
               "(surfaces touching; a larger contact distance may help)");
      return false;
    }
    if (smax < 1) {
      d_ *= smax;
      dir.slope *= smax;
      if (!bones_) {
        dx_ *= smax;
        Fd_ *= smax;
        Wdx_ *= smax;
      }
    }
    return true;
  }

  // Contact: the largest step s <= 1 along d_ whose fitted positions' straight
  // path creates no intersection (without bones x*(F + s d) = x + s dx exactly).
  double collision_free_step() {
    if (!bones_) return s_.contact_.max_step(x_, x_ + dx_);
    Mat9X F1, Fx1;
    Eigen::MatrixX3d x1;
    s_.retract(F_, d_, 1.0, F1);
    s_.fit_into(c_, F1, x1, Fx1);
    return s_.contact_.max_step(x_, x1);
  }
 public:
  /// The round-off of grad_norm() here: |gR(F') - gR(F)| / sqrt 2, F' = F
  /// moved by one rounding per entry, both from a fresh fit (two samples of
  /// the rounding errors). With bones the fit's conditioning lifts it far
  /// above gradient_floor's scale bound; there the iterate's own fit is fresh
  /// (take_step swaps in the trial's), without bones it is updated linearly.
  double gradient_noise() {
    Mat9X g, g1, F1 = F_;
    perturb_by_rounding(F1);
    if (bones_) g = gR_;
    else riemannian_gradient_at(F_, g);
    riemannian_gradient_at(F1, g1);
    return (g1 - g).norm() / std::sqrt(2.0);
  }

 private:
  // The gradient at F with its fit (x, Fx), contact included (Euclidean).
  void gradient_with_fit(const Mat9X& F, const Eigen::MatrixX3d& x, const Mat9X& Fx, Mat9X& g) const {
    s_.gradient_into(c_, F, Fx, g);
    s_.add_position_gradient(c_, x, g);
  }
  void riemannian_gradient_at(const Mat9X& F, Mat9X& g) const {
    Eigen::MatrixX3d x;
    Mat9X Fx;
    s_.fit_into(c_, F, x, Fx);
    gradient_with_fit(F, x, Fx, g);
    if (bones_) s_.project_tangent(F, g);
  }
  void update_gradient() {
    gradient_with_fit(F_, x_, Fx_, g_);
    gR_ = g_;
    if (bones_) s_.project_tangent(F_, gR_);
    gn_ = gR_.norm();
    if (g0_ < 0) g0_ = gn_;
  }

  EmuSolver& s_;
  const Context& c_;
  const bool bones_;
  const bool exact_allowed_ = s_.options_.exact_when_definite && s_.emu_.step == EmuStep::NewtonKrylov;
  Mat9X F_, Fx_, g_, gR_, d_, Fd_, Ftrial_, Fxtrial_;
  Eigen::MatrixX3d x_, dx_, xtrial_;
  double E_ = 0, gn_ = 0, g0_ = -1, Wx_ = 0, Wdx_ = 0, trial_s_ = -1;
  bool exact_ok_ = true, exact_step_ = false;
  int dir_cg_ = 0;
  StepSolver step_;  // after the members it reads
};

SolveResult EmuSolver::solve(const LoadCase& load, const Eigen::MatrixXd* F0) {
  const auto t0 = Clock::now();
  const Context c = make_context(load);
  preconditioner_->set_inertia(c.inertia_weight);  // (a new step size factorises S0 again)
  Mat9X start = start_unknowns(F0);
  if (joints_) joints_->project_onto_joints(start, c.h);
  NewtonProblem newton(*this, c, std::move(start));
  SolveResult res;
  // A warm start's step-test gate on the cold start's scale (newton_minimize);
  // without contact (its terms need not be defined at rest under these pins).
  const double cold_g0 =
      F0 && options_.step_tol > 0 && options_.step_tol_cold_scale && !has_contact() ? cold_gradient_norm(c) : 0.0;
  newton_minimize(newton, options_, gradient_floor(c), t0, res, 10.0 * rest_gradient_per_alpha_ * emu_.alpha,
                  cold_g0);
  newton.finish(res);
  res.time_s = seconds_since(t0);
  return res;
}

}  // namespace emu
