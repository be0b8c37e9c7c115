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
// step with the Hessian CG uses (3 Hessian products per bone, their fits
// from the unit turn's: no back-substitution without contact). Q works in the
// coarse coordinates Zc = Z Tc (the bones' turns, or in joint coordinates the
// turn map's combinations of them, then the extra directions): H Zc is kept,
// so an application costs one B and a few passes over H Zc, the extra
// columns and the bones' shared fields, below.
// A bone's three turns share one field: turn k of bone b is M_bk Phi_b
// (M_bk = [e_k]_x F_b; Phi_b: the unit turn's F_t on the soft unknowns,
// `follow`, the identity on b's own unknown, zero on the other bones), so Z
// itself is not stored: Z^T r takes G_b = sum_u R_u Phi_b,u^T (3x3) and
// c_bk = <M_bk, G_b>, and Z c adds (sum_k c_bk M_bk) Phi_b,u: a pass over
// Phi_b in place of three over Z's columns (the recycled directions, which
// have no such form, stay columns).
// Where Z^T H Z is not positive definite (negative curvature far from
// equilibrium, or a neutral mode) the additive form Q + B with the positive
// part of Z^T H Z is used. A direction of zero curvature, measured against the
// curvature 2 alpha sum_t V_t of turning the bone's volume against an ACAP term
// of weight 1, is a neutral mode: left out and reported.
#include <array>
#include <functional>
#include <vector>

#include <Eigen/Core>

#include "emu/linalg/chunked_sum.h"
#include "emu/model/unknown_layout.h"
#include "emu/solvers/emu/acap.h"
#include "emu/solvers/newton/result.h"

namespace emu {

class BoneCoarseSpace {
 public:
  using Product = std::function<void(const Mat9X&, Mat9X&)>;
  /// turns(b, M, Z, HZ): for each of bone b's three tangents M[k], Z[k] (9 x
  /// #unknowns) = bone b turned by M[k] with the soft F_t of the turn's fitted
  /// positions (other bones 0), and HZ[k] = H Z[k] (BoneTurnFits::turns:
  /// from the unit turn's fits, the three in one pass over H's blocks).
  using Turn = std::function<void(int, const std::array<Mat3, 3>&, std::array<Mat9X, 3>&, std::array<Mat9X, 3>&)>;

  /// follow: per movable bone, Phi_b on the soft unknowns (9 x #soft; the
  /// unit turn's F_t), which every turn of build must follow: Z[k] = M[k]
  /// Phi_b (above). Kept by pointer: it must outlive the coarse space.
  BoneCoarseSpace(const UnknownLayout& layout, double alpha, std::vector<const Mat9X*> follow);

  /// Rebuild at F (9 x #unknowns; bone columns rotations) with H's product;
  /// `extra` directions (9 x #unknowns each, bone columns tangent at F: the
  /// recycled directions of earlier CG solves) join the 3 turns per bone.
  /// turn_map (3 #bones by n; nullptr: none): the coarse turns are its columns'
  /// combinations of the bones' world turns (joint coordinates, joint_coordinates.h:
  /// a joint turns its whole subtree), and turn's HZ must be of a Hessian that
  /// is exact on those combinations.
  void build(const Mat9X& F, const Turn& turn, const Product& product, const std::vector<Mat9X>& extra = {},
             const Eigen::MatrixXd* turn_map = nullptr);
  bool built() const { return built_; }

  /// out = M^-1 in around the base inverse base(in, out) (tangent-projected).
  template <class Base>
  void apply(const Mat9X& in, Mat9X& out, Base&& base) const;

  /// Neutral modes found by the last build.
  const std::vector<NeutralMode>& neutral_modes() const { return neutral_; }

 private:
  static double dot(const Mat9X& a, const Mat9X& b) { return a.cwiseProduct(b).sum(); }
  using Flat = Eigen::Map<const Eigen::VectorXd>;
  static Flat flat(const Mat9X& v) { return Flat(v.data(), v.size()); }
  static Eigen::Map<Eigen::VectorXd> flat(Mat9X& v) { return Eigen::Map<Eigen::VectorXd>(v.data(), v.size()); }
  /// c = M^T v (M: #entries by nz), per fixed chunk of rows then over the
  /// chunks in order: the same bits for any number of threads.
  void project(const Eigen::MatrixXd& M, const Mat9X& v, Eigen::VectorXd& c) const;
  /// H Zc (kept) and the extra directions' columns from Z, H Z (nz each,
  /// 9 x #unknowns); returns Zc^T H Zc.
  Eigen::MatrixXd coarse_products(const std::vector<Mat9X>& Z, const std::vector<Mat9X>& HZ);
  /// inv_, the neutral modes and the form (balancing or additive) from Zc^T H Zc.
  void invert_coarse_matrix(const Eigen::MatrixXd& Ec);
  /// out = a + s M c over the entries (a may be out), in parallel.
  static void combine(const Mat9X& a, double s, const Eigen::MatrixXd& M, const Eigen::VectorXd& c, Mat9X& out);
  /// c = Z^T v from the turns' shared fields and the recycled columns
  /// (the same fixed chunks over the unknowns: thread-count independent).
  void project_Z(const Mat9X& v, Eigen::VectorXd& c) const;
  /// out = a + s Z c (a may be out), in parallel.
  void combine_Z(const Mat9X& a, double s, const Eigen::VectorXd& c, Mat9X& out) const;

  const UnknownLayout& layout_;
  double alpha_;
  std::vector<const Mat9X*> follow_;  // Phi_b on the soft unknowns, per bone
  std::vector<Mat3> turn_;            // M_bk, column 3 b + k of Z
  // H Zc, one column per coarse coordinate (vec of its 9 x #unknowns array),
  // and the recycled directions' columns of Z (after the 3 #bones turns): an
  // application streams each once per use, not once per column.
  Eigen::MatrixXd HZ_, Zx_;
  Eigen::MatrixXd Tc_;   // nz x nc: Z's directions -> the coarse coordinates (Zc = Z Tc)
  Eigen::MatrixXd inv_;  // pseudo-inverse of Zc^T H Zc (nc x nc)
  bool built_ = false, balancing_ = false;
  std::vector<NeutralMode> neutral_;
  mutable Mat9X r1_;
  mutable Eigen::MatrixXd parts_;    // nz by kSumChunks partial projections (H Z)
  mutable Eigen::MatrixXd parts_z_;  // the same for Z's (9 #bones + recycled rows): no resize per use
  mutable Eigen::VectorXd c1_, c2_, cz_;
  mutable std::vector<Mat3> combined_;  // sum_k c_bk M_bk per bone (combine_Z)
};

template <class Base>
void BoneCoarseSpace::apply(const Mat9X& in, Mat9X& out, Base&& base) const {
  if (!built_) {
    base(in, out);
    return;
  }
  // in the coarse coordinates (Zc = Z Tc); Z's own coefficients for combine_Z
  if (balancing_) {
    project_Z(in, cz_);
    c2_.noalias() = Tc_.transpose() * cz_;
    c1_.noalias() = inv_ * c2_;        // c1 = (Zc^T H Zc)^-1 Zc^T r
    combine(in, -1.0, HZ_, c1_, r1_);                // r1 = r - H Zc c1
    base(r1_, out);
    project(HZ_, out, c2_);
    c1_.noalias() -= inv_ * c2_;  // c1 - c2, c2 = (Zc^T H Zc)^-1 (H Zc)^T B r1
    cz_.noalias() = Tc_ * c1_;
    combine_Z(out, 1.0, cz_, out);
    return;
  }
  base(in, out);
  project_Z(in, cz_);
  c2_.noalias() = Tc_.transpose() * cz_;
  c1_.noalias() = inv_ * c2_;
  cz_.noalias() = Tc_ * c1_;
  combine_Z(out, 1.0, cz_, out);
}

}  // namespace emu
