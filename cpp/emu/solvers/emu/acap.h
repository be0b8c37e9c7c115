#pragma once
// The ACAP fit x*(F): the positions whose per-tet deformation gradients best
// match the targets F in the weighted least-squares sense,
//   E_C(x, F) = alpha/2 sum_t w_t V_t |F_t(x) - F_own(t)|^2,
// over the position unknowns z, per coordinate:
//   - one scalar per free soft vertex (y), and
//   - four per movable bone (q_b): a bone vertex sits at x_v = A_b (X_v - Xbar_b) + c_b,
//     so per coordinate x_v[c] = phi_v . q_b[c] with phi_v = (X_v - Xbar_b, 1);
// subject to the joint rows J q = h (a bone vertex that is pinned must sit at
// its target; one shared by two bones must agree). Pins, bone maps and joints
// all act on whole vertices, so the matrix is K = L (x) I_3 with the scalar
// L = S^T L_vertex S: each fit is a solve with 3 right-hand sides.
//
// L is bordered: the soft block L_ss (sparse, CHOLMOD, factorised once), the
// bone block L_bb (4 #bones, dense) and the coupling L_sb. With
// W = L_ss^-1 L_sb and the bone Schur complement S_b = L_bb - L_sb^T W (both
// formed once), a fit is
//   y0 = L_ss^-1 r_s,   min_q 1/2 q^T S_b q - q^T (r_b - W^T r_s)  s.t.  J q = h,
//   y = y0 - W q,
// one back-substitution plus small dense work: the constant-matrix property is
// kept. The bone problem is solved in the null space of J (SVD once), which
// also drops redundant joint rows. alpha cancels from the fit.
#include <memory>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "emu/linalg/cholmod_factor.h"
#include "emu/mesh/block_pattern.h"
#include "emu/model/unknown_layout.h"

namespace emu {

using Mat9X = Eigen::Matrix<double, 9, Eigen::Dynamic>;

/// F_t(x) for every tet, as columns vec(F_t) of a 9 x #T matrix. x: #V by 3.
void deformation_gradients(const UnknownLayout& layout, const Eigen::MatrixX4i& T,
                           const Eigen::MatrixX3d& x, Mat9X& out);

/// Per-tet copies of the EMU unknowns: out.col(t) = U.col(tet_unknown(t)). U: 9 x #unknowns.
void expand_unknowns(const UnknownLayout& layout, const Mat9X& U, Mat9X& out);
/// The per-tet view of unknowns U: U itself when every unknown is one tet (no
/// bones: no copy), else U expanded into buf.
const Mat9X& per_tet_view(const UnknownLayout& layout, const Mat9X& U, Mat9X& buf);
/// Sums of per-tet columns into their unknowns (fixed order). per_tet: 9 x #T;
/// without bones it is moved into out (no copy) and left empty.
void reduce_to_unknowns(const UnknownLayout& layout, Mat9X& per_tet, Mat9X& out);

class AcapOperator {
 public:
  /// weight_volume  #T per-tet weights of the fit (nullptr: the ACAP weights
  ///                w_t V_t; ConstantSchur builds the same operator with others)
  /// pattern_of     an operator of the same model and layout whose assembly
  ///                pattern, symbolic analysis and weight-independent bone
  ///                data (rigid tets, bone corners) are reused (nullptr: its own)
  /// single_precision  every solve with the factor rounded to float, the bone
  ///                elimination's included: the exact inverse of the rounded
  ///                matrix, for a preconditioner (ConstantSchur's own S0)
  /// free_diagonal  #free values added to the scalar matrix's diagonal (nullptr:
  ///                none; ConstantSchur's inertia)
  AcapOperator(const Model& model, const UnknownLayout& layout, const Eigen::VectorXd* weight_volume = nullptr,
               const AcapOperator* pattern_of = nullptr, bool single_precision = false,
               const Eigen::VectorXd* free_diagonal = nullptr);

  /// Number of scalar position unknowns per coordinate: num_free + 4 #bones.
  int dofs() const { return ns_ + nq_; }
  bool has_bones() const { return nq_ > 0; }
  int constraint_rank() const { return rank_; }

  /// Writes every non-pinned row of x (#V by 3) with the fit to per-tet targets
  /// F (9 x #T). F_pinned (9 x #T): F_t of the positions with only the pinned
  /// rows set (their share of every F_t(x)). h: joint targets (see
  /// joint_targets), nullptr for homogeneous joints (a displacement fit).
  void fit(const Mat9X& F, const Mat9X* F_pinned, const Eigen::MatrixX3d* h, Eigen::MatrixX3d& x) const;

  /// Joint targets h (#joint rows by 3): pinned joint vertices from positions x
  /// (#V by 3, pinned rows set), declared world joints from declared (#J by 3;
  /// empty: rest).
  Eigen::MatrixX3d joint_targets(const Eigen::MatrixX3d& x, const Eigen::MatrixX3d& declared) const;

  /// Z = K_c^-1 R with homogeneous joints: R, Z are dofs() by ncols (any ncols).
  void solve(const Eigen::MatrixXd& R, Eigen::MatrixXd& Z) const { solve_with(R, nullptr, Z); }
  /// Z = K~^-1 R with the factor rounded to single precision (after
  /// keep_single_precision_copy; operators without movable bones only): for
  /// a preconditioner sharing the fit's operator, half the bytes streamed
  /// (ConstantSchur where S0 = c K).
  void solve_rounded(const Eigen::MatrixXd& R, Eigen::MatrixXd& Z) const;
  void keep_single_precision_copy() { factor_.keep_single_precision_copy(); }

  /// R = C D = S^T sum_t w_t V_t D_t b_a (dofs() by 3) for per-tet matrices D (9 x #T).
  void apply_C(const Mat9X& D, Eigen::MatrixX3d& R) const;
  /// The same for per-unknown matrices U (9 x #unknowns): each tet's D_t is its
  /// unknown's, read in place (no per-tet copy: per_tet_view).
  void apply_C_of_unknowns(const Mat9X& U, Eigen::MatrixX3d& R) const;
  /// The homogeneous fit (no pinned share, homogeneous joints) to per-unknown
  /// targets U: writes the non-pinned rows of x (#V by 3).
  void fit_of_unknowns(const Mat9X& U, Eigen::MatrixX3d& x) const;

  /// out_t = w_t V_t F_t(S u) (= C^T u) for position unknowns u (dofs() by 3).
  void apply_CT(const Eigen::MatrixX3d& u, Mat9X& out) const;

  /// R = S^T f: forces per vertex (#V by 3) to the position unknowns (dofs() by 3).
  void reduce_vertex(const Eigen::MatrixX3d& f, Eigen::MatrixX3d& R) const;

  /// Writes the non-pinned rows of x (#V by ncols) from position unknowns Z (dofs() by ncols).
  void expand(const Eigen::MatrixXd& Z, Eigen::MatrixXd& x) const;
  void expand(const Eigen::MatrixX3d& Z, Eigen::MatrixX3d& x) const;

  /// The scalar soft-block factor (L_ss).
  const CholmodFactor& factor() const { return factor_; }
  /// w_t V_t per tet.
  const Eigen::VectorXd& weight_volume() const { return wv_; }

 private:
  void solve_with(const Eigen::MatrixXd& R, const Eigen::MatrixXd* h, Eigen::MatrixXd& Z) const;
  /// same_model: an operator of the same model whose weight-independent bone
  /// data (rigid tets, bone corners) are copied (nullptr: computed).
  void setup_bones(const AcapOperator* same_model);
  // setup_bones' steps, with phi (4 x #V) of every bone vertex: which tets
  // touch a bone or are rigid and the bone corners (model data alone); the
  // rigid tets' weights per bone; L_sb, L_bb, W = L_ss^-1 L_sb and S_b; the
  // joint rows J, their null space and the reduced bone system.
  void classify_bone_tets(const Eigen::Matrix<double, 4, Eigen::Dynamic>& phi);
  void sum_rigid_tets();
  void eliminate_soft_block(const Eigen::Matrix<double, 4, Eigen::Dynamic>& phi);
  void setup_joint_rows();
  /// apply_C with D_t = target(t): a Mat3 or a Map of 9 doubles in column
  /// order, never a lazy expression (it is held with auto per tet).
  /// by_unknowns: target(t) is the unknown of tet t (apply_C_of_unknowns),
  /// so a bone's own rigid tets share their bone's target.
  template <class TargetOf>
  void apply_C_with(TargetOf&& target, Eigen::MatrixX3d& R, bool by_unknowns = false) const;

  bool rounded_ = false;  // single_precision: every factor solve with the rounded copy
  const Model& model_;
  const UnknownLayout& layout_;
  std::shared_ptr<const BlockPattern> pattern_;  // shared with pattern_of's (read only)
  CholmodFactor factor_;
  Eigen::VectorXd wv_;
  int ns_ = 0, nq_ = 0, rank_ = 0;
  // Bones: corners whose vertex moves with a bone (t * 4 + a, in fixed order)
  // and the vertex's phi; the coupling and the bone problem.
  std::vector<int> bone_corner_, bone_corner_bone_;
  std::vector<int> bone_tets_;  // tets with a vertex on a movable bone (L_sb, L_bb)
  // Rigid tets: all four vertices move with one bone b (a bone's own tets,
  // or tissue held between its vertices). Such a tet's corners add
  // sum_a phi_a (w V T b_a)^T = w V [T^T; 0] to b's rows of C T (sum_a b_a = 0,
  // sum_a X_a b_a^T = I), and its F_t(S u) is the linear part of b's map,
  // u_b's top three rows transposed: no per-corner work.
  std::vector<int> rigid_tets_, rigid_tet_bone_;
  std::vector<char> is_rigid_;  // #T with bones, else empty
  // Of the rigid tets, those whose unknown is their bone's own (the bone's
  // tets, not tissue held between its vertices) add the same T to their
  // bone's rows: apply_C_of_unknowns adds them at once, (sum w V) T_b^T per
  // bone (a serial loop over every such tet per application costs too much;
  // docs/DESIGN.md, "The cost of an iteration").
  Eigen::VectorXd rigid_own_wv_;                      // per bone: sum of w V over its own rigid tets
  std::vector<int> rigid_own_tets_;                   // per bone: one of them (-1: none)
  std::vector<int> rigid_other_tets_, rigid_other_bone_;  // the other rigid tets and their bones
  Eigen::Matrix<double, 4, Eigen::Dynamic> bone_corner_phi_;
  Eigen::MatrixXd W_;            // num_free x nq: L_ss^-1 L_sb
  Eigen::MatrixXd Sb_;           // nq x nq bone Schur complement
  Eigen::MatrixXd J_;            // #joint rows x nq
  Eigen::MatrixXd Jpinv_;        // nq x #joint rows: particular solution q_p = Jpinv h
  Eigen::MatrixXd N_;            // nq x (nq - rank): null space of J
  Eigen::LLT<Eigen::MatrixXd> reduced_;  // N^T S_b N
  mutable std::vector<double> corner_;
  mutable Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> rhs_rows_;
};

}  // namespace emu
