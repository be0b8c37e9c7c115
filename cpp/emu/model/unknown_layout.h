#pragma once
// The unknown layout: which numbers each solver solves for, derived once from
// a Model and shared (immutable) by both solvers.
//
// Position unknowns (FEM's Newton, EMU's ACAP fit):
//   free_index(v)  #V  index among the free soft vertices, -1 for a vertex that
//                      is pinned or moves with a movable bone;
//   vertex_bone(v) #V  the movable bone that places vertex v (lowest id where
//                      two share it), -1 otherwise;
//   joints             every point of a movable bone that something else also
//                      places (a pinned vertex, another bone, a declared joint).
// Deformation unknowns (EMU): one F per soft tet, in tet order, then one per
// movable bone (all its tets share it):
//   tet_unknown(t)  #T  the F unknown tet t uses;
//   unknown_ptr / unknown_tets  the tets of each unknown (CSR, tet order).
// Beside it, the rest data every solver needs: the tet geometry (volumes,
// shape gradients) and the lumped vertex masses.
#include <vector>

#include <Eigen/Core>

#include "emu/mesh/tet_geometry.h"
#include "emu/model/model.h"

namespace emu {

/// A point of a movable bone that something else also places: a vertex it
/// shares with a pinned vertex (fixed or scripted bone, user pin; other = -1)
/// or with another movable bone (other = that bone, which owns the vertex's
/// position), or a declared joint point (vertex = -1, declared = its row).
struct JointPoint {
  Eigen::Vector3d rest;
  int vertex, bone, other, declared;
};

struct UnknownLayout {
  TetGeometry geometry;
  Eigen::VectorXd lumped_mass;  // #V

  // Position unknowns.
  Eigen::VectorXi free_index;  // #V
  int num_free = 0;
  // Movable bones.
  int num_bones = 0;
  Eigen::VectorXi vertex_bone;    // #V
  Eigen::MatrixX3d bone_center;   // #bones by 3 rest centroids of each bone's vertices
  std::vector<JointPoint> joints;
  /// Whether an unknown moves vertex v: free, or on a movable bone (gravity's
  /// and a time step's inertia act on these; the rest are pinned or fixed).
  bool moves(Eigen::Index v) const { return free_index(v) >= 0 || vertex_bone(v) >= 0; }

  // Deformation unknowns.
  int num_unknowns = 0, num_soft = 0;
  Eigen::VectorXi tet_unknown;  // #T
  std::vector<int> unknown_ptr, unknown_tets;
  bool is_bone_tet(Eigen::Index t) const { return tet_unknown(t) >= num_soft; }

  explicit UnknownLayout(const Model& model);
};

}  // namespace emu
