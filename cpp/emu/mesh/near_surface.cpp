#include "emu/mesh/near_surface.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

namespace emu {

namespace {

Eigen::Vector3d closest_on_segment(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  const Eigen::Vector3d ab = b - a;
  const double l2 = ab.squaredNorm();
  if (l2 <= 0.0) return a;
  return a + std::clamp((p - a).dot(ab) / l2, 0.0, 1.0) * ab;
}

// Grid cell of a point: integer coordinates of floor((x - origin) / h).
struct Grid {
  Eigen::Vector3d origin;
  double h;
  Eigen::Array3i dims;
  Eigen::Array3i cell(const Eigen::Vector3d& x) const {
    Eigen::Array3i c = ((x - origin).array() / h).floor().cast<int>();
    return c.max(0).min(dims - 1);
  }
  std::int64_t key(const Eigen::Array3i& c) const {
    return (std::int64_t(c[2]) * dims[1] + c[1]) * dims[0] + c[0];
  }
};

// The grid over the triangles' boxes grown by max_distance, and (cell key,
// triangle) for every cell a box touches, sorted by key; top: the grid's far corner.
// Cell size: the median triangle extent (at least twice the search distance),
// so a triangle spans few cells and a cell holds few triangles.
Grid bin_triangles(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, double max_distance, Eigen::Vector3d& top,
                   std::vector<std::pair<std::int64_t, int>>& cell_tri) {
  const Eigen::Index nf = F.rows();
  Eigen::MatrixX3d lo(nf, 3), hi(nf, 3);
  std::vector<double> extent(nf);
  for (Eigen::Index f = 0; f < nf; ++f) {
    const Eigen::Vector3d a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
    lo.row(f) = a.cwiseMin(b).cwiseMin(c).array() - max_distance;
    hi.row(f) = a.cwiseMax(b).cwiseMax(c).array() + max_distance;
    extent[f] = (hi.row(f) - lo.row(f)).maxCoeff();
  }
  std::nth_element(extent.begin(), extent.begin() + nf / 2, extent.end());
  Grid grid;
  grid.origin = lo.colwise().minCoeff().transpose();
  top = hi.colwise().maxCoeff().transpose();
  grid.h = std::max(extent[nf / 2], 2.0 * max_distance);
  // at most ~64 cells per triangle on average: a coarser grid for very uneven surfaces
  const Eigen::Array3d span = (top - grid.origin).array();
  while ((span / grid.h).ceil().prod() > 64.0 * double(nf) + 1.0) grid.h *= 2.0;
  grid.dims = (span / grid.h).ceil().cast<int>().max(1);
  cell_tri.clear();
  cell_tri.reserve(static_cast<std::size_t>(nf) * 2);
  for (Eigen::Index f = 0; f < nf; ++f) {
    const Eigen::Array3i c0 = grid.cell(lo.row(f).transpose()), c1 = grid.cell(hi.row(f).transpose());
    for (int z = c0[2]; z <= c1[2]; ++z)
      for (int y = c0[1]; y <= c1[1]; ++y)
        for (int x = c0[0]; x <= c1[0]; ++x) cell_tri.emplace_back(grid.key({x, y, z}), int(f));
  }
  std::sort(cell_tri.begin(), cell_tri.end());
  return grid;
}

}  // namespace

Eigen::Vector3d closest_point_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                          const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  // Barycentric regions (Ericson, Real-Time Collision Detection 5.1.5):
  // d1..d6 are the projections of p - a, p - b, p - c on the edges ab, ac.
  const Eigen::Vector3d ab = b - a, ac = c - a;
  if (ab.cross(ac).squaredNorm() <= 1e-30 * std::max(ab.squaredNorm(), ac.squaredNorm()) *
                                        std::max(ab.squaredNorm(), ac.squaredNorm())) {
    const Eigen::Vector3d q[3] = {closest_on_segment(p, a, b), closest_on_segment(p, b, c),
                                  closest_on_segment(p, c, a)};
    int best = 0;
    for (int k = 1; k < 3; ++k)
      if ((q[k] - p).squaredNorm() < (q[best] - p).squaredNorm()) best = k;
    return q[best];
  }
  const Eigen::Vector3d ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + d1 / (d1 - d3) * ab;
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

void near_surface(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const Eigen::MatrixX3d& Q,
                  double max_distance, Eigen::VectorXd& distance, Eigen::VectorXi& nearest) {
  if (!(max_distance > 0)) throw std::invalid_argument("near_surface: max_distance must be positive");
  const Eigen::Index nv = V.rows(), nf = F.rows(), nq = Q.rows();
  for (Eigen::Index f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k)
      if (F(f, k) < 0 || F(f, k) >= nv)
        throw std::invalid_argument("near_surface: triangle " + std::to_string(f) + " has vertex id " +
                                    std::to_string(F(f, k)) + " outside [0, " + std::to_string(nv) + ")");
  distance = Eigen::VectorXd::Constant(nq, std::numeric_limits<double>::infinity());
  nearest = Eigen::VectorXi::Constant(nq, -1);
  if (nf == 0 || nq == 0) return;

  Eigen::Vector3d top;
  std::vector<std::pair<std::int64_t, int>> cell_tri;
  const Grid grid = bin_triangles(V, F, max_distance, top, cell_tri);

#pragma omp parallel for schedule(static)
  for (Eigen::Index q = 0; q < nq; ++q) {
    const Eigen::Vector3d p = Q.row(q);
    if ((p - grid.origin).minCoeff() < 0 || (p - top).maxCoeff() > 0) continue;
    const std::int64_t key = grid.key(grid.cell(p));
    auto it = std::lower_bound(cell_tri.begin(), cell_tri.end(), std::make_pair(key, -1));
    double best = max_distance;
    for (; it != cell_tri.end() && it->first == key; ++it) {
      const int f = it->second;
      const Eigen::Vector3d x = closest_point_on_triangle(p, V.row(F(f, 0)), V.row(F(f, 1)), V.row(F(f, 2)));
      const double d = (x - p).norm();
      if (d <= best) {
        best = d;
        distance[q] = d;
        nearest[q] = f;
      }
    }
  }
}

}  // namespace emu
