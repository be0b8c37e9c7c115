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
  int num_muscles = 0;

  /// Throws std::invalid_argument naming the first inconsistency found.
  void validate() const;
};

/// One frame's loads and boundary values.
struct LoadCase {
  Eigen::VectorXd activation;      // #muscles absolute activation a (>= 0)
  Eigen::MatrixX3d pin_positions;  // #P by 3 targets of the pinned vertices (empty: rest)
  Eigen::Vector3d gravity = Eigen::Vector3d::Zero();  // acceleration
};

/// Derived, immutable data shared by the solvers.
struct Discretization {
  TetGeometry geometry;
  Eigen::VectorXi free_index;  // #V index among free vertices, -1 if pinned
  int num_free = 0;
  Eigen::VectorXd lumped_mass;  // #V
  explicit Discretization(const Model& model);
};

/// Full #V by 3 positions: free rows from x_free (num_free by 3), pinned rows
/// from the load case (or rest).
Eigen::MatrixX3d pinned_positions(const Model& model, const LoadCase& load);

/// Activation per tet (0 where a tet belongs to no muscle).
Eigen::VectorXd tet_activation(const Model& model, const LoadCase& load);

void validate_load(const Model& model, const LoadCase& load);

}  // namespace emu
