#include "emu/solvers/emu/step_solver.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "emu/solvers/emu/bone_turn_fits.h"
#include "emu/solvers/emu/fit_jacobian.h"
#include "emu/solvers/emu/joint_coordinates.h"

namespace emu {
namespace {
double dot(const Mat9X& a, const Mat9X& b) { return a.cwiseProduct(b).sum(); }
}  // namespace

EmuSolver::StepSolver::StepSolver(EmuSolver& s, const Context& c, const Mat9X& F, const Mat9X& g, const Mat9X& gR,
                                  const double& gn, const double& g0, Mat9X& d)
    : s_(s),
      c_(c),
      bones_(s.layout_.num_bones > 0),
      F_(F),
      g_(g),
      gR_(gR),
      gn_(gn),
      g0_(g0),
      d_(d),
      coarse_(s.layout_, s.emu_.alpha, s.turn_fits_ ? s.turn_fits_->follow_fields() : std::vector<const Mat9X*>()),
      lbfgs_(s.emu_.lbfgs_memory) {}

// The blocks and the preconditioner when due, contact's Hessian, the bone
// coarse space, then the step's kind and a descent check.
bool EmuSolver::StepSolver::direction(int it, bool exact, const Eigen::MatrixX3d& x, SearchDirection& dir,
                                      PhaseTimes& time) {
  bool refreshed = false;
  if (!refresh_blocks(it, exact, dir, time, refreshed)) return false;
  const std::vector<Mat9>& H = exact ? A_exact_ : A_;
  if (s_.has_position_terms(c_)) {
    ScopedSeconds timer(time.hessian);
    Hc_ = s_.position_hessian(c_, x);
  }
  const auto product = [&](const Mat9X& v, Mat9X& out) { hessian_product(H, exact, v, out); };
  for (Mat9X& r : recycled_) s_.project_tangent(F_, r);  // tangent at the current bones
  // The bone coarse space follows the Hessian CG uses (rebuilt every step;
  // for L-BFGS, whose H0 it is part of, with the preconditioner).
  if (bones_ && s_.emu_.bone_coarse_space && (s_.emu_.step != EmuStep::Lbfgs || refreshed)) {
    ScopedSeconds timer(time.preconditioner);
    build_coarse_space(H, exact, product);
  }
  ++since_refresh_;
  ScopedSeconds timer(time.linear_solve);
  return step_direction(product, dir);
}

void EmuSolver::StepSolver::stepped(double s, int cg_iterations, const Mat9X& dgR) {
  if (s_.emu_.step == EmuStep::Lbfgs) lbfgs_.push(s * d_, dgR);
  last_cg_ = cg_iterations;
  if (cg_after_refresh_ < 0) cg_after_refresh_ = cg_iterations;
}

// The blocks A_u at F_: the filtered ones (and the preconditioner built on
// them) every preconditioner_refresh steps, or sooner when CG slows down by
// half since the last rebuild, the exact ones every step they are used.
// Between rebuilds the preconditioner lags behind the exact products
// (L-BFGS's curvature pairs make up for it); the Woodbury step rebuilds it
// every step, as the paper does. False: dir has failed.
bool EmuSolver::StepSolver::refresh_blocks(int it, bool exact, SearchDirection& dir, PhaseTimes& time, bool& refreshed) {
  const EmuSolverOptions& o = s_.emu_;
  const bool lbfgs = o.step == EmuStep::Lbfgs;
  refreshed = (!exact && !lbfgs) || it == 1 || since_refresh_ >= o.preconditioner_refresh ||
              (cg_after_refresh_ >= 0 && last_cg_ > 1.5 * cg_after_refresh_ + 5);
  if (!refreshed) {
    if (!lbfgs) {
      ScopedSeconds timer(time.hessian);
      s_.blocks_into(c_, F_, nullptr, &A_exact_);
    }
    return true;
  }
  {
    ScopedSeconds timer(time.hessian);
    s_.blocks_into(c_, F_, &A_, exact ? &A_exact_ : nullptr);
  }
  ScopedSeconds timer(time.preconditioner);
  BlockPreconditioner& pc = *s_.preconditioner_;
  if (pc.factorises_on_update()) ++dir.factorizations;
  if (!pc.update(A_)) {
    dir.fail(pc.failure());
    return false;
  }
  since_refresh_ = 0;
  cg_after_refresh_ = -1;
  return true;
}

// out = H v with H's blocks (exact or filtered), Riemannian with bones (the
// spring's curvature with exact blocks); contact's curvature J^T H_c J
// enters the products (the preconditioner leaves it out), its bone columns
// projected like the rest.
void EmuSolver::StepSolver::hessian_product(const std::vector<Mat9>& H, bool exact, const Mat9X& v, Mat9X& out) const {
  if (bones_) s_.riemannian_product(H, F_, g_, v, exact, out);
  else s_.hessian_product_into(H, v, out);
  if (s_.has_position_terms(c_) && Hc_.nonZeros()) {
    Mat9X add = Mat9X::Zero(9, out.cols());
    s_.jacobian_->add_hessian_product(Hc_, v, add);
    if (bones_) s_.project_tangent(F_, add);
    out += add;
  }
}

template <class Product>
void EmuSolver::StepSolver::build_coarse_space(const std::vector<Mat9>& H, bool exact, const Product& product) {
  // bone b's turns by M (3 tangents) and H of them, in one pass over H's blocks
  const auto turn = [&](int b, const std::array<Mat3, 3>& M, std::array<Mat9X, 3>& Z, std::array<Mat9X, 3>& HZ) {
    s_.turn_fits_->turns<3>(H, b, M, s_.emu_.alpha, s_.acap_->weight_volume(), Z, HZ);
    for (int k = 0; k < 3; ++k) {
      if (s_.has_position_terms(c_) && Hc_.nonZeros()) product(Z[k], HZ[k]);  // position terms need the fit
      else
        s_.riemannian_bone_columns(F_, g_, Z[k], exact, HZ[k]);
    }
  };
  // in joint coordinates the coarse turns are the turn map's combinations of
  // the bones' turns (a joint turns its subtree)
  if (!s_.joints_) {
    coarse_.build(F_, turn, product, recycled_);
    return;
  }
  const Eigen::MatrixXd turn_map = s_.joints_->turn_map(F_);
  coarse_.build(F_, turn, product, recycled_, &turn_map);
}

// d_ by the step's kind: the preconditioner's step (Woodbury), L-BFGS on it,
// or inexact Newton: PCG on H d = -g to |r| <= eta |g| (Eisenstat-Walker)
// and until the quadratic model stops falling fast (Nash-Sofer). A
// direction that does not descend is replaced by the preconditioner's.
// False: dir has failed.
template <class Product>
bool EmuSolver::StepSolver::step_direction(const Product& product, SearchDirection& dir) {
  const EmuSolverOptions& o = s_.emu_;
  const auto precond = [&](const Mat9X& r, Mat9X& z) { precondition(r, z); };
  if (o.step == EmuStep::Woodbury) {
    precondition(gR_, d_);
    d_ = -d_;
  } else if (o.step == EmuStep::Lbfgs) {
    lbfgs_.apply(gR_, precond, d_);
    d_ = -d_;
  } else {
    const double eta =
        std::min(o.cg_forcing_max, std::max(o.cg_forcing_min, std::pow(gn_ / g0_, o.cg_forcing_exponent)));
    const int cap = stall_limit();
    const PcgResult cg = pcg_.solve(product, precond, Mat9X(-gR_), eta * gn_, cap, d_, o.cg_model_decrease);
    dir.cg_iterations = cg.iterations;
    if (cg.negative_curvature) ++dir.filtered;  // exact H is indefinite here: keep what CG had
    dir.cg_cut = !cg.converged && !cg.negative_curvature && cap < o.cg_max_iterations;
  }
  if (dir.cg_cut) recycle(d_);  // (a cut needs a coarse space that learns: stall_limit)
  dir.slope = dot(gR_, d_);
  if (!(dir.slope < 0)) {
    precondition(gR_, d_);
    d_ = -d_;
    dir.slope = dot(gR_, d_);
    if (!(dir.slope < 0)) {
      dir.fail("no descent direction (Hessian approximation broke down)");
      return false;
    }
  }
  return true;
}

// With a coarse space that learns (bones, recycled directions), CG is cut where
// it runs kCgStallRatio x the last step's iterations (at least kCgStallMin):
// it has met a mode the preconditioner misses, and the iterations after that
// resolve it slowly (realistic_biceps as a chain: 56 CG in one step of 8, 40%
// of the solve, the next step 3 CG). The cut step is taken, its direction
// joins the coarse space, and the next step resolves the mode in it; a cut
// step is no Newton step, so the step test does not stop on it
// (docs/DESIGN.md, "The cost of an iteration").
int EmuSolver::StepSolver::stall_limit() const {
  const int cap = s_.emu_.cg_max_iterations;
  return learns_modes() ? std::min(cap, std::max(kCgStallMin, kCgStallRatio * last_cg_)) : cap;
}

bool EmuSolver::StepSolver::learns_modes() const {
  return s_.emu_.recycled_directions > 0 && bones_ && s_.emu_.bone_coarse_space;  // only a coarse space takes them
}

// A CG solve cut where it stalled met a mode the preconditioner misses; its
// direction (orthogonalised against those kept) joins the bone
// coarse space of the following steps, the oldest dropped beyond
// EmuSolverOptions::recycled_directions (docs/DESIGN.md, "The cost of an iteration").
void EmuSolver::StepSolver::recycle(const Mat9X& d) {
  Mat9X dn = d;
  for (const Mat9X& r : recycled_) dn -= (dot(r, dn) / dot(r, r)) * r;
  if (!(dn.norm() > 1e-3 * d.norm())) return;
  recycled_.push_back(std::move(dn));
  if (static_cast<int>(recycled_.size()) > s_.emu_.recycled_directions) recycled_.erase(recycled_.begin());
}

void EmuSolver::StepSolver::precondition(const Mat9X& in, Mat9X& out) const {
  auto base = [&](const Mat9X& r, Mat9X& z) { s_.base_precondition(F_, r, z); };
  if (bones_) coarse_.apply(in, out, base);
  else base(in, out);
}

}  // namespace emu
