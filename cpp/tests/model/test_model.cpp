// The model's tet order: along_curve carries every per-tet array and the scene index.
#include <Eigen/Dense>
#include <algorithm>
#include <random>
#include "bar_model.h"
#include "check.h"
#include "emu/mesh/spatial_order.h"
#include "emu/model/tet_order.h"
#include "emu/solvers/emu/emu_solver.h"

using namespace emu;

TEST(along_curve_carries_every_per_tet_array_and_the_scene_index) {
  // A bar given with its tets shuffled and named as scene tets 2 t + 1 of a
  // scene with 2 #T + 1 tets: the stored model lists them along the curve,
  // each array and scene_tet moved with its tet.
  Model m = bar(2, 4);
  const Eigen::Index nt = m.tets.rows();
  std::vector<int> shuffle(nt);
  for (Eigen::Index t = 0; t < nt; ++t) shuffle[t] = static_cast<int>(t);
  std::shuffle(shuffle.begin(), shuffle.end(), std::mt19937(3));
  Model given = m;
  for (Eigen::Index t = 0; t < nt; ++t) {
    given.tets.row(t) = m.tets.row(shuffle[t]);
    given.mu(t) = 1.0 + t;  // distinct per tet, to follow them
    given.acap_weight(t) = 2.0 + t;
  }
  given.scene_tet.resize(nt);
  for (Eigen::Index t = 0; t < nt; ++t) given.scene_tet(t) = static_cast<int>(2 * t + 1);
  given.num_scene_tets = static_cast<int>(2 * nt + 1);
  const Model stored = along_curve(given);
  const std::vector<int> order = spatial_order(given.rest, given.tets);
  CHECK(stored.num_scene_tets == 2 * nt + 1);
  for (Eigen::Index i = 0; i < nt; ++i) {
    const int t = order[i];
    CHECK(stored.tets.row(i) == given.tets.row(t));
    CHECK(stored.mu(i) == given.mu(t) && stored.acap_weight(i) == given.acap_weight(t));
    CHECK(stored.scene_tet(i) == 2 * t + 1 && stored.scene_index(i) == 2 * t + 1);
  }
  // the solvers store it so, and give EMU's F back per scene tet
  EmuSolverOptions eo;
  eo.alpha = 100.0 * m.mu(0);
  EmuSolver emu(given, SolverOptions(), eo);
  CHECK(emu.model().scene_tet == stored.scene_tet);
  LoadCase l;
  l.activation = Eigen::VectorXd::Constant(1, 2.0);
  const SolveResult r = emu.solve(l);
  CHECK(r.F.rows() == 2 * nt + 1 && r.F.cols() == 9);
  for (Eigen::Index s = 0; s < r.F.rows(); s += 2)  // scene tets 0, 2, 4, ...: no unknowns, identity
    CHECK(r.F.row(s) == (Eigen::RowVectorXd(9) << 1, 0, 0, 0, 1, 0, 0, 0, 1).finished());
  CHECK((r.F.row(1) - (Eigen::RowVectorXd(9) << 1, 0, 0, 0, 1, 0, 0, 0, 1).finished()).norm() > 1e-6);
  // a warm start from that F (scene rows) is already converged
  const SolveResult again = emu.solve(l, &r.F);
  CHECK(again.converged && again.iterations <= 1);
  // scene_tet naming a tet twice is refused
  Model bad = given;
  bad.scene_tet(1) = bad.scene_tet(0);
  bool threw = false;
  try {
    along_curve(bad);
  } catch (const std::invalid_argument&) {
    threw = true;
  }
  CHECK(threw);
}


TEST_MAIN()
