#pragma once
// The scene as the solvers see it: flat per-tet arrays, no names. Python's
// emu.Scene builds one of these; nothing here knows about parts or files.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "emu/mesh/tet_geometry.h"

namespace emu {

struct Model {
  Eigen::MatrixX3d rest;        // #V by 3 rest positions
  Eigen::MatrixX4i tets;        // #T by 4 vertex indices, positively oriented
  Eigen::VectorXd mu;           // #T shear modulus (Lame mu)
  Eigen::VectorXd lambda;       // #T Lame lambda
  Eigen::VectorXd density;      // #T mass per unit rest volume (gravity only)
  Eigen::VectorXd acap_weight;  // #T ACAP weight w_t (EMU only; tendons > 1)
  Eigen::MatrixX3d fiber;       // #T by 3 unit fibre directions (rows of zeros where unused)
  Eigen::VectorXi muscle;       // #T index of the muscle that activates the tet, -1 if none
  Eigen::VectorXi pinned;       // #P pinned vertex ids (sorted, unique)
  // #T index of the movable (rigid) bone a tet belongs to, -1 for soft tissue;
  // empty means no movable bones. A movable bone moves rigidly: its vertices
  // follow one rotation and translation; its tets carry no elastic energy.
  // Vertices a bone shares with a pinned vertex or another bone are joints.
  Eigen::VectorXi bone;
  int num_muscles = 0;
  int num_bones = 0;

  /// Throws std::invalid_argument naming the first inconsistency found.
  void validate() const;
};

/// One frame's loads and boundary values.
struct LoadCase {
  Eigen::VectorXd activation;      // #muscles absolute activation a (>= 0)
  Eigen::MatrixX3d pin_positions;  // #P by 3 targets of the pinned vertices (empty: rest)
  Eigen::Vector3d gravity = Eigen::Vector3d::Zero();  // acceleration
};

/// A vertex a movable bone shares with something that also places it: a
/// pinned vertex (fixed or scripted bone, user pin; other = -1) or another
/// movable bone (other = that bone, which owns the vertex's position).
struct JointVertex {
  int vertex, bone, other;
};

/// Derived, immutable data shared by the solvers.
struct Discretization {
  TetGeometry geometry;
  // #V index among free soft vertices (the per-vertex unknowns), -1 for pinned
  // vertices and for vertices that move with a bone
  Eigen::VectorXi free_index;
  int num_free = 0;
  Eigen::VectorXd lumped_mass;  // #V
  // Bones. vertex_bone: #V bone that places the vertex (lowest bone id if it is
  // shared; -1 for soft and pinned vertices).
  int num_bones = 0;
  Eigen::VectorXi vertex_bone;
  Eigen::MatrixX3d bone_center;        // num_bones by 3 rest centroids of each bone's vertices
  std::vector<JointVertex> joints;
  // EMU unknowns: one per soft tet (in tet order), then one per bone.
  // owner: #T unknown of each tet; unknown_ptr/unknown_tets: the tets of each
  // unknown (CSR).
  int num_unknowns = 0, num_soft = 0;
  Eigen::VectorXi owner;
  std::vector<int> unknown_ptr, unknown_tets;
  bool is_bone_tet(Eigen::Index t) const { return owner(t) >= num_soft; }
  explicit Discretization(const Model& model);
};

/// Full #V by 3 positions: free rows from x_free (num_free by 3), pinned rows
/// from the load case (or rest).
Eigen::MatrixX3d pinned_positions(const Model& model, const LoadCase& load);

/// Activation per tet (0 where a tet belongs to no muscle).
Eigen::VectorXd tet_activation(const Model& model, const LoadCase& load);

void validate_load(const Model& model, const LoadCase& load);

}  // namespace emu
