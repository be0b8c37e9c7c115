// FEM on a small bar: its gradient against finite differences of its energy, and a solve that converges.
#include <Eigen/Dense>
#include <random>
#include "bar_model.h"
#include "check.h"
#include "emu/solvers/fem/fem_solver.h"
#include "emu/solvers/fem/fem_solver_testing.h"

using namespace emu;

TEST(fem_gradient_matches_energy_and_solve_converges) {
  const Model m = bar(2, 5);
  FemSolver fem(m, SolverOptions{});
  const LoadCase l = bar_load(3e4);
  std::mt19937 rng(5);
  std::normal_distribution<double> n(0, 0.02);
  Eigen::MatrixX3d x = m.rest;
  for (Eigen::Index i = 0; i < x.size(); ++i) x.data()[i] += n(rng);
  for (Eigen::Index i = 0; i < m.pinned.size(); ++i) x.row(m.pinned(i)) = m.rest.row(m.pinned(i));
  const Eigen::MatrixX3d g = FemSolverTesting::gradient(fem, l, x);
  const double h = 1e-6;
  for (int v : {10, 20, 40}) {
    for (int c = 0; c < 3; ++c) {
      Eigen::MatrixX3d a = x, b = x;
      a(v, c) += h;
      b(v, c) -= h;
      CHECK_CLOSE(g(v, c),
                  (FemSolverTesting::energy(fem, l, a) - FemSolverTesting::energy(fem, l, b)) / (2 * h), 1e-5 * (1 + g.norm()));
    }
  }
  const SolveResult r = fem.solve(l);
  CHECK(r.converged);
  CHECK(r.grad_norm <= 1e-6 * r.grad_norm0);
  // the bar shortens along its fibres
  CHECK(r.positions.col(2).maxCoeff() < m.rest.col(2).maxCoeff());
}


TEST_MAIN()
