// Mesh geometry: the closest point on a triangle against a dense sampling of
// it, and the grid search of near_surface against checking every triangle.
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

#include <Eigen/Core>

#include "check.h"
#include "emu/mesh/near_surface.h"

using namespace emu;

namespace {
// The nearest of (k+1)(k+2)/2 barycentric samples of the triangle: an upper
// bound on the distance, within the sample spacing of the exact one.
double sampled_distance(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                        const Eigen::Vector3d& c, int k) {
  double best = std::numeric_limits<double>::infinity();
  for (int i = 0; i <= k; ++i)
    for (int j = 0; i + j <= k; ++j) {
      const Eigen::Vector3d x = a + (b - a) * (double(i) / k) + (c - a) * (double(j) / k);
      best = std::min(best, (x - p).norm());
    }
  return best;
}
}  // namespace

TEST(closest_point_on_triangle_in_each_region_matches_dense_sampling) {
  std::mt19937 rng(7);
  std::normal_distribution<double> g(0.0, 1.0);
  const int k = 400;
  for (int trial = 0; trial < 300; ++trial) {
    const Eigen::Vector3d a(g(rng), g(rng), g(rng)), b(g(rng), g(rng), g(rng)), c(g(rng), g(rng), g(rng));
    const Eigen::Vector3d p(2 * g(rng), 2 * g(rng), 2 * g(rng));
    const Eigen::Vector3d x = closest_point_on_triangle(p, a, b, c);
    const double exact = (x - p).norm();
    const double spacing = std::max({(b - a).norm(), (c - a).norm(), (c - b).norm()}) / k;
    const double sampled = sampled_distance(p, a, b, c, k);
    CHECK(exact <= sampled + 1e-12);            // nothing on the triangle is nearer
    CHECK(sampled <= exact + 2 * spacing);      // and the point is on the triangle
  }
  // a face, an edge and a vertex region with known answers
  const Eigen::Vector3d a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  CHECK((closest_point_on_triangle({0.2, 0.2, 3.0}, a, b, c) - Eigen::Vector3d(0.2, 0.2, 0)).norm() < 1e-15);
  CHECK((closest_point_on_triangle({1.0, 1.0, 0.0}, a, b, c) - Eigen::Vector3d(0.5, 0.5, 0)).norm() < 1e-15);
  CHECK((closest_point_on_triangle({-1.0, -2.0, 1.0}, a, b, c) - a).norm() < 1e-15);
  // a degenerate (collinear) triangle: the nearest point of its edges
  CHECK((closest_point_on_triangle({0.5, 1.0, 0.0}, a, b, Eigen::Vector3d(2, 0, 0)) -
         Eigen::Vector3d(0.5, 0, 0)).norm() < 1e-15);
}

TEST(near_surface_finds_what_checking_every_triangle_finds) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  // a bumpy height field of 2 x 20 x 20 triangles plus one large triangle far off
  const int n = 21;
  Eigen::MatrixX3d V(n * n + 3, 3);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) V.row(i * n + j) << i / 20.0, j / 20.0, 0.05 * std::sin(7.0 * i / 20.0 + 3.0 * j / 20.0);
  V.row(n * n) << 5, 5, 5;
  V.row(n * n + 1) << 9, 5, 5;
  V.row(n * n + 2) << 5, 9, 6;
  Eigen::MatrixX3i F(2 * 20 * 20 + 1, 3);
  int f = 0;
  for (int i = 0; i < 20; ++i)
    for (int j = 0; j < 20; ++j) {
      const int v = i * n + j;
      F.row(f++) << v, v + n, v + 1;
      F.row(f++) << v + 1, v + n, v + n + 1;
    }
  F.row(f++) << n * n, n * n + 1, n * n + 2;
  Eigen::MatrixX3d Q(2000, 3);
  for (int q = 0; q < Q.rows(); ++q) Q.row(q) << -0.2 + 9.4 * u(rng), -0.2 + 9.4 * u(rng), -0.3 + 6.6 * u(rng);
  for (int q = 0; q < 500; ++q) Q(q, 0) = -0.2 + 1.4 * u(rng), Q(q, 1) = -0.2 + 1.4 * u(rng), Q(q, 2) = 0.3 * (u(rng) - 0.5);
  const double max_distance = 0.06;
  Eigen::VectorXd distance;
  Eigen::VectorXi nearest;
  near_surface(V, F, Q, max_distance, distance, nearest);
  int found = 0;
  for (int q = 0; q < Q.rows(); ++q) {
    double best = std::numeric_limits<double>::infinity();
    for (int t = 0; t < F.rows(); ++t)
      best = std::min(best, (closest_point_on_triangle(Q.row(q), V.row(F(t, 0)), V.row(F(t, 1)), V.row(F(t, 2))) -
                             Q.row(q).transpose()).norm());
    if (best <= max_distance) {
      ++found;
      CHECK(std::abs(distance[q] - best) < 1e-14 && nearest[q] >= 0);
    } else {
      CHECK(std::isinf(distance[q]) && nearest[q] == -1);
    }
  }
  CHECK(found > 50);   // the test exercises both outcomes
  bool threw = false;
  try {
    near_surface(V, F, Q, 0.0, distance, nearest);
  } catch (const std::invalid_argument&) {
    threw = true;
  }
  CHECK(threw);
}

TEST_MAIN()
