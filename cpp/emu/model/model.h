#pragma once
// The scene as the solvers see it: flat per-tet arrays, no names. Python's
// emu.Scene builds one of these; nothing here knows about parts or files.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "emu/energy/material.h"
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
  // Joints declared at points (for bones that share no vertex there): row i
  // joins movable bone joint_bones(i, 0) to joint_bones(i, 1), another movable
  // bone or -1 for the world (a fixed or scripted bone), at rest point
  // joint_points.row(i). A ball joint is one row, a hinge two rows on its axis.
  Eigen::MatrixX3d joint_points;  // #J by 3
  Eigen::MatrixX2i joint_bones;   // #J by 2
  // #bones passive rotational stiffness k of each movable bone about its rest
  // orientation: energy k/2 (3 - tr R) = k (1 - cos theta) ~ k theta^2 / 2
  // for a turn theta (empty: none).
  Eigen::VectorXd bone_stiffness;
  int num_muscles = 0;
  int num_bones = 0;
  // The scene's tet of each tet here (#T; empty: tet t is the scene's tet t),
  // and the number of the scene's tets (0: #T). A scene's tets that carry no
  // unknowns (a fixed bone's) are left out; the solvers store the rest in an
  // order of their own (tet_order.h) and take and give per-tet results in
  // the scene's order (SolveResult::F).
  Eigen::VectorXi scene_tet;
  int num_scene_tets = 0;

  /// Throws std::invalid_argument naming the first inconsistency found.
  void validate() const;
  /// The scene's tet count (num_scene_tets, or #T when it is 0).
  Eigen::Index scene_tet_count() const { return num_scene_tets > 0 ? num_scene_tets : tets.rows(); }
  /// The scene's index of tet t.
  Eigen::Index scene_index(Eigen::Index t) const { return scene_tet.size() ? scene_tet(t) : t; }
};

/// One frame's loads and boundary values.
struct LoadCase {
  Eigen::VectorXd activation;      // #muscles absolute activation a (>= 0)
  Eigen::MatrixX3d pin_positions;  // #P by 3 targets of the pinned vertices (empty: rest)
  Eigen::Vector3d gravity = Eigen::Vector3d::Zero();  // acceleration
  Eigen::MatrixX3d joint_targets;  // #J by 3 where declared world joints are (empty: rest)
  // An implicit time step's inertia (energy/inertia.h): weight w = 1 / h_eff^2
  // (0: a quasi-static solve) and the #V by 3 predicted positions y.
  double inertia_weight = 0.0;
  Eigen::MatrixX3d inertia_target;
};

/// Full #V by 3 positions: free rows from x_free (num_free by 3), pinned rows
/// from the load case (or rest).
Eigen::MatrixX3d pinned_positions(const Model& model, const LoadCase& load);

/// Activation per tet (0 where a tet belongs to no muscle).
Eigen::VectorXd tet_activation(const Model& model, const LoadCase& load);

/// The material of soft tet t under per-tet activations act (#T): the one
/// place a tet's Lame parameters, activation and fibre are put together.
inline TetMaterial tet_material(const Model& model, const Eigen::VectorXd& act, Eigen::Index t) {
  return {model.mu(t), model.lambda(t), act(t), model.fiber.row(t).transpose()};
}

void validate_load(const Model& model, const LoadCase& load);

}  // namespace emu
