#include "emu/solvers/fem/fem_solver.h"
#include "emu/solvers/fem/fem_solver_testing.h"
#include "emu/solvers/fem/step_solver.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>

#include "emu/energy/gravity_work.h"
#include "emu/energy/inertia.h"
#include "emu/solvers/elastic_term.h"
#include "emu/linalg/negative_curvature.h"
#include "emu/model/tet_order.h"
#include "emu/linalg/symmetric_product.h"
#include "emu/solvers/newton/pcg.h"
#include "emu/solvers/newton/newton_driver.h"
#include "emu/solvers/newton/rounding_perturbation.h"

namespace emu {

namespace {
// SolverOptions::lagged_refresh: a PCG solve on the lagged factor ages it past
// max(kRefreshMin, flops / (kRefreshFlopsPerEntry nnz)) iterations, about half
// of what a numeric factorisation costs in PCG iterations (one iteration
// streams the factor twice; a factorisation's BLAS-3 rate grows with its
// supernodes). Measured on fusiform_20k and fusiform_80k (flops / nnz 360 and
// 787), where a factorisation cost 15-17 iterations: docs/DESIGN.md, "The FEM
// baselines: a factorisation per step, or a lagged factor".
constexpr int kRefreshMin = 8;
constexpr double kRefreshFlopsPerEntry = 80.0;

int aged_after_iterations(const CholmodFactor& f) {
  const double nnz = f.factor_nnz();
  if (!(nnz > 0)) return kRefreshMin;
  return std::max(kRefreshMin, static_cast<int>(f.factorization_flops() / (kRefreshFlopsPerEntry * nnz)));
}
}  // namespace

FemSolver::FemSolver(const Model& model, const SolverOptions& options, PositionTerm contact)
    : model_(along_curve(model)),
      layout_(model_),
      options_(options),
      contact_(std::move(contact)),
      pattern_(model_.tets, layout_.free_index, layout_.num_free, 3),
      bones_(model_, layout_) {
  const auto t0 = Clock::now();
  factor_.analyze(pattern_.rows(), pattern_.col_ptr().data(), pattern_.row_index().data());
  refresh_iterations_ = aged_after_iterations(factor_);
  const Eigen::Index m = model_.tets.rows();
  element_.resize(m * 144);
  values_.resize(pattern_.nnz());
  diagonal_.assign(pattern_.rows(), -1);
  for (int j = 0; j < pattern_.rows(); ++j)
    for (int k = pattern_.col_ptr()[j]; k < pattern_.col_ptr()[j + 1]; ++k)
      if (pattern_.row_index()[k] == j) diagonal_[j] = k;
  corner_.resize(m * 12);
  tet_energy_.resize(m);
  setup_seconds_ = seconds_since(t0);
}

std::vector<std::pair<std::string, double>> FemSolver::structures() const {
  std::vector<std::pair<std::string, double>> out;
  out.emplace_back("Hessian factor", 8.0 * factor_.factor_nnz());
  out.emplace_back("element Hessians and assembled matrix", 8.0 * double(element_.size() + values_.size()));
  if (bones_.dofs() > 0)  // the border of the bordered Newton system and its solve, per step
    out.emplace_back("movable bones", 8.0 * double(bones_.dofs()) * (6.0 * layout_.num_free + bones_.dofs()));
  return out;
}

double FemSolver::energy_with(const Eigen::MatrixX3d& x, const Eigen::VectorXd& act, const LoadCase& load) const {
  const Eigen::Vector3d& grav = load.gravity;
  const Eigen::Index m = model_.tets.rows();
  const auto& geo = layout_.geometry;
  const ElasticTerm elastic(model_, layout_, act);
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t)
    tet_energy_[t] = elastic.active(t) ? elastic.energy(t, deformation_gradient(geo.grad[t], x, model_.tets, t)) : 0.0;
  double E = 0;
  for (Eigen::Index t = 0; t < m; ++t) E += tet_energy_[t];  // fixed order: reproducible
  if (grav.squaredNorm() > 0) E -= gravity_work::energy(layout_.lumped_mass, x, grav);
  if (load.inertia_weight > 0)  // on the vertices that move, as EMU's
    E += inertia::energy(layout_.lumped_mass, x, load.inertia_target, load.inertia_weight,
                         [&](Eigen::Index v) { return layout_.moves(v); });
  return E;
}

void FemSolver::set_inertia(const LoadCase& load) {
  inertia_weight_ = load.inertia_weight;
  if (!(inertia_weight_ > 0) || bones_.dofs() == 0) {
    bone_inertia_.resize(0, 0);
    return;
  }
  // the bones' vertices: their inertia turns and moves the bone (RigidBones::add_vertex_hessian)
  bone_inertia_ = inertia::diagonal_hessian(layout_.lumped_mass, inertia_weight_,
                                            [&](Eigen::Index v) { return layout_.vertex_bone(v) >= 0; });
}

void FemSolver::free_gradient(const LoadCase& load, const Eigen::MatrixX3d& x,
                              const Eigen::VectorXd& act, Eigen::VectorXd& g) const {
  const Eigen::Index m = model_.tets.rows();
  const auto& geo = layout_.geometry;
  const ElasticTerm elastic(model_, layout_, act);
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    if (!elastic.active(t)) {
      Eigen::Map<Vec12>(corner_.data() + t * 12).setZero();
      continue;
    }
    const Mat3 P = elastic.stress(t, deformation_gradient(geo.grad[t], x, model_.tets, t));
    Eigen::Map<Vec12>(corner_.data() + t * 12) = geo.volume(t) * corner_vectors(geo.grad[t], P);
  }
  g.resize(layout_.num_free * 3);
  pattern_.gather(corner_.data(), 3, g.data());
  if (load.gravity.squaredNorm() > 0)
    for (Eigen::Index v = 0; v < model_.rest.rows(); ++v)
      if (layout_.free_index(v) >= 0) g.segment<3>(3 * layout_.free_index(v)) -= gravity_work::vertex_gradient(layout_.lumped_mass(v), load.gravity);
  if (load.inertia_weight > 0)
    for (Eigen::Index v = 0; v < model_.rest.rows(); ++v)
      if (layout_.free_index(v) >= 0)
        g.segment<3>(3 * layout_.free_index(v)) += inertia::vertex_gradient(
            layout_.lumped_mass(v), x.row(v).transpose(), load.inertia_target.row(v).transpose(), load.inertia_weight);
}

void FemSolver::assemble_hessian(const Eigen::MatrixX3d& x, const Eigen::VectorXd& act, bool exact) {
  const EigenFilter filter = options_.eigen_filter;
  const Eigen::Index m = model_.tets.rows();
  const auto& geo = layout_.geometry;
  const ElasticTerm elastic(model_, layout_, act);
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    if (!elastic.active(t)) {
      Eigen::Map<Mat12>(element_.data() + t * 144).setZero();
      continue;
    }
    const Mat3 F = deformation_gradient(geo.grad[t], x, model_.tets, t);
    Mat9 H;
    elastic.hessians(t, F, filter, exact ? nullptr : &H, exact ? &H : nullptr);
    Eigen::Map<Mat12>(element_.data() + t * 144) = geo.volume(t) * position_hessian(geo.grad[t], H);
  }
  pattern_.assemble(element_.data(), values_.data());
  if (inertia_weight_ > 0)
    for (Eigen::Index v = 0; v < model_.rest.rows(); ++v) {
      const int f = layout_.free_index(v);
      if (f < 0) continue;
      const double h = inertia::vertex_hessian(layout_.lumped_mass(v), inertia_weight_);
      for (int c = 0; c < 3; ++c) values_[diagonal_[3 * f + c]] += h;
    }
}

void FemSolver::vertex_forces(const LoadCase& load, const Eigen::MatrixX3d& x, Eigen::MatrixX3d& f) const {
  const Eigen::Vector3d& grav = load.gravity;
  f = Eigen::MatrixX3d::Zero(model_.rest.rows(), 3);
  for (int t : bones_.touching_tets())
    for (int a = 0; a < 4; ++a) {
      const int v = model_.tets(t, a);
      if (layout_.vertex_bone(v) >= 0) f.row(v) += Eigen::Map<const Vec3>(corner_.data() + t * 12 + 3 * a).transpose();
    }
  if (grav.squaredNorm() > 0)
    for (Eigen::Index v = 0; v < f.rows(); ++v)
      if (layout_.vertex_bone(v) >= 0) f.row(v) -= gravity_work::vertex_gradient(layout_.lumped_mass(v), grav).transpose();
  if (load.inertia_weight > 0)
    for (Eigen::Index v = 0; v < f.rows(); ++v)
      if (layout_.vertex_bone(v) >= 0)
        f.row(v) += inertia::vertex_gradient(layout_.lumped_mass(v), x.row(v).transpose(),
                                             load.inertia_target.row(v).transpose(), load.inertia_weight)
                        .transpose();
}

double FemSolver::contact_energy(const Eigen::MatrixX3d& x) const {
  return has_contact() ? contact_.energy(x) : 0.0;
}

Eigen::MatrixX3d FemSolver::contact_gradient(const Eigen::MatrixX3d& x) const {
  return has_contact() ? contact_.checked_gradient(x) : Eigen::MatrixX3d::Zero(x.rows(), 3);
}

void FemSolver::set_contact_hessian(const Eigen::MatrixX3d& x) {
  contact_H_ = contact_.checked_hessian(x);
  // Its free-vertex block in the soft rows, upper triangle (as values_ holds K).
  std::vector<Eigen::Triplet<double>> upper;
  for (int j = 0; j < contact_H_.outerSize(); ++j) {
    const int fj = layout_.free_index(j / 3);
    if (fj < 0) continue;
    for (Eigen::SparseMatrix<double>::InnerIterator it(contact_H_, j); it; ++it) {
      const int fi = layout_.free_index(static_cast<int>(it.row()) / 3);
      const int ri = 3 * fi + static_cast<int>(it.row()) % 3, rj = 3 * fj + j % 3;
      if (fi >= 0 && ri <= rj && it.value() != 0.0) upper.emplace_back(ri, rj, it.value());
    }
  }
  contact_soft_.resize(pattern_.rows(), pattern_.rows());
  contact_soft_.setFromTriplets(upper.begin(), upper.end());
}

bool FemSolver::factorize_newton_matrix() {
  use_merged_ = has_contact() && contact_soft_.nonZeros() > 0;
  if (!use_merged_) return factor_.factorize(values_.data());
  return merged_factor_.factorize(pattern_.rows(), pattern_.col_ptr().data(), pattern_.row_index().data(),
                                  values_.data(), contact_soft_);
}

double FemSolver::gradient_floor(const Eigen::VectorXd& act) const {
  // Round-off in P(F) scales with the largest modulus (lambda at nu near 0.5).
  double force_scale = 0;
  for (Eigen::Index t = 0; t < model_.tets.rows(); ++t)
    if (!layout_.is_bone_tet(t)) force_scale += layout_.geometry.volume(t) * (model_.mu(t) + model_.lambda(t) + act(t));
  const double diagonal = bbox_diagonal(model_.rest);
  force_scale /= diagonal;
  // a time step's inertia w m (x - y): its round-off scales with w m times the positions' size
  if (inertia_weight_ > 0) force_scale += inertia_weight_ * layout_.lumped_mass.sum() * diagonal;
  return 1e-13 * force_scale;
}

namespace {
// newton_correction with a lagged factor: PCG to this fraction of the
// gradient (the correction, an error estimate, needs a few digits).
constexpr double kCorrectionResidual = 1e-3;
// The negative-curvature step (StepSolver::add_negative_curvature): looked for
// where the exact Hessian is indefinite and the filtered step stalls, its
// slope -g.d (twice the decrease it predicts) at most kSaddleDecrease of the
// decrease so far (only near a stationary point: far from one it costs
// iterations).
constexpr double kSaddleDecrease = 1e-3;
}  // namespace

// One FEM solve as the Newton driver sees it. The iterate is the positions x
// with the bones' poses; the gradient in the reduced unknowns is gs (free soft
// rows) and gb (bone rows).
class FemSolver::NewtonProblem {
 public:
  /// with_energy false: the energy is not evaluated (energy() reads 0; a
  /// correction's single Newton step needs only the gradient and the Hessian)
  NewtonProblem(FemSolver& s, const LoadCase& load, Eigen::VectorXd act, const Eigen::MatrixX3d* initial,
                bool with_energy = true)
      : s_(s), load_(load), act_(std::move(act)), nd_(s.bones_.dofs()), step_(s, act_, x_, poses_, fv_, gs_, gb_, ds_, db_) {
    s_.set_inertia(load_);  // the step's inertia in this solve's Newton matrices
    x_ = pinned_positions(s_.model_, load_);
    if (initial) {
      if (initial->rows() != x_.rows() || !initial->allFinite())
        throw std::invalid_argument("initial positions must be finite and #V by 3");
      for (Eigen::Index v = 0; v < x_.rows(); ++v)
        if (s_.layout_.free_index(v) >= 0) x_.row(v) = initial->row(v);
    }
    poses_ = s_.bones_.begin(load_, x_, initial);
    s_.bones_.place(poses_, x_);
    if (with_energy || s_.has_contact()) E_ = total_energy(x_, poses_);
    if (s_.has_contact()) s_.contact_.check_start_state(x_, E_);
    reduced_gradient(x_, poses_, gs_, gb_);
    gn_ = s_.bones_.gradient_norm(gs_.squaredNorm(), gb_);
    g0_ = gn_;
    E0_ = E_;
  }

  double energy() const { return E_; }
  double grad_norm() const { return gn_; }
  const Eigen::MatrixX3d& positions() const { return x_; }
  const Eigen::VectorXd& soft_gradient() const { return gs_; }
  const Eigen::VectorXd& bone_gradient() const { return gb_; }
  const std::vector<NeutralMode>& neutral_modes() const { return last_neutral_; }
  /// The bone Schur complement of the last factorised Newton step (empty: none yet) and its poses.
  const Eigen::MatrixXd& last_bone_schur() const { return step_.last_bone_schur(); }
  const BonePoses& last_schur_poses() const { return step_.last_schur_poses(); }

  SearchDirection direction(int /*iteration*/, PhaseTimes& time) {
    SearchDirection dir;
    if (s_.has_contact()) {
      ScopedSeconds timer(time.hessian);
      s_.set_contact_hessian(x_);
    }
    // Newton with the true Hessian where it is definite (near a stable
    // equilibrium). A failed attempt costs a factorisation, so after one it is
    // retried only once the iteration is in the Newton regime (last step full).
    const bool try_exact = s_.options_.exact_when_definite && (last_exact_ok_ || last_step_ == 1.0);
    const int factorizations0 = s_.factorizations_;
    assembled_ = -1;
    if (s_.lagged_usable() && lagged_newton_step(try_exact, dir, time)) {
      if (!try_exact) ++dir.filtered;
      last_neutral_.clear();
      dir.slope = slope();
      return dir;  // (no contact here: no collision cap needed)
    }
    if (!factorised_step(try_exact, dir, time)) return dir;
    dir.factorizations = s_.factorizations_ - factorizations0;
    if (s_.has_contact() && !cap_at_collision()) {
      ScopedSeconds timer(time.line_search);
      return dir.fail("contact: continuous collision detection allows no step along the Newton direction "
                      "(surfaces touching; a larger contact distance may help)");
    }
    dir.slope = slope();
    if (!(dir.slope < 0)) return dir.fail("Newton direction is not a descent direction");
    return dir;
  }

  // The element Hessians assembled into values_ (exact or filtered), once per
  // kind and direction: the lagged PCG only reads them, so its fallback reuses them.
  void assemble(bool exact, PhaseTimes& time) {
    if (assembled_ == int(exact)) return;
    ScopedSeconds timer(time.hessian);
    s_.assemble_hessian(x_, act_, exact);
    assembled_ = int(exact);
  }

  // Newton-CG on the lagged factor, to the forcing term of EMU's CG
  // (Eisenstat-Walker): true where it converged to a descent direction (else
  // a factorisation follows).
  bool lagged_newton_step(bool try_exact, SearchDirection& dir, PhaseTimes& time) {
    assemble(try_exact, time);
    ScopedSeconds timer(time.linear_solve);
    const double eta = std::min(s_.options_.lagged_cg_forcing, std::sqrt(gn_ / g0_));
    return step_.lagged_direction(try_exact, eta * gn_, dir.cg_iterations) && slope() < 0;
  }

  // A factorised step: the exact matrix where it is definite and descends,
  // else the filtered one (with FEM's negative-curvature step at a saddle);
  // the neutral modes of a filtered step kept for the result. False: dir failed.
  bool factorised_step(bool try_exact, SearchDirection& dir, PhaseTimes& time) {
    bool have = false;
    if (try_exact) {
      assemble(true, time);
      ScopedSeconds timer(time.linear_solve);
      have = step_.newton_direction(true) && slope() < 0;
      last_exact_ok_ = have;
      if (!have) ++dir.exact_failed;
    }
    if (!have) {
      ++dir.filtered;
      assemble(false, time);
      {
        ScopedSeconds timer(time.linear_solve);
        if (!step_.filtered_direction()) {
          dir.fail("Newton matrix is not positive definite even after regularisation: likely a part that nothing "
                   "anchors (no pin, fixed bone or joint holds it), or collapsed tets (see scene.mesh_report and "
                   "Solution.inverted_tets)");
          return false;
        }
      }
      if (try_exact && s_.options_.negative_curvature && !nd_ && !s_.has_contact() &&
          -slope() <= kSaddleDecrease * (E0_ - E_)) {
        ScopedSeconds timer(time.linear_solve);
        dir.negative_curvature = step_.add_negative_curvature();
      }
    }
    std::vector<NeutralMode> found = step_.take_neutral();
    last_neutral_ = have ? std::vector<NeutralMode>() : std::move(found);
    return true;
  }

  /// Contact: shortens the step to the largest one along which no surfaces
  /// pass through each other (CCD on the straight path of the positions;
  /// movable bones turn, so trial_energy checks each of their trial states
  /// too). False if no step is possible.
  bool cap_at_collision() {
    Eigen::MatrixX3d x1;
    BonePoses poses1;
    step_positions(1.0, x1, poses1);
    const double s = s_.contact_.max_step(x_, x1);
    if (!(s > 0)) return false;
    if (s < 1) {
      ds_ *= s;
      if (nd_) db_ *= s;
    }
    return true;
  }

  /// The total energy at positions x with the bones at poses: elastic, fibre and
  /// gravity terms (energy_with), the bones' joint springs and contact; summed here only.
  double total_energy(const Eigen::MatrixX3d& x, const BonePoses& poses) const {
    return s_.energy_with(x, act_, load_) + s_.bones_.spring_energy(poses) + s_.contact_energy(x);
  }

  double trial_energy(double s) {
    trial_ = x_;
    step_positions(s, trial_, trial_poses_);
    if (s_.has_contact() && nd_ && s_.contact_.max_step(x_, trial_) < 1.0)
      return std::numeric_limits<double>::infinity();  // the straight path to it crosses a surface
    return total_energy(trial_, nd_ ? trial_poses_ : poses_);
  }

  /// The positions of the last trial_energy call.
  const Eigen::MatrixX3d& trial_positions() const { return trial_; }

  /// The positions after the full step along the current direction (no energy evaluated).
  Eigen::MatrixX3d full_step_positions() const {
    Eigen::MatrixX3d x;
    BonePoses poses;
    step_positions(1.0, x, poses);
    return x;
  }

  /// The round-off of grad_norm() here: the change of the reduced gradient
  /// when every position moves by one rounding, over sqrt 2 (two samples).
  double gradient_noise() {
    Eigen::MatrixX3d x1 = x_;
    perturb_by_rounding(x1);
    Eigen::VectorXd gs1, gb1;
    const Eigen::MatrixX3d fv = fv_;  // reduced_gradient rewrites the vertex forces the border reads
    reduced_gradient(x1, poses_, gs1, gb1);
    fv_ = fv;
    return s_.bones_.gradient_norm((gs1 - gs_).squaredNorm(), gb1 - gb_) / std::sqrt(2.0);
  }

  double trial_grad_norm() {  // at the trial point of the last trial_energy call
    Eigen::VectorXd gs1, gb1;
    reduced_gradient(trial_, nd_ ? trial_poses_ : poses_, gs1, gb1);
    return s_.bones_.gradient_norm(gs1.squaredNorm(), gb1);
  }

  double take_step(int /*iteration*/, double s, double E_trial) {
    step_positions(s, x_, poses_);
    E_ = E_trial;
    reduced_gradient(x_, poses_, gs_, gb_);
    gn_ = s_.bones_.gradient_norm(gs_.squaredNorm(), gb_);
    last_step_ = s;
    return E_;
  }

  /// The Newton matrix at the current iterate (after s_.assemble_hessian) as
  /// the bone border and Schur solve see it; see reduced_system.
  /// The bones' border of the Newton matrix at the iterate (StepSolver::border).
  void border(bool exact, Eigen::MatrixXd& Hsb, Eigen::MatrixXd& Hbb) { step_.border(exact, Hsb, Hbb); }

  /// Positions and poses after the step s (ds, db) from the current iterate.
  void step_positions(double s, Eigen::MatrixX3d& x, BonePoses& poses) const {
    const UnknownLayout& L = s_.layout_;
    if (&x != &x_) x = x_;
    for (Eigen::Index v = 0; v < x.rows(); ++v)
      if (L.free_index(v) >= 0) x.row(v) += s * ds_.segment<3>(3 * L.free_index(v)).transpose();
    if (nd_) {
      poses = s_.bones_.moved(poses_, db_, s);
      s_.bones_.place(poses, x);
    }
  }
  /// The direction of newton_correction: the exact Newton matrix where it is
  /// definite (exact = true), or the PSD-filtered element Hessians with the
  /// bones' exact rotation term where the bone Schur complement stays
  /// definite (a bone turn is resisted only by that curvature), else filtered
  /// throughout.
  bool correction_direction(bool exact) {
    if (s_.has_contact()) s_.set_contact_hessian(x_);
    s_.assemble_hessian(x_, act_, exact);
    last_exact_ = exact;
    int cg = 0;  // with a lagged factor, PCG first (SolverOptions::lagged_cg_iterations)
    bool indefinite = false;
    if (s_.lagged_usable()) {
      if (step_.lagged_direction(true, kCorrectionResidual * gn_, cg) && slope() < 0) return true;
      indefinite = step_.lagged_indefinite();
    }
    // where PCG met p^T H p <= 0 the matrix is not definite: its factorisation
    // would fail, so none is tried
    if (!indefinite && step_.newton_direction(true) && slope() < 0) return true;
    last_exact_ = false;
    s_.assemble_hessian(x_, act_, false);
    // the filtered matrix is definite: PCG on the lagged factor first here too
    if (indefinite && step_.lagged_direction(false, kCorrectionResidual * gn_, cg) && slope() < 0) return true;
    return step_.filtered_direction() && slope() < 0;
  }
  /// The exact Newton step by PCG on the lagged factor alone (no factorisation,
  /// no filtered fallback): false where there is no lagged factor, PCG misses
  /// its tolerance within the cap or meets negative curvature (x is not in
  /// Newton's regime on that factor).
  bool lagged_newton_direction() {
    if (s_.has_contact() || s_.options_.lagged_cg_iterations <= 0 || !s_.lag_.valid) return false;
    s_.assemble_hessian(x_, act_, true);
    last_exact_ = true;
    int cg = 0;
    return step_.lagged_direction(true, kCorrectionResidual * gn_, cg) && slope() < 0;
  }
  /// The exact Newton step: PCG on the lagged factor where it converges, else a
  /// factorisation of the exact matrix; false where that matrix is not
  /// definite (PCG met negative curvature, or the factorisation failed).
  bool exact_newton_direction() {
    if (s_.has_contact()) s_.set_contact_hessian(x_);
    s_.assemble_hessian(x_, act_, true);
    last_exact_ = true;
    if (s_.lagged_usable()) {
      int cg = 0;
      if (step_.lagged_direction(true, kCorrectionResidual * gn_, cg) && slope() < 0) return true;
      if (step_.lagged_indefinite()) return false;
    }
    return step_.newton_direction(true) && slope() < 0;
  }
  /// Whether the last correction_direction used the exact element Hessians.
  bool last_direction_exact() const { return last_exact_; }

  /// Sets the direction directly (reduced_energy uses it).
  void set_direction(const Eigen::VectorXd& ds, const Eigen::VectorXd& db) {
    ds_ = ds;
    db_ = db;
  }

 private:
  double slope() const { return gs_.dot(ds_) + (nd_ ? gb_.dot(db_) : 0.0); }

  void reduced_gradient(const Eigen::MatrixX3d& x, const BonePoses& poses, Eigen::VectorXd& gs, Eigen::VectorXd& gb) {
    s_.free_gradient(load_, x, act_, gs);
    Eigen::MatrixX3d gc;
    if (s_.has_contact()) {
      gc = s_.contact_gradient(x);
      const UnknownLayout& L = s_.layout_;
      for (Eigen::Index v = 0; v < x.rows(); ++v)
        if (L.free_index(v) >= 0) gs.segment<3>(3 * L.free_index(v)) += gc.row(v).transpose();
    }
    if (!nd_) return;
    s_.vertex_forces(load_, x, fv_);
    if (s_.has_contact())
      for (Eigen::Index v = 0; v < x.rows(); ++v)
        if (s_.layout_.vertex_bone(v) >= 0) fv_.row(v) += gc.row(v);
    s_.bones_.gradient(poses, x, fv_, gb);
  }

  FemSolver& s_;
  const LoadCase& load_;
  const Eigen::VectorXd act_;
  const int nd_;
  Eigen::MatrixX3d x_, trial_, fv_;
  BonePoses poses_, trial_poses_;
  Eigen::VectorXd gs_, gb_, ds_, db_;
  double E_ = 0, E0_ = 0, gn_ = 0, g0_ = 0, last_step_ = 0;
  bool last_exact_ok_ = true, last_exact_ = false;
  int assembled_ = -1;  // the kind of Hessian in values_ this direction: -1 none, 0 filtered, 1 exact
  std::vector<NeutralMode> last_neutral_;  // of the last step
  StepSolver step_;  // after the members it reads
};

SolveResult FemSolver::solve(const LoadCase& load, const Eigen::MatrixX3d* initial) {
  validate_load(model_, load);
  const auto t0 = Clock::now();
  const Eigen::VectorXd act = tet_activation(model_, load);
  // A warm start's step-test gate on the cold start's scale (newton_minimize);
  // without contact (its terms need not be defined at rest under these pins).
  double cold_g0 = 0.0;
  if (initial && options_.step_tol > 0 && options_.step_tol_cold_scale && !has_contact())
    // (a time step's cold start: its predicted positions, where an integrator starts)
    cold_g0 = NewtonProblem(*this, load, act, load.inertia_weight > 0 ? &load.inertia_target : nullptr).grad_norm();
  NewtonProblem newton(*this, load, act, initial);
  SolveResult res;
  newton_minimize(newton, options_, gradient_floor(act), t0, res, 0.0, cold_g0);
  if (!res.converged && res.iterations == options_.max_iterations && newton.last_bone_schur().size())
    res.status += bones_.weakest_turn(newton.last_schur_poses(), newton.last_bone_schur());
  res.set_neutral_modes(newton.neutral_modes());
  res.positions = newton.positions();
  res.time_s = seconds_since(t0);
  return res;
}

namespace {
// newton_correction: the gradient reduction of an exact step that counts as
// Newton's regime (docs/DESIGN.md, "EMU's error estimate").
constexpr double kCorrectionContraction = 0.1;
}  // namespace

Eigen::MatrixX3d FemSolver::newton_correction(const LoadCase& load, const Eigen::MatrixX3d& x0,
                                              CorrectionHessian hessian, int max_steps) {
  validate_load(model_, load);
  if (max_steps < 1) throw std::invalid_argument("max_steps must be >= 1");
  const Eigen::VectorXd act = tet_activation(model_, load);
  Eigen::MatrixX3d x = x0;
  set_inertia(load);  // (the floor reads it)
  const double floor = gradient_floor(act);
  // the exact Newton step alone compares no energies
  const bool newton_only = hessian == CorrectionHessian::LaggedNewton || hessian == CorrectionHessian::Newton;
  for (int step = 0; step < max_steps; ++step) {
    NewtonProblem newton(*this, load, act, &x, /*with_energy=*/!newton_only);
    // Where FEM's own solve would stop at once (the gradient at round-off:
    // Convergence::initial), the correction is zero: nothing is assembled or
    // factorised (a sequence's first frame at rest).
    if (newton.grad_norm() <= floor) {
      x = newton.positions();
      break;
    }
    // the exact Newton step alone (never a filtered one): one step, or none
    if (newton_only) {
      const bool lagged = hessian == CorrectionHessian::LaggedNewton;
      if (!(lagged ? newton.lagged_newton_direction() : newton.exact_newton_direction()))
        throw std::runtime_error(lagged ? "no lagged Newton correction from these positions: PCG on the last "
                                          "factor did not converge or met negative curvature"
                                        : "no Newton correction from these positions: the exact Newton matrix is "
                                          "not positive definite");
      x = newton.full_step_positions();
      break;
    }
    if (!newton.correction_direction(hessian != CorrectionHessian::Filtered))
      throw std::runtime_error("no Newton correction from these positions: the Newton matrix is not positive "
                               "definite");
    bool used_exact = newton.last_direction_exact();
    const double E_first = newton.trial_energy(1.0);
    Eigen::MatrixX3d x1 = newton.trial_positions();
    // The exact step (where the exact matrix is definite; else the call above
    // already fell back to the filtered one) is kept as it is when it cuts the
    // gradient tenfold (Newton's regime, one factorisation); otherwise the
    // filtered step competes and the one that lowers the FEM energy more wins.
    if (hessian == CorrectionHessian::LowerEnergy && used_exact &&
        newton.trial_grad_norm() > kCorrectionContraction * newton.grad_norm() &&
        newton.correction_direction(false) && newton.trial_energy(1.0) < E_first) {
      x1 = newton.trial_positions();
      used_exact = false;
    }
    x.swap(x1);
    if (used_exact) break;  // in Newton's regime: one step is the correction
  }
  return x;
}

// FemSolverTesting's pieces that take the Newton state defined above (declared in fem_solver_testing.h).

double FemSolverTesting::reduced_energy(FemSolver& s, const LoadCase& load, const Eigen::MatrixX3d& x0,
                                        const Eigen::VectorXd& z) {
  validate_load(s.model_, load);
  const int ns = 3 * s.layout_.num_free, nd = s.bones_.dofs();
  if (z.size() != ns + nd)
    throw std::invalid_argument("z must have 3 #free + #bone unknowns = " + std::to_string(ns + nd) + " entries");
  FemSolver::NewtonProblem newton(s, load, tet_activation(s.model_, load), &x0);
  newton.set_direction(z.head(ns), z.tail(nd));
  return newton.trial_energy(1.0);
}

void FemSolverTesting::reduced_system(FemSolver& s, const LoadCase& load, const Eigen::MatrixX3d& x0, bool exact,
                                      Eigen::VectorXd& gradient, Eigen::MatrixXd& hessian) {
  validate_load(s.model_, load);
  const Eigen::VectorXd act = tet_activation(s.model_, load);
  FemSolver::NewtonProblem newton(s, load, act, &x0);
  const int ns = 3 * s.layout_.num_free, nd = s.bones_.dofs();
  gradient.resize(ns + nd);
  gradient << newton.soft_gradient(), newton.bone_gradient();
  s.assemble_hessian(newton.positions(), act, exact);
  hessian.setZero(ns + nd, ns + nd);
  const auto& cp = s.pattern_.col_ptr();
  const auto& ri = s.pattern_.row_index();
  for (int j = 0; j < s.pattern_.rows(); ++j)
    for (int k = cp[j]; k < cp[j + 1]; ++k) hessian(ri[k], j) = hessian(j, ri[k]) = s.values_[k];
  if (s.has_contact()) {
    s.set_contact_hessian(newton.positions());
    for (int j = 0; j < s.contact_soft_.outerSize(); ++j)
      for (Eigen::SparseMatrix<double>::InnerIterator it(s.contact_soft_, j); it; ++it) {
        hessian(it.row(), j) += it.value();
        if (it.row() != j) hessian(j, it.row()) += it.value();
      }
  }
  if (!nd) return;
  Eigen::MatrixXd Hsb, Hbb;
  newton.border(exact, Hsb, Hbb);
  hessian.topRightCorner(ns, nd) = Hsb;
  hessian.bottomLeftCorner(nd, ns) = Hsb.transpose();
  hessian.bottomRightCorner(nd, nd) = Hbb;
}

}  // namespace emu
