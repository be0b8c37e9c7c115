#pragma once
// A coarse correction for the rotations of movable bones in EMU's
// Newton-Krylov preconditioner.
//
// The Woodbury term sees a bone's block as stiff as alpha times its ACAP
// weight (alpha sum w V), while turning a bone with the soft tissue following
// is cheap; CG would spend most of its iterations on the bones. The coarse
// space Z = {turn bone b about axis k (W_k F_b), the soft F_t set to F_t of the
// fitted positions of that turn} (3 per bone) enters as a balancing
// preconditioner
//   M^-1 r = Q r + (I - Q H) B (I - H Q) r,   Q = Z (Z^T H Z)^-1 Z^T,
// with B the base (Woodbury, tangent-projected) inverse, rebuilt every Newton
// step with the Hessian CG uses (3 fits and 3 Hessian products per bone; H Z is
// kept, so an application costs one B and 4 x 3 vector operations per bone).
// Where Z^T H Z is not positive definite (negative curvature far from
// equilibrium, or a neutral mode) the additive form Q + B with the positive
// part of Z^T H Z is used. A direction of zero curvature, measured against the
// curvature 2 alpha sum_t V_t of turning the bone's volume against an ACAP term
// of weight 1, is a neutral mode: left out and reported.
#include <functional>
#include <vector>

#include <Eigen/Core>

#include "emu/model/unknown_layout.h"
#include "emu/solvers/acap.h"
#include "emu/solvers/newton/result.h"

namespace emu {

class BoneCoarseSpace {
 public:
  using Product = std::function<void(const Mat9X&, Mat9X&)>;
  /// Fills the soft columns of Z from its bone columns (the fit of the turn).
  using Follow = std::function<void(Mat9X&)>;

  BoneCoarseSpace(const UnknownLayout& layout, double alpha);

  /// Rebuild at F (9 x #unknowns; bone columns rotations) with H's product;
  /// `extra` directions (9 x #unknowns each, bone columns tangent at F: the
  /// recycled directions of earlier CG solves) join the 3 turns per bone.
  void build(const Mat9X& F, const Follow& follow, const Product& product, const std::vector<Mat9X>& extra = {});
  bool built() const { return built_; }

  /// out = M^-1 in around the base inverse base(in, out) (tangent-projected).
  template <class Base>
  void apply(const Mat9X& in, Mat9X& out, Base&& base) const;

  /// Neutral modes found by the last build.
  const std::vector<NeutralMode>& neutral_modes() const { return neutral_; }

 private:
  static double dot(const Mat9X& a, const Mat9X& b) { return a.cwiseProduct(b).sum(); }
  const UnknownLayout& layout_;
  double alpha_;
  std::vector<Mat9X> Z_, HZ_;
  Eigen::MatrixXd inv_;  // pseudo-inverse of Z^T H Z
  bool built_ = false, balancing_ = false;
  std::vector<NeutralMode> neutral_;
  mutable Mat9X r1_;
};

template <class Base>
void BoneCoarseSpace::apply(const Mat9X& in, Mat9X& out, Base&& base) const {
  const size_t nz = Z_.size();
  if (!built_) {
    base(in, out);
    return;
  }
  Eigen::VectorXd zr(nz);
  if (balancing_) {
    for (size_t i = 0; i < nz; ++i) zr(i) = dot(Z_[i], in);
    const Eigen::VectorXd c1 = inv_ * zr;
    r1_ = in;
    for (size_t i = 0; i < nz; ++i) r1_ -= c1(i) * HZ_[i];
    base(r1_, out);
    for (size_t i = 0; i < nz; ++i) zr(i) = dot(HZ_[i], out);
    const Eigen::VectorXd c2 = inv_ * zr;
    for (size_t i = 0; i < nz; ++i) out += (c1(i) - c2(i)) * Z_[i];
    return;
  }
  base(in, out);
  for (size_t i = 0; i < nz; ++i) zr(i) = dot(Z_[i], in);
  const Eigen::VectorXd c = inv_ * zr;
  for (size_t i = 0; i < nz; ++i) out += c(i) * Z_[i];
}

}  // namespace emu
