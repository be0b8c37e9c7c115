// What both solvers share: the option choices' spelling, the bone forest's chains, and EMU's
// answer tending to FEM's as alpha grows (the same energy).
#include <Eigen/Dense>
#include <algorithm>
#include <stdexcept>
#include <string>
#include <vector>
#include "bar_model.h"
#include "check.h"
#include "emu/solvers/bone_forest.h"
#include "emu/solvers/option_choices.h"
#include "emu/solvers/emu/emu_solver.h"
#include "emu/solvers/fem/fem_solver.h"

using namespace emu;

TEST(emu_and_fem_agree_as_alpha_grows) {
  const Model m = bar(2, 4);
  FemSolver fem(m, SolverOptions{});
  const LoadCase l = bar_load(3e4);
  const SolveResult rf = fem.solve(l);
  CHECK(rf.converged);
  double prev = 1e9;
  const double diag = (m.rest.colwise().maxCoeff() - m.rest.colwise().minCoeff()).norm();
  for (double rel : {10.0, 100.0, 1000.0}) {
    EmuSolverOptions eo;
    eo.alpha = rel * m.mu(0);
    EmuSolver emu(m, SolverOptions{}, eo);
    const SolveResult re = emu.solve(l);
    CHECK(re.converged);
    const double err = (re.positions - rf.positions).rowwise().norm().maxCoeff() / diag;
    CHECK(err < prev);
    prev = err;
  }
  CHECK(prev < 1e-2);
}

// The constant Schur preconditioner in single precision (S0's factor and the
// block inverses rounded to float; EmuSolverOptions::single_precision_preconditioner,
// the default): the preconditioner changes CG's path, not the answer, and CG
// needs about as many iterations as in double.

// Every choice's name parses back to its value; a misspelling names the option and its choices.
TEST(option_choices_round_trip_and_refuse_a_misspelling) {
  for (const auto& c : kEmuSteps) CHECK(parse_choice(kEmuSteps, "step", c.name) == c.value);
  for (const auto& c : kEmuPreconditioners)
    CHECK(std::string(choice_name(kEmuPreconditioners, parse_choice(kEmuPreconditioners, "p", c.name))) == c.name);
  CHECK(choice_names(kEigenFilters) == std::vector<std::string>({"clamp", "abs"}));
  std::string what;
  try {
    parse_choice(kEmuSteps, "step", "newton_krylov");
  } catch (const std::invalid_argument& e) {
    what = e.what();
  }
  CHECK(what == "step must be one of 'newton-krylov', 'woodbury', 'lbfgs', got 'newton_krylov'");
}

// A forest given node by node: each bone's chain (root first) and the bones
// below it (itself first, its descendants), for two trees.
TEST(bone_forest_chains_and_subtrees) {
  std::vector<BoneForest::Node> nodes(4);
  nodes[0].kind = BoneForest::Kind::Ball;
  nodes[1].kind = BoneForest::Kind::Hinge;
  nodes[1].parent = 0;
  nodes[2].kind = BoneForest::Kind::Hinge;
  nodes[2].parent = 1;
  nodes[3].kind = BoneForest::Kind::Free;   // a second tree
  const BoneForest f(nodes, {0, 3, 1, 2});
  CHECK(f.bones[2].chain == std::vector<int>({0, 1, 2}));
  CHECK(f.bones[3].chain == std::vector<int>({3}));
  std::vector<int> below0 = f.bones[0].below;
  std::sort(below0.begin() + 1, below0.end());
  CHECK(below0 == std::vector<int>({0, 1, 2}));
  CHECK(f.bones[2].below == std::vector<int>({2}));
  CHECK(f.bones[3].below == std::vector<int>({3}));
}

TEST_MAIN()
