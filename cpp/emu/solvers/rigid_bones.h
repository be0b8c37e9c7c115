#pragma once
// FEM's movable bones: rigid bodies x_v = R_b (X_v - P_b) + p_b.
//
// Their Newton unknowns are exponential-map increments, re-linearised every
// iteration (R <- exp([w]_x) R): a free bone has w and a translation (6
// unknowns), a bone on a ball joint (one point shared with a pinned vertex, a
// fixed bone or a declared world joint) turns about it (w, 3), a hinge (two or
// more such points on a line) about its axis (1 unknown). The bone rows border
// the soft-vertex Newton matrix:
//   [ H_ss  H_sb ] [ds]   [-g_s]     H_sb = sum_t K_t,ac J_c,
//   [ H_sb' H_bb ] [db] = [-g_b],    H_bb = sum_t J_a' K_t,ac J_c + rotation term,
// solved with the factor of H_ss, one back-substitution per bone unknown and
// the dense Schur complement S = H_bb - H_sb' H_ss^-1 H_sb. The rotation's
// second-order term (from d2/dw2 of R(w) r) is
//   sum_v [ (f_v r_v' + r_v f_v')/2 - (f_v . r_v) I ]   (f = dE/dx, r = x - p),
// plus the joint springs' (energy/joint_spring.h). Joints between two movable
// bones are not supported here.
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "emu/energy/types.h"
#include "emu/model/unknown_layout.h"
#include "emu/solvers/newton/result.h"

namespace emu {

/// One movable bone's pose: x_v = R (X_v - P) + p.
struct BonePose {
  Mat3 R = Mat3::Identity();
  Vec3 p = Vec3::Zero();
};
using BonePoses = std::vector<BonePose>;

class RigidBones {
 public:
  /// Kinds (free, ball, hinge) from the joints' rest points; throws
  /// std::invalid_argument for a welded bone or a joint between two movable bones.
  RigidBones(const Model& model, const UnknownLayout& layout);

  int size() const { return static_cast<int>(bones_.size()); }
  /// Number of bone unknowns in the Newton system.
  int dofs() const { return dofs_; }
  /// Soft tets with a corner on a movable bone (the only ones in the border).
  const std::vector<int>& touching_tets() const { return touching_; }

  /// Per solve: hinge axes from the joints' targets, and the start poses (the
  /// best rigid fit of `initial` (#V by 3; nullptr: rest), moved onto the
  /// joints' targets). x: #V by 3 with the pinned rows set.
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

  /// Solves S db = rb for the bone Schur complement S. Exact: false unless S is
  /// positive definite. Filtered: where S is singular (a turn nothing resists)
  /// its pseudo-inverse leaves that direction alone and `neutral` records it;
  /// false if S is indefinite beyond round-off.
  bool solve_schur(const Eigen::MatrixXd& S, const Eigen::VectorXd& rb, bool exact, Eigen::VectorXd& db,
                   std::vector<NeutralMode>& neutral) const;

 private:
  enum class Kind { Free, Ball, Hinge };
  struct Bone {
    Kind kind = Kind::Free;
    int offset = 0, dofs = 6;
    int axis_end = -1;          // hinge: the anchor that spans the axis with the pivot
    Vec3 P = Vec3::Zero();      // rest pivot
    Vec3 axis = Vec3::UnitX();  // hinge: the current axis (set per solve)
    std::vector<int> vertices;  // non-pinned vertices placed by the bone
    std::vector<int> anchors;   // the layout's joint points on this bone
  };
  /// 3 x dofs Jacobian of a bone vertex at current offset r = x - p.
  Eigen::Matrix<double, 3, Eigen::Dynamic> jacobian(const Bone& B, const Vec3& r) const;

  const Model& model_;
  const UnknownLayout& layout_;
  double diag_;
  std::vector<Bone> bones_;
  int dofs_ = 0;
  std::vector<int> touching_;
};

}  // namespace emu
