// Mesh geometry: the closest point on a triangle against a dense sampling of
// it, and the grid search of near_surface against checking every triangle.
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

#include <Eigen/Core>

#include "bar_model.h"
#include "check.h"
#include "emu/mesh/block_pattern.h"
#include "emu/mesh/connected_components.h"
#include "emu/mesh/harmonic_field.h"
#include "emu/model/unknown_layout.h"
#include "emu/mesh/spatial_order.h"
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

TEST(block_assembly_matches_dense_assembly) {
  const Model m = bar(2, 3);
  UnknownLayout d(m);
  BlockPattern pat(m.tets, d.free_index, d.num_free, 3);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> elem(m.tets.rows() * 144);
  for (Eigen::Index t = 0; t < m.tets.rows(); ++t) {
    Mat12 K;
    for (int i = 0; i < 144; ++i) K.data()[i] = u(rng);
    K = (K + K.transpose()).eval();
    Eigen::Map<Mat12>(elem.data() + t * 144) = K;
  }
  std::vector<double> values(pat.nnz());
  pat.assemble(elem.data(), values.data());
  const int n = pat.rows();
  Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(n, n), sparse = Eigen::MatrixXd::Zero(n, n);
  for (Eigen::Index t = 0; t < m.tets.rows(); ++t) {
    const Eigen::Map<const Mat12> K(elem.data() + t * 144);
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) {
        const int va = d.free_index(m.tets(t, a)), vb = d.free_index(m.tets(t, b));
        if (va >= 0 && vb >= 0) dense.block<3, 3>(3 * va, 3 * vb) += K.block<3, 3>(3 * a, 3 * b);
      }
  }
  for (int j = 0; j < n; ++j)
    for (int e = pat.col_ptr()[j]; e < pat.col_ptr()[j + 1]; ++e) {
      CHECK(pat.row_index()[e] <= j);
      sparse(pat.row_index()[e], j) = values[e];
    }
  CHECK((sparse - Eigen::MatrixXd(dense.triangularView<Eigen::Upper>())).norm() <= 1e-12 * dense.norm());
}

TEST(corner_gather_matches_a_scatter_for_every_width) {
  // Widths 1 and 3 take the unrolled path, 2 the general one; pinned
  // vertices (free_index -1) receive nothing.
  const Model m = bar(2, 3);
  UnknownLayout d(m);
  CHECK(d.num_free < m.rest.rows());  // the bar has pinned vertices
  BlockPattern pat(m.tets, d.free_index, d.num_free, 1);
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int width : {1, 2, 3}) {
    std::vector<double> corner(m.tets.rows() * 4 * width);
    for (double& c : corner) c = u(rng);
    Eigen::MatrixXd expected = Eigen::MatrixXd::Zero(width, d.num_free);
    for (Eigen::Index t = 0; t < m.tets.rows(); ++t)
      for (int a = 0; a < 4; ++a) {
        const int v = d.free_index(m.tets(t, a));
        if (v >= 0)
          for (int c = 0; c < width; ++c) expected(c, v) += corner[(t * 4 + a) * width + c];
      }
    Eigen::MatrixXd out = Eigen::MatrixXd::Constant(width, d.num_free, 7.0);  // overwritten
    pat.gather(corner.data(), width, out.data());
    CHECK((out - expected).norm() <= 1e-13 * expected.norm());
  }
}

TEST(spatial_order_is_a_stable_permutation_along_the_z_curve) {
  // A bar along z with its tets shuffled: the order runs from one end to the
  // other with short steps; two tets with the same centroid keep their order in T.
  const Model m = bar(2, 6);
  const Eigen::Index nt = m.tets.rows();
  std::vector<int> shuffle(nt);
  for (Eigen::Index t = 0; t < nt; ++t) shuffle[t] = static_cast<int>(t);
  std::shuffle(shuffle.begin(), shuffle.end(), std::mt19937(7));
  Eigen::MatrixX4i T(nt + 1, 4);
  for (Eigen::Index t = 0; t < nt; ++t) T.row(t) = m.tets.row(shuffle[t]);
  T.row(nt) = T.row(0);  // a duplicate of tet 0, listed last
  const std::vector<int> order = spatial_order(m.rest, T);
  CHECK(static_cast<Eigen::Index>(order.size()) == nt + 1);
  std::vector<int> seen(nt + 1, 0);
  for (int t : order) ++seen[t];
  CHECK(std::all_of(seen.begin(), seen.end(), [](int k) { return k == 1; }));
  auto centroid = [&](int t) {
    Eigen::RowVector3d c = Eigen::RowVector3d::Zero();
    for (int a = 0; a < 4; ++a) c += m.rest.row(T(t, a));
    return Eigen::RowVector3d(c / 4);
  };
  // The bar is thin along x and y: the curve's first tet lies at one end of z, its last at the other.
  double zmin = 1e300, zmax = -1e300;
  for (Eigen::Index t = 0; t <= nt; ++t) zmin = std::min(zmin, centroid(t)(2)), zmax = std::max(zmax, centroid(t)(2));
  CHECK(centroid(order.front())(2) < zmin + 0.25 * (zmax - zmin));
  CHECK(centroid(order.back())(2) > zmax - 0.25 * (zmax - zmin));
  // Locality: consecutive tets in the order are closer than in the shuffled T.
  double step_order = 0, step_given = 0;
  for (Eigen::Index k = 1; k <= nt; ++k) {
    step_order += (centroid(order[k]) - centroid(order[k - 1])).norm();
    step_given += (centroid(static_cast<int>(k)) - centroid(static_cast<int>(k - 1))).norm();
  }
  CHECK(step_order < 0.5 * step_given);
  const auto first = std::find(order.begin(), order.end(), 0), dup = std::find(order.begin(), order.end(), static_cast<int>(nt));
  CHECK(first < dup);  // equal codes keep T's order
  Eigen::MatrixX4i bad = T;
  bad(0, 0) = static_cast<int>(m.rest.rows());
  bool threw = false;
  try {
    spatial_order(m.rest, bad);
  } catch (const std::invalid_argument&) {
    threw = true;
  }
  CHECK(threw);
  CHECK(spatial_order(m.rest, Eigen::MatrixX4i(0, 4)).empty());
  // The curve itself: eight "tets" collapsed onto the corners of a cube, listed
  // in a scrambled order, come out x fastest, then y, then z (the Morton code
  // interleaves the bits of x, y, z in that order).
  Eigen::MatrixX3d corners(8, 3);
  const int scrambled[8] = {6, 1, 7, 4, 0, 3, 5, 2};  // the corner at row k is corner scrambled[k]
  for (int k = 0; k < 8; ++k) {
    const int i = scrambled[k];
    corners.row(k) << (i & 1), (i >> 1) & 1, (i >> 2) & 1;
  }
  Eigen::MatrixX4i at_corner(8, 4);
  for (int k = 0; k < 8; ++k) at_corner.row(k).setConstant(k);
  const std::vector<int> cube = spatial_order(corners, at_corner);
  bool curve = cube.size() == 8;
  for (int i = 0; i < 8 && curve; ++i) curve = scrambled[cube[i]] == i;
  CHECK(curve);
}

// Two tets sharing a vertex are one piece, a third apart another, a vertex of
// no tet a piece of its own; each labelled by its smallest vertex id.
TEST(connected_components_label_each_piece_by_its_smallest_vertex) {
  Eigen::MatrixX4i T(3, 4);
  T << 3, 1, 2, 6, 3, 4, 5, 0, 10, 8, 9, 7;
  const Eigen::VectorXi c = connected_components(12, T);
  for (int v = 0; v <= 6; ++v) CHECK(c(v) == 0);
  for (int v = 7; v <= 10; ++v) CHECK(c(v) == 7);
  CHECK(c(11) == 11);
  Eigen::MatrixX4i bad(1, 4);
  bad << 0, 1, 2, 12;
  bool threw = false;
  try {
    connected_components(12, bad);
  } catch (const std::invalid_argument&) {
    threw = true;
  }
  CHECK(threw);
}

// The P1 Laplace solution between two opposite faces of a bar held at 0 and 1
// is the linear field z / L: exact on any tet mesh (linear fields are P1).
TEST(harmonic_field_between_two_faces_is_linear) {
  const Model m = bar(2, 4);
  std::vector<int> ids;
  std::vector<double> vals;
  for (Eigen::Index v = 0; v < m.rest.rows(); ++v) {
    const double z = m.rest(v, 2);
    if (z == 0.0 || z == 4.0) {
      ids.push_back(static_cast<int>(v));
      vals.push_back(z / 4.0);
    }
  }
  const Eigen::VectorXi fixed = Eigen::Map<Eigen::VectorXi>(ids.data(), ids.size());
  const Eigen::VectorXd values = Eigen::Map<Eigen::VectorXd>(vals.data(), vals.size());
  const Eigen::VectorXd phi = harmonic_field(m.rest, m.tets, fixed, values);
  for (Eigen::Index v = 0; v < m.rest.rows(); ++v) CHECK_CLOSE(phi(v), m.rest(v, 2) / 4.0, 1e-10);
  const Eigen::MatrixX3d g = tet_gradients(m.rest, m.tets, phi);
  for (Eigen::Index t = 0; t < g.rows(); ++t) CHECK_CLOSE((g.row(t) - Eigen::RowVector3d(0, 0, 0.25)).norm(), 0.0, 1e-10);
  // a piece with no fixed vertex has no field: an error, not zeros
  bool threw = false;
  try {
    harmonic_field(m.rest, m.tets, Eigen::VectorXi(), Eigen::VectorXd());
  } catch (const std::invalid_argument&) {
    threw = true;
  }
  CHECK(threw);
}

TEST_MAIN()
