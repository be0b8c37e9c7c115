#include "emu/solvers/emu/constant_schur.h"

#include "emu/linalg/spd_inverse.h"
#include "emu/solvers/emu/schur_form.h"

#include <cmath>
#include <stdexcept>

namespace emu {

Eigen::VectorXd ConstantSchur::weights(const Model& model, const UnknownLayout& layout, const Eigen::VectorXd& wv,
                                       double alpha) {
  const Eigen::Index m = model.tets.rows();
  Eigen::VectorXd e(m);
  for (Eigen::Index t = 0; t < m; ++t) {
    // a bone is rigid: the limit h -> infinity, e -> w V
    if (layout.is_bone_tet(t)) {
      e(t) = wv(t);
      continue;
    }
    const double h = model.mu(t) + model.lambda(t) / 3.0;
    e(t) = wv(t) * h / (h + alpha * model.acap_weight(t));
  }
  return e;
}

ConstantSchur::ConstantSchur(const Model& model, const UnknownLayout& layout, AcapOperator& acap, double alpha,
                             bool single_precision)
    : model_(model), layout_(layout), acap_(acap), single_precision_(single_precision), alpha_(-1.0) {
  if (single_precision_) Ainv_rounded_.resize(layout.num_unknowns);
  else Ainv_.resize(layout.num_unknowns);
  set_alpha(alpha);
}

void ConstantSchur::set_alpha(double alpha) {
  if (alpha != alpha_) rebuild_with(alpha_, alpha);
}

void ConstantSchur::set_inertia(double weight) {
  if (!(weight >= 0) || !std::isfinite(weight)) throw std::invalid_argument("the inertia weight must be >= 0 and finite");
  if (weight != inertia_) rebuild_with(inertia_, weight);
}

void ConstantSchur::rebuild_with(double& setting, double value) {
  const double before = setting;
  setting = value;
  try {
    build_s0();
  } catch (...) {  // S0 stays as it was: the next call with this value tries again
    setting = before;
    throw;
  }
}

void ConstantSchur::build_s0() {
  const Eigen::VectorXd& wv = acap_.weight_volume();
  const Eigen::VectorXd e = weights(model_, layout_, wv, alpha_);
  // S0 = c K where every tet's e_t / (w_t V_t) is the same c (one tissue, or
  // ACAP weights proportional to the curvatures) and no inertia: K's own factor serves.
  const Eigen::ArrayXd ratio = e.array() / wv.array();
  if (inertia_ == 0.0 && ratio.maxCoeff() - ratio.minCoeff() <= 1e-12 * ratio.maxCoeff()) {
    scale_ = ratio.maxCoeff();
    s0_.reset();
  } else {
    scale_ = 1.0;
    // + (w / alpha) m_v on each free vertex (see the header)
    Eigen::VectorXd diagonal;
    if (inertia_ > 0) {
      diagonal.setZero(layout_.num_free);
      for (Eigen::Index v = 0; v < layout_.free_index.size(); ++v)
        if (layout_.free_index(v) >= 0) diagonal(layout_.free_index(v)) = inertia_ / alpha_ * layout_.lumped_mass(v);
    }
    // the ACAP matrix's pattern; rounded, every solve of it (the bone
    // elimination's too) is the exact inverse of the rounded matrix
    s0_ = std::make_unique<AcapOperator>(model_, layout_, &e, &acap_, single_precision_,
                                         inertia_ > 0 ? &diagonal : nullptr);
  }
  // S0 = c K shares the fit's operator, which must stay exact: a rounded copy
  // of its factor beside it (solve_rounded: operators without movable bones;
  // a bone scene always has its own S0, a bone tet's e_t being w V and a soft
  // tet's less). Whether S0 = c K depends on the tissues, not on alpha, so
  // a later alpha never leaves such a copy behind; a time step's inertia
  // gives S0 its own factor and the copy stays for the next quasi-static solve.
  rounded_ = single_precision_ && (s0_ != nullptr || !acap_.has_bones());
  if (rounded_ && !s0_) acap_.keep_single_precision_copy();
}

bool ConstantSchur::update(const std::vector<Mat9>& A) {
  const long refused = invert_spd_blocks<9>(A, [&](long u, const Mat9& inv, bool ok) {
    const Mat9 B = ok ? inv : Mat9::Zero();
    if (single_precision_) round_spd_block(B, Ainv_rounded_[u]);
    else Ainv_[u] = B;
  });
  ok_ = refused == 0;
  return ok_;
}

void ConstantSchur::apply(const Mat9X& r, Mat9X& out) const {
  if (!ok_) {
    out = r;
    return;
  }
  // A^-1 r + alpha A^-1 C^T S0^-1 C (A^-1 r): C with the ACAP weights, S0 with
  // its own (S0^-1 = (scale_ K)^-1 without an own factor)
  auto middle = [&](const Eigen::MatrixX3d& y, Eigen::MatrixX3d& u) {
    rhs_ = y;
    if (rounded_ && !s0_) acap_.solve_rounded(rhs_, z_);
    else s0().solve(rhs_, z_);  // s0_: rounded where built so
    u = z_;
  };
  if (single_precision_) apply_schur_form(layout_, acap_, Ainv_rounded_, alpha_ / scale_, r, out, work_, middle);
  else apply_schur_form(layout_, acap_, Ainv_, alpha_ / scale_, r, out, work_, middle);
}

}  // namespace emu
