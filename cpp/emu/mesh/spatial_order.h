#pragma once
// An order of a tet mesh's tets along a Z-order (Morton) curve through their
// centroids: tets near each other in space come out near each other, so that
// per-vertex sums over per-tet arrays read memory that is close together.
#include <vector>

#include <Eigen/Core>

namespace emu {

/// X  #V by 3 positions
/// T  #T by 4 vertex ids in [0, #V)
/// Returns #T tet ids, a permutation of 0..#T-1, sorted by the 30-bit Morton
/// code of each centroid on a 1024^3 grid over the centroids' bounding cube;
/// equal codes keep their order in T. Throws std::invalid_argument on an id
/// outside [0, #V).
std::vector<int> spatial_order(const Eigen::MatrixX3d& X, const Eigen::MatrixX4i& T);

}  // namespace emu
