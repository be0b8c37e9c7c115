#pragma once
// FEM's movable bones: rigid bodies x_v = R_b (X_v - P_b) + p_b, in trees.
//
// Bones form a forest: a root is held by the world (one point shared with a
// pinned vertex, a fixed bone or a declared world joint: a ball; two or more
// on a line: a hinge) or by nothing (free: 6 unknowns); a child turns about
// its joint with its parent bone (ball: 3 unknowns, hinge: 1, the axis
// carried by the parent). Reduced joint coordinates, not constraint rows: the
// joints hold exactly at every iterate, the unknowns stay few and the bone
// Schur complement stays definite (docs/DESIGN.md, "Chains of bones in FEM").
//
// The Newton unknowns are exponential-map increments about the current state,
// re-linearised every iteration: bone b's increment turns b and everything
// below it about b's pivot p_b, by exp(theta [u]_x) for each axis u of b (ball
// and free: e_x, e_y, e_z; hinge: its current axis). A step applies the
// deepest bones' increments first, so x = T_root(... T_b(X)) and
//   dx/d(theta_u of a) = u x (x - p_a)             (a any ancestor-or-self),
//   d2x/d(theta_u of a) d(theta_v of b) = u x (v x (x - p_b))   (a above b),
//   the same symmetrised for a = b.
// With forces f = dE/dx, M_b = sum over the vertices below b of f (x - p_b)^T
// gives the rotation's second-order term U_a^T (M_b^T - tr(M_b) I) U_b for a
// above b and U_b^T (sym(M_b) - tr(M_b) I) U_b on the diagonal; a joint spring
// on R_b adds U_a^T (H_w - [g_w]_x / 2) U_c for a above c in b's chain (g_w,
// H_w: its exponential-map gradient and Hessian, energy/joint_spring.h).
// The bone rows border the soft-vertex Newton matrix:
//   [ H_ss  H_sb ] [ds]   [-g_s]     H_sb = sum_t K_t,ac J_c,
//   [ H_sb' H_bb ] [db] = [-g_b],    H_bb = sum_t J_a' K_t,ac J_c + rotation term,
// solved with the factor of H_ss, one back-substitution per bone unknown and
// the dense Schur complement S = H_bb - H_sb' H_ss^-1 H_sb.
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "emu/energy/types.h"
#include "emu/model/unknown_layout.h"
#include "emu/solvers/bone_forest.h"
#include "emu/solvers/newton/result.h"

namespace emu {

/// One movable bone's pose: x_v = R (X_v - P) + p; a hinge's current axis.
struct BonePose {
  Mat3 R = Mat3::Identity();
  Vec3 p = Vec3::Zero();
  Vec3 axis = Vec3::UnitX();
};
using BonePoses = std::vector<BonePose>;

class RigidBones {
 public:
  /// The bone forest and each bone's kind (free, ball, hinge) from the joints'
  /// rest points; throws std::invalid_argument for a welded bone (its joint
  /// points not on one line) or a closed loop of joints.
  RigidBones(const Model& model, const UnknownLayout& layout);

  int size() const { return static_cast<int>(bones_.size()); }
  /// Number of bone unknowns in the Newton system.
  int dofs() const { return dofs_; }
  /// Soft tets with a corner on a movable bone (the only ones in the border).
  const std::vector<int>& touching_tets() const { return touching_; }

  /// Per solve: the start poses, roots first: the best rigid fit of `initial`
  /// (#V by 3; nullptr: rest), a root moved onto its joints' targets (a root
  /// hinge's axis from them), a child onto its parent's joint (a child
  /// hinge turned about its axis only). x: #V by 3 with the pinned rows set.
  BonePoses begin(const LoadCase& load, const Eigen::MatrixX3d& x, const Eigen::MatrixX3d* initial);

  /// Poses after the Newton increment s db (exponential map).
  BonePoses moved(const BonePoses& poses, const Eigen::VectorXd& db, double s) const;
  /// Writes the rows of x (#V by 3) of every vertex that moves with a bone.
  void place(const BonePoses& poses, Eigen::MatrixX3d& x) const;

  double spring_energy(const BonePoses& poses) const;
  /// gb (dofs): the bone rows of the gradient, J' f over each bone's vertices
  /// (f: #V by 3 dE/dx at bone vertices) plus the joint springs.
  void gradient(const BonePoses& poses, const Eigen::MatrixX3d& x, const Eigen::MatrixX3d& f,
                Eigen::VectorXd& gb) const;
  /// sqrt(soft_norm2 + |gb|^2) with torques over the bounding-box diagonal
  /// (so the whole norm is in units of force).
  double gradient_norm(double soft_norm2, const Eigen::VectorXd& gb) const;

  /// The border Hsb (3 #free by dofs) and Hbb (dofs by dofs) from the 12 x 12
  /// element Hessians `element` (144 per tet, column-major), at positions x
  /// with vertex forces f. exact = false clamps the rotation term to PSD.
  void assemble_border(const BonePoses& poses, const std::vector<double>& element, const Eigen::MatrixX3d& x,
                       const Eigen::MatrixX3d& f, bool exact, Eigen::MatrixXd& Hsb, Eigen::MatrixXd& Hbb) const;

  /// Adds to the border the part of a position Hessian H (3 #V by 3 #V, both
  /// triangles, dof 3 v + i; a contact term's) that couples bone vertices:
  /// Hsb += H_sb J, Hbb += J' H_bb J at positions x.
  void add_vertex_hessian(const BonePoses& poses, const Eigen::MatrixX3d& x, const Eigen::SparseMatrix<double>& H,
                          Eigen::MatrixXd& Hsb, Eigen::MatrixXd& Hbb) const;

  /// Solves S db = rb for the bone Schur complement S at poses. Exact: false
  /// unless S is positive definite. Filtered: where S is singular (a turn
  /// nothing resists) its pseudo-inverse leaves that direction alone and
  /// `neutral` records it; false if S is indefinite beyond round-off.
  bool solve_schur(const BonePoses& poses, const Eigen::MatrixXd& S, const Eigen::VectorXd& rb, bool exact,
                   Eigen::VectorXd& db, std::vector<NeutralMode>& neutral) const;

  /// Why a solve that ran out of iterations may have: where S's smallest
  /// eigenvalue is under kWeakTurn of its largest, "; the turn of movable bone
  /// b about (x, y, z) is resisted ... (a near-neutral mode): ..." naming the
  /// fixes; else "".
  std::string weakest_turn(const BonePoses& poses, const Eigen::MatrixXd& S) const;
  static constexpr double kWeakTurn = 1e-2;

 private:
  using Kind = BoneForest::Kind;
  struct Bone : BoneForest::Node {  // the forest's node (bone_forest.h) and FEM's unknowns
    int offset = 0, dofs = 6;
    std::vector<int> vertices;  // non-pinned vertices placed by the bone
  };
  /// 3 x dofs(): the Jacobian of a vertex of bone b at current position x,
  /// written into J (columns of bones outside b's chain zero).
  void vertex_jacobian(int b, const Vec3& x, const BonePoses& poses,
                       Eigen::Matrix<double, 3, Eigen::Dynamic>& J) const;
  /// The turn axes of bone b at poses, as columns (ball and free: I; hinge: its axis).
  Eigen::Matrix<double, 3, Eigen::Dynamic> axes(int b, const BonePoses& poses) const;
  /// Adds the rotation's second-order term and the joint springs' Hessian to Hbb.
  void add_rotation_term(const BonePoses& poses, const Eigen::MatrixX3d& x, const Eigen::MatrixX3d& f, bool exact,
                         Eigen::MatrixXd& Hbb) const;

  const Model& model_;
  const UnknownLayout& layout_;
  double diag_;
  std::vector<Bone> bones_;
  std::vector<int> order_;      // roots first, then each bone after its parent
  int dofs_ = 0;
  std::vector<int> touching_;
};

}  // namespace emu
