#pragma once
// Which query points lie within a distance of a triangle surface, and how far:
// a uniform grid over the triangles' bounding boxes, then the exact
// point-triangle distance against the triangles of the query's cell.
#include <Eigen/Core>

namespace emu {

/// The closest point to p on the triangle (a, b, c), by the region of the
/// triangle's plane p projects into (vertex, edge or face); degenerate
/// triangles fall back to the nearest of their edges' closest points.
Eigen::Vector3d closest_point_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                          const Eigen::Vector3d& b, const Eigen::Vector3d& c);

/// V             #V by 3 surface vertex positions
/// F             #F by 3 triangle vertex ids in [0, #V)
/// Q             #Q by 3 query points
/// max_distance  only distances <= max_distance are found (> 0)
/// distance      (out) #Q distances to the nearest triangle, +inf where none is within max_distance
/// nearest       (out) #Q ids of that triangle, -1 where none
/// Throws std::invalid_argument on an id outside [0, #V) or max_distance <= 0.
void near_surface(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const Eigen::MatrixX3d& Q,
                  double max_distance, Eigen::VectorXd& distance, Eigen::VectorXi& nearest);

}  // namespace emu
