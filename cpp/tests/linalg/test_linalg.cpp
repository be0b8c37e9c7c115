// CHOLMOD wrapper and shift-invert modes against dense Eigen.
#include <cmath>
#include <random>
#include <stdexcept>
#include <thread>

#include <dirent.h>

#include <omp.h>

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <vector>

#include "check.h"
#include "emu/linalg/chunked_sum.h"
#include "emu/linalg/blas_info.h"
#include "emu/linalg/cholmod_factor.h"
#include "emu/linalg/merged_pattern_factor.h"
#include "emu/linalg/modes.h"
#include "emu/linalg/negative_curvature.h"
#include "emu/linalg/rounded_block.h"
#include "emu/linalg/serial_openmp_scope.h"
#include "emu/linalg/spd_inverse.h"
#include "emu/linalg/supernodal_solve.h"
#include "emu/linalg/symmetric_product.h"

using namespace emu;

namespace {
// The upper triangle of a dense symmetric matrix in compressed-column form.
void upper_csc(const Eigen::MatrixXd& dense, std::vector<int>& p, std::vector<int>& i, std::vector<double>& x) {
  p.assign(1, 0);
  i.clear();
  x.clear();
  for (int col = 0; col < dense.cols(); ++col) {
    for (int row = 0; row <= col; ++row)
      if (dense(row, col) != 0.0) {
        i.push_back(row);
        x.push_back(dense(row, col));
      }
    p.push_back(static_cast<int>(i.size()));
  }
}

// 2D grid Laplacian (n = g*g) plus a small diagonal shift: SPD. Upper CSC.
void grid_laplacian(int g, double shift, std::vector<int>& p, std::vector<int>& i, std::vector<double>& x,
                    Eigen::MatrixXd& dense) {
  const int n = g * g;
  dense = Eigen::MatrixXd::Zero(n, n);
  for (int r = 0; r < g; ++r)
    for (int c = 0; c < g; ++c) {
      const int v = r * g + c;
      dense(v, v) += shift;
      if (c + 1 < g) {
        const int w = v + 1;
        dense(v, v) += 1; dense(w, w) += 1; dense(v, w) -= 1; dense(w, v) -= 1;
      }
      if (r + 1 < g) {
        const int w = v + g;
        dense(v, v) += 1; dense(w, w) += 1; dense(v, w) -= 1; dense(w, v) -= 1;
      }
    }
  upper_csc(dense, p, i, x);
}
}  // namespace

TEST(cholmod_solve_matches_dense) {
  std::vector<int> p, i;
  std::vector<double> x;
  Eigen::MatrixXd K;
  grid_laplacian(12, 0.01, p, i, x, K);
  const int n = static_cast<int>(K.rows());
  CholmodFactor f;
  f.analyze(n, p.data(), i.data());
  CHECK(f.factorize(x.data()));
  Eigen::MatrixXd b = Eigen::MatrixXd::Random(n, 3), sol(n, 3);
  f.solve(b.data(), sol.data(), 3);
  const Eigen::MatrixXd ref = K.llt().solve(b);
  CHECK((sol - ref).norm() <= 1e-9 * ref.norm());
  // refactorise with new values, same pattern
  for (double& v : x) v *= 2.0;
  CHECK(f.factorize(x.data()));
  f.solve(b.data(), sol.data(), 3);
  CHECK((sol - 0.5 * ref).norm() <= 1e-9 * ref.norm());
}

TEST(factorization_flops_count_a_dense_factor_exactly) {
  // a dense SPD matrix: L is full, sum_k k^2 = n (n + 1) (2n + 1) / 6 however
  // CHOLMOD splits it into supernodes, and the same once simplicial
  const int n = 120;  // flops per entry (2n + 1) / 3 above CHOLMOD's supernodal switch
  Eigen::MatrixXd A = Eigen::MatrixXd::Random(n, n);
  const Eigen::MatrixXd K = A * A.transpose() + n * Eigen::MatrixXd::Identity(n, n);
  std::vector<int> p, i;
  std::vector<double> x;
  upper_csc(K, p, i, x);
  CholmodFactor f;
  f.analyze(n, p.data(), i.data());
  const double expected = n * (n + 1.0) * (2.0 * n + 1.0) / 6.0;
  CHECK(f.factorization_flops() == expected);
  CHECK(f.factorize(x.data()) && !f.simplicial());
  f.make_simplicial();
  CHECK(f.simplicial() && f.factorization_flops() == expected);
  CholmodFactor none;
  CHECK(none.factorization_flops() == 0.0);
}

TEST(cholmod_simplicial_factor_solves_and_refactorises_like_the_supernodal_one) {
  std::vector<int> p, i;
  std::vector<double> x;
  Eigen::MatrixXd K;
  grid_laplacian(30, 0.01, p, i, x, K);
  const int n = static_cast<int>(K.rows());
  CholmodFactor f;
  f.analyze(n, p.data(), i.data());
  CHECK(f.factorize(x.data()) && !f.simplicial());
  const Eigen::MatrixXd b = Eigen::MatrixXd::Random(n, 3);
  Eigen::MatrixXd super(n, 3), simple(n, 3);
  f.solve(b.data(), super.data(), 3);
  f.make_simplicial();
  CHECK(f.simplicial() && f.factor_nnz() > n);
  f.solve(b.data(), simple.data(), 3);
  const Eigen::MatrixXd ref = K.llt().solve(b);
  CHECK((simple - ref).norm() <= 1e-9 * ref.norm());
  CHECK((simple - super).norm() <= 1e-12 * ref.norm());
  // a copy of its pattern (ConstantSchur's analyze_like) and a refactorisation stay simplicial and right
  CholmodFactor g;
  g.analyze_like(f);
  for (double& v : x) v *= 2.0;
  CHECK(g.factorize(x.data()) && g.simplicial());
  g.solve(b.data(), simple.data(), 3);
  CHECK((simple - 0.5 * ref).norm() <= 1e-9 * ref.norm());
  for (double& v : x) v = -v;  // negative definite: reported, as for the supernodal factor
  CHECK(!g.factorize(x.data()));
}

// 3D grid Laplacian (n = g^3) plus a diagonal shift, with random positive
// weights on its edges: SPD, with supernodes of many sizes (the root's off-
// diagonal block empty, leaves of one column). Upper CSC.
static void grid_laplacian_3d(int g, double shift, std::vector<int>& p, std::vector<int>& i, std::vector<double>& x,
                       Eigen::MatrixXd& dense) {
  const int n = g * g * g;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> weight(0.5, 2.0);
  dense = Eigen::MatrixXd::Zero(n, n);
  auto id = [g](int a, int b, int c) { return (a * g + b) * g + c; };
  for (int a = 0; a < g; ++a)
    for (int b = 0; b < g; ++b)
      for (int c = 0; c < g; ++c) {
        const int v = id(a, b, c);
        dense(v, v) += shift;
        const int next[3] = {a + 1 < g ? id(a + 1, b, c) : -1, b + 1 < g ? id(a, b + 1, c) : -1,
                             c + 1 < g ? id(a, b, c + 1) : -1};
        for (int w : next) {
          if (w < 0) continue;
          const double k = weight(rng);
          dense(v, v) += k; dense(w, w) += k; dense(v, w) -= k; dense(w, v) -= k;
        }
      }
  upper_csc(dense, p, i, x);
}

// A grid Laplacian's supernodal factor f, the same matrix's simplicial factor
// and its dense Cholesky: the supernodal solve's tests' common ground.
struct GridFactor {
  std::vector<int> p, i;
  std::vector<double> x;
  Eigen::MatrixXd K;
  int n = 0;
  CholmodFactor f, simple;
  Eigen::LLT<Eigen::MatrixXd> dense;
  GridFactor() {
    grid_laplacian_3d(11, 1e-3, p, i, x, K);
    n = static_cast<int>(K.rows());
    f.analyze(n, p.data(), i.data());
    CHECK(f.factorize(x.data()) && !f.simplicial());
    simple.analyze_like(f);
    CHECK(simple.factorize(x.data()));
    simple.make_simplicial();
    CHECK(simple.simplicial());
    dense.compute(K);
  }
};

TEST(supernodal_solve_of_few_right_hand_sides_matches_dense_and_cholmod) {
  // CholmodFactor::solve takes supernodal_solve_in_place for 2-4 right-hand
  // sides of a supernodal factor (1 and 5 CHOLMOD's solve): each count must
  // give the dense solution (b and x aliased too) and agree with CHOLMOD's
  // own solve (the simplicial factor's, which supernodal_solve_in_place does
  // not handle)
  GridFactor g;
  CholmodFactor &f = g.f, &simple = g.simple;
  const int n = g.n;
  for (int nrhs = 1; nrhs <= 5; ++nrhs) {
    const Eigen::MatrixXd b = Eigen::MatrixXd::Random(n, nrhs);
    const Eigen::MatrixXd ref = g.dense.solve(b);
    Eigen::MatrixXd sol(n, nrhs), by_cholmod(n, nrhs);
    f.solve(b.data(), sol.data(), nrhs);
    CHECK((sol - ref).norm() <= 1e-10 * ref.norm());
    simple.solve(b.data(), by_cholmod.data(), nrhs);
    CHECK((sol - by_cholmod).norm() <= 1e-12 * ref.norm());
    Eigen::MatrixXd inplace = b;
    f.solve(inplace.data(), inplace.data(), nrhs);
    CHECK((inplace - sol).norm() == 0.0);
  }
  {  // the factor's single-precision copy, through CholmodFactor::solve
    f.keep_single_precision_copy();
    const Eigen::MatrixXd b = Eigen::MatrixXd::Random(n, 3);
    const Eigen::MatrixXd ref = g.dense.solve(b);
    Eigen::MatrixXd sol(n, 3), full(n, 3);
    f.solve(b.data(), sol.data(), 3, true);
    f.solve(b.data(), full.data(), 3);
    CHECK((sol - ref).norm() <= 1e-3 * ref.norm() && (sol - full).norm() > 0.0);
    CHECK((full - ref).norm() <= 1e-10 * ref.norm());
    // a refactorisation refreshes the copy (values doubled: half the solution)
    for (double& v : g.x) v *= 2.0;
    CHECK(f.factorize(g.x.data()));
    f.solve(b.data(), sol.data(), 3, true);
    CHECK((sol - 0.5 * ref).norm() <= 1e-3 * ref.norm());
    // a simplicial factor cannot keep one
    bool refused = false;
    try {
      simple.keep_single_precision_copy();
    } catch (const std::logic_error&) {
      refused = true;
    }
    CHECK(refused);
  }
  // a negative-definite matrix is still reported, and the kernel refuses a simplicial factor
  for (double& v : g.x) v = -v;
  CHECK(!f.factorize(g.x.data()));
  bool refused = false;
  try {
    supernodal_panels(*simple.factor());
  } catch (const std::logic_error&) {
    refused = true;
  }
  CHECK(refused);
}

TEST(supernodal_schedule_gives_the_same_bits_on_one_and_two_threads) {
  // the schedule splits the tree (tasks and a top); its result has the same
  // bits on 1 and 2 threads and agrees with one serial task to round-off
  GridFactor g;
  const int n = g.n;
  const SupernodalPanels<double> panels = supernodal_panels(*g.f.factor());
  // tasks of at least 1,000 entries (the default's 131,072 leaves this small factor one serial task)
  const SupernodalSchedule order = supernodal_schedule(panels, 16, 1000);
  CHECK(supernodal_schedule(panels).task_first.size() == 1 && supernodal_schedule(panels).top.empty());
  CHECK(order.task_first.size() >= 4 && !order.top.empty() && order.top_columns > 0);
  SupernodalSchedule serial;
  serial.task_first = {0};
  serial.task_last = {panels.nsuper - 1};
  serial.top_slot.assign(n, -1);
  serial.longest = order.longest;
  std::vector<double> scratch;
  Eigen::MatrixXd one = Eigen::MatrixXd::Zero(4, n), two, alone;
  one.topRows(3) = Eigen::MatrixXd::Random(3, n);
  two = alone = one;
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  supernodal_solve_in_place<4>(panels, order, one.data(), scratch);
  omp_set_num_threads(2);
  supernodal_solve_in_place<4>(panels, order, two.data(), scratch);
  supernodal_solve_in_place<4>(panels, serial, alone.data(), scratch);
  omp_set_num_threads(threads);
  CHECK((one - two).norm() == 0.0);
  CHECK((one - alone).norm() <= 1e-12 * one.norm());
}

TEST(supernodal_kernel_solves_each_lane_in_double_and_rounded) {
  // the kernel alone, each build this CPU runs, on a zero-padded fourth lane:
  // the padding stays zero and the lanes solve independently; with the
  // factor rounded to float, the exact solution of the rounded factor (a
  // dense solve with L~ L~^T) and within float round-off of the true one
  GridFactor g;
  const int n = g.n;
  const cholmod_factor* L = g.f.factor();
  const SupernodalPanels<double> panels = supernodal_panels(*L);
  const SupernodalSchedule order = supernodal_schedule(panels, 16, 1000);
  std::vector<float> rounded(static_cast<const double*>(L->x), static_cast<const double*>(L->x) + L->xsize);
  const SupernodalPanels<float> rounded_panels = with_values(panels, rounded.data());
  Eigen::MatrixXd Lr = Eigen::MatrixXd::Zero(n, n);  // the rounded factor, dense, in L's (permuted) order
  for (int s = 0; s < panels.nsuper; ++s) {
    const int nsrow = panels.pi[s + 1] - panels.pi[s];
    for (int j = 0; j < panels.super[s + 1] - panels.super[s]; ++j)
      for (int k = j; k < nsrow; ++k)
        Lr(panels.rows[panels.pi[s] + k], panels.super[s] + j) = rounded[panels.px[s] + j * nsrow + k];
  }
  const int* perm = static_cast<const int*>(L->Perm);
  const Eigen::MatrixXd b = Eigen::MatrixXd::Random(n, 3);
  Eigen::MatrixXd bp(n, 3);  // P b
  for (int k = 0; k < n; ++k) bp.row(k) = b.row(perm[k]);
  const Eigen::MatrixXd ref = g.dense.solve(b);
  const Eigen::MatrixXd ref_rounded =
      Lr.transpose().triangularView<Eigen::Upper>().solve(Lr.triangularView<Eigen::Lower>().solve(bp));
  std::vector<SupernodalIsa> isas = {SupernodalIsa::baseline};
  if (supernodal_solve_has_avx2()) isas.push_back(SupernodalIsa::avx2);
  std::vector<double> scratch;
  for (SupernodalIsa isa : isas) {
    Eigen::MatrixXd rows = Eigen::MatrixXd::Zero(4, n);  // column k: row k of the lanes
    rows.topRows(3) = bp.transpose();
    supernodal_solve_in_place<4>(panels, order, rows.data(), scratch, isa);
    CHECK(rows.row(3).norm() == 0.0);
    for (int k = 0; k < n; ++k) CHECK((rows.col(k).head(3).transpose() - ref.row(perm[k])).norm() <= 1e-10 * ref.norm());
    rows.setZero();
    rows.topRows(3) = bp.transpose();
    supernodal_solve_in_place<4>(rounded_panels, order, rows.data(), scratch, isa);
    CHECK((rows.topRows(3).transpose() - ref_rounded).norm() <= 1e-10 * ref_rounded.norm());
    double err = 0.0;
    for (int k = 0; k < n; ++k) err += (rows.col(k).head(3).transpose() - ref.row(perm[k])).squaredNorm();
    CHECK(std::sqrt(err) <= 1e-3 * ref.norm() && std::sqrt(err) > 1e-12 * ref.norm());  // rounded, not exact
    for (int lanes : {1, 2}) {  // one and two right-hand sides: the first columns
      Eigen::MatrixXd r = bp.leftCols(lanes).transpose();
      if (lanes == 1) supernodal_solve_in_place<1>(panels, order, r.data(), scratch, isa);
      else supernodal_solve_in_place<2>(panels, order, r.data(), scratch, isa);
      for (int k = 0; k < n; ++k)
        CHECK((r.col(k).transpose() - ref.row(perm[k]).head(lanes)).norm() <= 1e-10 * ref.norm());
    }
  }
}

TEST(merged_pattern_factor_solves_k_plus_e_and_reanalyses_only_a_new_pattern) {
  // K a grid Laplacian (upper CSC), E a few couplings between far vertices
  // (upper triangle) whose pattern changes on the third call: each factor
  // solves (K + E) x = b like a dense solve; the analysis runs again only then.
  std::vector<int> p, i;
  std::vector<double> x;
  Eigen::MatrixXd K;
  grid_laplacian_3d(6, 1e-3, p, i, x, K);
  const int n = static_cast<int>(K.rows());
  auto coupling = [&](std::initializer_list<std::pair<int, int>> pairs, double k) {
    Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(n, n);
    for (auto [a, b] : pairs) {
      dense(a, a) += k; dense(b, b) += k; dense(a, b) -= k; dense(b, a) -= k;
    }
    Eigen::SparseMatrix<double> E = dense.sparseView();
    return std::make_pair(Eigen::SparseMatrix<double>(E.triangularView<Eigen::Upper>()), dense);
  };
  MergedPatternFactor f;
  const std::pair<int, int> first[] = {{0, n - 1}, {3, n - 7}};
  int expected_analyses = 0;
  for (int call = 0; call < 4; ++call) {
    const bool moved = call >= 2;  // the pairs change from the third call on
    const double k = 0.5 + call;   // new values every call
    auto [E, Ed] = moved ? coupling({{1, n - 2}, {5, n - 9}, {2, n / 2}}, k)
                         : coupling({first[0], first[1]}, k);
    if (call == 0 || call == 2) ++expected_analyses;
    CHECK(f.factorize(n, p.data(), i.data(), x.data(), E));
    CHECK(f.analyses() == expected_analyses);
    const Eigen::VectorXd b = Eigen::VectorXd::Random(n);
    Eigen::VectorXd sol(n);
    f.factor().solve(b.data(), sol.data(), 1);
    const Eigen::VectorXd ref = (K + Ed).llt().solve(b);
    CHECK((sol - ref).norm() <= 1e-10 * ref.norm());
  }
  // not positive definite: reported
  std::vector<double> neg = x;
  for (double& v : neg) v = -v;
  auto [E, Ed] = coupling({{1, n - 2}}, 1.0);
  CHECK(!f.factorize(n, p.data(), i.data(), neg.data(), E));
}

TEST(symmetric_upper_product_matches_dense) {
  // A random symmetric matrix on the grid pattern (diagonal and off-diagonal
  // entries of mixed sign), stored as its upper triangle.
  std::vector<int> p, i;
  std::vector<double> x;
  Eigen::MatrixXd K;
  grid_laplacian(7, 0.3, p, i, x, K);
  const int n = static_cast<int>(K.rows());
  std::srand(4);
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(n, n);
  for (int col = 0; col < n; ++col)
    for (int k = p[col]; k < p[col + 1]; ++k) {
      x[k] = Eigen::VectorXd::Random(1)(0);
      A(i[k], col) = A(col, i[k]) = x[k];
    }
  const Eigen::VectorXd v = Eigen::VectorXd::Random(n);
  Eigen::VectorXd y = Eigen::VectorXd::Constant(n, 7.0);  // overwritten, not accumulated
  symmetric_upper_product(n, p.data(), i.data(), x.data(), v.data(), y.data());
  CHECK((y - A * v).norm() <= 1e-13 * (A * v).norm());
}

TEST(cholmod_reports_indefinite) {
  std::vector<int> p, i;
  std::vector<double> x;
  Eigen::MatrixXd K;
  grid_laplacian(6, 0.01, p, i, x, K);
  for (double& v : x) v = -v;
  CholmodFactor f;
  f.analyze(static_cast<int>(K.rows()), p.data(), i.data());
  CHECK(!f.factorize(x.data()));
}

TEST(lowest_modes_match_dense_eigensolver) {
  std::vector<int> p, i;
  std::vector<double> x;
  Eigen::MatrixXd K;
  grid_laplacian(30, 0.05, p, i, x, K);  // n = 900: the Lanczos path
  CholmodFactor f;
  f.analyze(static_cast<int>(K.rows()), p.data(), i.data());
  CHECK(f.factorize(x.data()));
  const Modes m = lowest_modes(f, 12);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(K);
  for (int j = 0; j < 12; ++j) {
    CHECK_CLOSE(m.values(j), es.eigenvalues()(j), 1e-8 * es.eigenvalues()(j));
    CHECK((K * m.vectors.col(j) - m.values(j) * m.vectors.col(j)).norm() <= 1e-6 * m.values(j));
  }
  CHECK((m.vectors.transpose() * m.vectors - Eigen::MatrixXd::Identity(12, 12)).norm() <= 1e-8);
}

TEST(most_negative_curvature_matches_dense_generalised_eigensolver) {
  // M: an SPD grid Laplacian; N = M - H: a rank-2 PSD filter, the largest
  // mu of N v = mu M v above 1 (H indefinite along it), the power iteration
  // on M's CHOLMOD factor against Eigen's dense generalised solver.
  std::vector<int> p, i;
  std::vector<double> x;
  Eigen::MatrixXd M;
  grid_laplacian(10, 0.05, p, i, x, M);
  const int n = static_cast<int>(M.rows());
  std::srand(7);
  const Eigen::VectorXd a = Eigen::VectorXd::Random(n), b = Eigen::VectorXd::Random(n);
  const Eigen::MatrixXd N = 0.3 * a * a.transpose() + 0.02 * b * b.transpose();
  CholmodFactor f;
  f.analyze(n, p.data(), i.data());
  CHECK(f.factorize(x.data()));
  const CurvatureDirection d = most_negative_curvature(
      n, [&](const Eigen::VectorXd& v, Eigen::VectorXd& y) { y = N * v; },
      [&](const Eigen::VectorXd& v, Eigen::VectorXd& y) { y = M * v; },
      [&](const Eigen::VectorXd& r, Eigen::VectorXd& z) { z.resize(n); f.solve(r.data(), z.data(), 1); }, 100,
      1e-12);
  Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> ges(N, M);
  const double mu_max = ges.eigenvalues()(n - 1);
  CHECK(mu_max > 1.0);  // the case has negative curvature
  CHECK_CLOSE(d.mu, mu_max, 1e-8 * mu_max);
  CHECK(d.iterations < 100);
  const Eigen::MatrixXd H = M - N;
  CHECK_CLOSE(d.v.dot(H * d.v), (1.0 - d.mu) * d.v.dot(M * d.v), 1e-8 * d.v.dot(M * d.v));
  CHECK(d.v.dot(H * d.v) < 0);
  CHECK_CLOSE(d.v.norm(), 1.0, 1e-12);
  // the same start every call: a solve repeats bit for bit
  CHECK(pseudo_random_vector(5) == pseudo_random_vector(5));
}

TEST(cholmod_empty_matrix_factorises_and_solves_nothing) {
  // A scene whose every vertex is pinned or on a bone has no soft unknowns.
  CholmodFactor f;
  const int col_ptr[1] = {0};
  f.analyze(0, col_ptr, nullptr);
  CHECK(f.factorize(nullptr));
  CHECK(f.factorized());
  f.solve(nullptr, nullptr, 3);
  CHECK(f.rows() == 0 && f.factor_nnz() == 0.0);
}

// The number of threads of this process (Linux: one entry per thread in /proc/self/task).
static int process_threads() {
  int n = 0;
  if (DIR* d = opendir("/proc/self/task")) {
    while (const dirent* e = readdir(d))
      if (e->d_name[0] != '.') ++n;
    closedir(d);
  }
  return n;
}

TEST(serial_openmp_scope_runs_regions_on_one_thread_and_restores) {
  const int levels = omp_get_max_active_levels();
  omp_set_dynamic(0);  // the team sizes asked for, not the runtime's choice
  int inside = 0, after = 0;
  {
    const SerialOpenMPScope serial;
#pragma omp parallel num_threads(4)
#pragma omp single
    inside = omp_get_num_threads();
  }
#pragma omp parallel num_threads(4)
#pragma omp single
  after = omp_get_num_threads();
  CHECK(inside == 1);
  if (omp_get_thread_limit() >= 2) CHECK(after > 1);  // the num_threads clause wins again after the scope
  CHECK(omp_get_max_active_levels() == levels);
}

TEST(cholmod_factorisation_starts_no_threads) {
  // CHOLMOD 3's supernodal factorisation opens OpenMP regions with a fixed
  // num_threads(4) (serial_openmp_scope.h). A thread of its own factorises, so
  // any OpenMP team it started would appear as new threads of the process
  // (libgomp keeps a team's threads per master thread until that exits); its
  // solve and the change to a simplicial factor are checked alike.
  std::vector<int> p, i;
  std::vector<double> x;
  Eigen::MatrixXd dense;
  grid_laplacian_3d(12, 1.0, p, i, x, dense);
  int before = 0, after = 0;
  bool factorised = false;
  std::thread worker([&] {
    before = process_threads();
    CholmodFactor f;
    f.analyze(static_cast<int>(p.size()) - 1, p.data(), i.data());
    factorised = f.factorize(x.data());
    std::vector<double> b(p.size() - 1, 1.0);
    f.solve(b.data(), b.data(), 1);  // CHOLMOD's own solve
    f.make_simplicial();
    factorised = factorised && f.factorize(x.data());  // simplicial refactorisation
    after = process_threads();
  });
  worker.join();
  CHECK(factorised);
  CHECK(before > 0);
  CHECK(after <= before);  // none started (one may have ended meanwhile)
}

TEST(blas_threads_scope_sets_and_restores_openblas_threads) {
  const int threads = blas_threads();
  if (threads <= 0) return;  // not OpenBLAS: nothing to set (the scope is a no-op)
  set_blas_threads(2);
  {
    const BlasThreadsScope one(1);
    CHECK(blas_threads() == 1);
    const BlasThreadsScope unchanged(0);
    CHECK(blas_threads() == 1);
  }
  CHECK(blas_threads() == 2);
  {  // a count asked for while a scope is open (another thread's set_threads) is kept after it
    const BlasThreadsScope one(1);
    set_blas_threads(3);
  }
  CHECK(blas_threads() == 3);
  set_blas_threads(2);
  // a small factorisation runs on one BLAS thread and leaves the count as it was
  std::vector<int> p, i;
  std::vector<double> x;
  Eigen::MatrixXd dense;
  grid_laplacian_3d(8, 1.0, p, i, x, dense);
  CholmodFactor f;
  f.analyze(static_cast<int>(p.size()) - 1, p.data(), i.data());
  CHECK(f.factorize(x.data()));
  CHECK(blas_threads() == 2);
  set_blas_threads(threads);
}

// round_spd_block keeps an SPD block definite in float however ill
// conditioned (a plain cast need not: shown on the same blocks), the stored
// block is symmetric and not below the exact one, and it moves the block by
// no more than its rounding bound; block_times applies the stored block.
TEST(round_spd_block_stays_definite_and_above_the_exact_block) {
  std::mt19937 rng(7);
  std::normal_distribution<double> g(0.0, 1.0);
  using Mat9d = Eigen::Matrix<double, 9, 9>;
  int plain_indefinite = 0;
  for (double spread : {1e1, 1e6, 1e10}) {
    for (int trial = 0; trial < 20; ++trial) {
      Mat9d Q;
      for (int i = 0; i < 81; ++i) Q.data()[i] = g(rng);
      Q = Eigen::HouseholderQR<Mat9d>(Q).householderQ();
      Eigen::Matrix<double, 9, 1> lam;
      for (int i = 0; i < 9; ++i) lam(i) = std::pow(spread, -double(i) / 8.0);
      Mat9d B = Q * lam.asDiagonal() * Q.transpose();
      B = (0.5 * (B + B.transpose())).eval();
      Mat9f R;
      round_spd_block(B, R);
      const Mat9d Rd = R.cast<double>();
      CHECK(Rd == Rd.transpose());
      const double delta = 10.0 * std::ldexp(1.0, -24) * B.cwiseAbs().maxCoeff();
      const Eigen::VectorXd shift = Eigen::SelfAdjointEigenSolver<Mat9d>(Rd - B).eigenvalues();
      CHECK(shift(0) >= 0.0);          // R >= B: definite with B
      CHECK(shift(8) <= 2.0 * delta);  // and close to it
      CHECK(Eigen::LLT<Mat9d>(Rd).info() == Eigen::Success);
      const Mat9d plain = B.cast<float>().cast<double>();
      if (Eigen::SelfAdjointEigenSolver<Mat9d>(plain).eigenvalues()(0) <= 0.0) ++plain_indefinite;
      Eigen::Matrix<double, 9, 1> x;
      for (int i = 0; i < 9; ++i) x(i) = g(rng);
      CHECK((block_times(R, x) - Rd * x).norm() <= 1e-15 * (Rd.norm() * x.norm()));
      CHECK((block_times(B, x) - B * x).norm() <= 1e-15 * (B.norm() * x.norm()));
    }
  }
  CHECK(plain_indefinite > 0);  // the shift is needed: a plain cast loses definiteness at condition 1e10
}

// spd_inverse_lanes and invert_spd_blocks give spd_inverse's bits block by
// block (13 blocks: three groups of four and one left over), and flag the
// blocks that are not positive definite without disturbing the others.
TEST(spd_inverse_lanes_give_the_same_bits_and_flag_indefinite_blocks) {
  std::mt19937 rng(11);
  std::normal_distribution<double> g(0.0, 1.0);
  using Mat9d = Eigen::Matrix<double, 9, 9>;
  std::vector<Mat9d> A(13);
  for (Mat9d& B : A) {
    Mat9d M;
    for (int i = 0; i < 81; ++i) M.data()[i] = g(rng);
    B = M * M.transpose() + 0.1 * Mat9d::Identity();
  }
  A[2](4, 4) = -1.0;             // indefinite, in a group of four
  A[7](0, 0) = std::nan("");     // not finite
  A[12] = -Mat9d::Identity();    // the left-over block
  std::vector<Mat9d> inv(A.size());
  std::vector<int> ok(A.size(), -1);
  const long refused = invert_spd_blocks<9>(A, [&](long u, const Mat9d& B, bool good) {
    inv[u] = B;
    ok[u] = good;
  });
  CHECK(refused == 3);
  for (size_t u = 0; u < A.size(); ++u) {
    Mat9d ref;
    const bool good = spd_inverse<9>(A[u], ref);
    CHECK(ok[u] == int(good));
    if (good) CHECK(inv[u] == ref);  // bit for bit
  }
  CHECK(ok[2] == 0 && ok[7] == 0 && ok[12] == 0 && ok[0] == 1 && ok[11] == 1);
}

TEST(spd_inverse_matches_the_dense_inverse_and_refuses_indefinite_blocks) {
  // 9x9 SPD blocks from well conditioned to condition 1e6 (an ACAP term
  // alpha w V beside a soft material's curvature), against a dense LU inverse.
  std::mt19937 rng(4);
  std::normal_distribution<double> g(0.0, 1.0);
  using Mat9d = Eigen::Matrix<double, 9, 9>;
  for (double spread : {1e-1, 1e2, 1e6}) {
    for (int trial = 0; trial < 20; ++trial) {
      Mat9d Q;
      for (int i = 0; i < 81; ++i) Q.data()[i] = g(rng);
      Q = Eigen::HouseholderQR<Mat9d>(Q).householderQ();
      Eigen::Matrix<double, 9, 1> lam;
      for (int i = 0; i < 9; ++i) lam(i) = std::pow(spread, double(i) / 8.0) * (1.0 + 0.1 * std::abs(g(rng)));
      const Mat9d A = Q * lam.asDiagonal() * Q.transpose();
      Mat9d inv;
      CHECK(spd_inverse<9>(A, inv));
      const Mat9d ref = A.fullPivLu().inverse();
      CHECK((inv - ref).norm() <= 1e-12 * spread * ref.norm());
      CHECK(inv == inv.transpose());  // both triangles written from one sum
      CHECK((A * inv - Mat9d::Identity()).norm() <= 1e-12 * spread);
    }
  }
  Mat9d A = Mat9d::Identity();
  Mat9d inv;
  A(4, 4) = -1e-3;  // indefinite
  CHECK(!spd_inverse<9>(A, inv));
  A(4, 4) = 0.0;  // singular
  CHECK(!spd_inverse<9>(A, inv));
  A(4, 4) = std::nan("");
  CHECK(!spd_inverse<9>(A, inv));
  Eigen::Matrix3d B;
  B << 4, 1, 0, 1, 3, 1, 0, 1, 2;
  Eigen::Matrix3d Binv;
  CHECK(spd_inverse<3>(B, Binv) && (Binv - B.inverse()).norm() < 1e-14);
}

// The chunked sum gives the same bits on one thread and on several (fixed
// chunks, summed in chunk order), and the vector form the same as the scalar one.
TEST(chunked_sum_has_the_same_bits_for_any_thread_count) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::VectorXd a(10007), b(10007);
  for (Eigen::Index i = 0; i < a.size(); ++i) {
    a(i) = u(rng) * std::pow(10.0, 8 * u(rng));   // wide magnitudes: the order of summation shows
    b(i) = u(rng);
  }
#ifdef _OPENMP
  const int before = omp_get_max_threads();
  omp_set_num_threads(1);
  const double one = chunked_dot(a, b);
  omp_set_num_threads(std::max(2, before));
  const double several = chunked_dot(a, b);
  omp_set_num_threads(before);
  CHECK(one == several);
#endif
  CHECK_CLOSE(chunked_dot(a, b), a.dot(b), 1e-9 * a.cwiseAbs().dot(b.cwiseAbs()));
  Eigen::MatrixXd parts;
  Eigen::VectorXd out;
  chunked_sum_into(
      a.size(), 2,
      [&](Eigen::Index lo, Eigen::Index hi, auto part) {
        part.setZero();
        for (Eigen::Index i = lo; i < hi; ++i) part += Eigen::Vector2d(a(i), a(i) * b(i));
      },
      parts, out);
  CHECK_CLOSE(out(0), a.sum(), 1e-9 * a.cwiseAbs().sum());
  CHECK(out(1) == chunked_dot(a, b));   // the same chunks, summed in the same order
}

TEST_MAIN()
