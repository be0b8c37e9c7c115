#pragma once
// EMU's movable bones in joint coordinates over the bone forest (bone_forest.h).
//
// A hinge between two movable bones ties their rotations, R_c e = R_p e (e
// the hinge's rest axis): a curved set in SO(3) x SO(3). Turned bone by bone,
// a step consistent with the hinge leaves that set at second order and the
// fit's stiff bone coupling punishes it (a penalty method's Maratos effect:
// cut steps). In joint coordinates every bone's turn is the sum of its chain's
// joint turns, so every step and every trial of the line search keeps the
// joints exactly (docs/DESIGN.md, "Chains of bones in EMU").
//
// Turns are world vectors. Joint j turns by tau_j = A_j theta_j (A_j: I for a
// free root or a ball, the current axis a_j = R_j e_j for a hinge); bone b's
// turn is omega_b = sum_{j in chain(b)} tau_j, i.e. omega = T theta with the
// turn map T (3 #bones by size()). A bone column of the unknowns (9 x
// #unknowns, bone b at column num_soft + b) holds a tangent [omega_b]x R_b;
// its metric is 2 |omega_b|^2, so the joint-consistent tangents are the range
// of T and their orthogonal projection is omega -> T (T'T)^-1 T' omega.
//
// The retraction turns the tree, root first:
//   R_b(s) = exp(s tau_r) ... exp(s tau_b) R_b     (r .. b: chain(b)),
// whose second derivative is (sum tau)^2 R_b + sum_{i above j} [tau_i x tau_j]x R_b.
// The first part is SO(3)'s per-bone curvature (bone_rotations.h); the second
// is the chain's:  H_c(theta, theta) = sum_b gamma_b . sum_{i above j in chain(b)} tau_i x tau_j,
// gamma_b = vee2(G_b R_b^T) the world torque of bone b's Euclidean gradient
// G_b (<G_b, [u]x R_b> = u . gamma_b). Its derivative in theta_j is
//   (1/2) A_j' sum_{b below j} (omega_b - tau_j - 2 omega_parent(j)) x gamma_b.
#include <vector>

#include <Eigen/Core>

#include "emu/energy/types.h"
#include "emu/solvers/emu/acap.h"
#include "emu/solvers/bone_forest.h"

namespace emu {

class JointCoordinates {
 public:
  /// num_soft: the soft unknowns before the bone columns.
  JointCoordinates(BoneForest forest, int num_soft);

  int bones() const { return static_cast<int>(forest_.bones.size()); }
  /// Number of joint coordinates: 3 per free root or ball, 1 per hinge.
  int size() const { return size_; }
  /// The offset of bone b's joint coordinates.
  int offset(int b) const { return offset_[b]; }
  const BoneForest& forest() const { return forest_; }

  /// T (3 #bones by size()) at F's rotations: bone b's world turn from the joint coordinates.
  Eigen::MatrixXd turn_map(const Mat9X& F) const;

  /// v's bone columns projected onto the joint-consistent tangents at F (the
  /// orthogonal projection; it includes SO(3)'s tangent projection).
  void project(const Mat9X& F, Mat9X& v) const;

  /// The joint coordinates of v's bone columns (their least-squares fit: exact
  /// for a joint-consistent tangent).
  Eigen::VectorXd coordinates(const Mat9X& F, const Mat9X& v) const;

  /// out = F + s d on the soft columns; the bones turned along the tree by the
  /// joint coordinates of d's bone columns (header), each child hinge's axis
  /// kept on its parent's to round-off.
  void retract(const Mat9X& F, const Mat9X& d, double s, Mat9X& out) const;

  /// The rotation term W (size() square, symmetric): the curvature of the
  /// tree's retraction, theta' W theta = sum_b <G_b, R_b''(0)> (header) for the
  /// Euclidean gradient g's bone columns G_b: SO(3)'s per bone, omega_b'
  /// (sym(G_b R_b') - tr(G_b R_b') I) omega_b, plus the chain's H_c. With
  /// `clamp` its negative eigenvalues are set to 0 (the PSD-filtered Newton
  /// model, as FEM's rigid bones clamp theirs per tree).
  Eigen::MatrixXd rotation_term(const Mat9X& F, const Mat9X& g, bool clamp) const;

  /// out's bone columns += W theta(v) as the joint-consistent tangent it represents.
  void add_rotation_product(const Mat9X& F, const Eigen::MatrixXd& W, const Mat9X& v, Mat9X& out) const;

  /// F's bone rotations moved onto the joints, roots first: a root hinge
  /// turned (the least turn) to put its axis on its targets' (h: the joint
  /// points' targets, AcapOperator::joint_targets), a child hinge onto its
  /// parent's. Balls and free bones are unchanged.
  void project_onto_joints(Mat9X& F, const Eigen::MatrixX3d& h) const;

 private:
  /// The world axes of bone b's joint turns at F (3 by 3 or 3 by 1).
  Eigen::Matrix<double, 3, Eigen::Dynamic> axes(const Mat9X& F, int b) const;
  /// omega (3 #bones): the world turn of each of v's bone columns at F (their tangent part).
  Eigen::VectorXd world_turns(const Mat9X& F, const Mat9X& v) const;
  /// theta = (T'T)^-1 T' omega for world turns omega (3 #bones).
  Eigen::VectorXd fit(const Eigen::MatrixXd& T, const Eigen::VectorXd& omega) const;
  /// gradient_theta (size()) as the joint-consistent tangent it represents, added to out's bone columns.
  void add_tangent(const Mat9X& F, const Eigen::MatrixXd& T, const Eigen::VectorXd& grad, Mat9X& out) const;
  /// The derivative of H_c(., theta) in the joint coordinates (header).
  Eigen::VectorXd curvature_gradient(const Mat9X& F, const Mat9X& g, const Eigen::VectorXd& theta) const;
  Mat3 rotation(const Mat9X& F, int b) const { return unflatten(F.col(num_soft_ + b)); }

  BoneForest forest_;
  int num_soft_ = 0, size_ = 0;
  std::vector<int> offset_, dims_;
};

}  // namespace emu
