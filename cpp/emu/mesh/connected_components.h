#pragma once
// The connected pieces of a tet mesh's vertex graph (two vertices are joined
// when a tet holds both): union-find, one pass over the tets.
#include <Eigen/Core>

namespace emu {

/// num_vertices  #V
/// T             #T by 4 vertex ids in [0, #V)
/// Returns #V labels: each vertex's label is the smallest vertex id of its
/// piece (a vertex of no tet is a piece of its own). Throws
/// std::invalid_argument on an id outside [0, #V).
Eigen::VectorXi connected_components(int num_vertices, const Eigen::MatrixX4i& T);

}  // namespace emu
