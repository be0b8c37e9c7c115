// The model's tet order (along_curve carries every per-tet array and the
// scene index) and the unknown layout derived from a model.
#include <Eigen/Dense>
#include <algorithm>
#include <random>
#include "bar_model.h"
#include "check.h"
#include "emu/mesh/spatial_order.h"
#include "emu/model/tet_order.h"
#include "emu/model/unknown_layout.h"
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


// A bar whose top layer of hexes is one movable bone, with one of its top
// vertices pinned as well: the soft tets and the bone are the unknowns, the
// bone's vertices and the pins are not free, the pinned bone vertex is a joint
// point with the world.
TEST(unknown_layout_of_a_bar_with_a_movable_bone) {
  Model m = bar(2, 3);
  const Eigen::Index nt = m.tets.rows(), nv = m.rest.rows();
  m.num_bones = 1;
  m.bone = Eigen::VectorXi::Constant(nt, -1);
  for (Eigen::Index t = 0; t < nt; ++t) {
    double zmin = 1e9;
    for (int a = 0; a < 4; ++a) zmin = std::min(zmin, m.rest(m.tets(t, a), 2));
    if (zmin >= 2.0) {
      m.bone(t) = 0;
      m.muscle(t) = -1;
    }
  }
  m.bone_stiffness = Eigen::VectorXd::Zero(1);
  int top = -1;  // a top vertex (on the bone)
  for (Eigen::Index v = 0; v < nv; ++v)
    if (m.rest(v, 2) == 3.0) top = static_cast<int>(v);
  std::vector<int> pins(m.pinned.data(), m.pinned.data() + m.pinned.size());
  pins.push_back(top);
  std::sort(pins.begin(), pins.end());
  m.pinned = Eigen::Map<Eigen::VectorXi>(pins.data(), pins.size());
  m.validate();
  const UnknownLayout d(m);
  const int bone_tets = static_cast<int>((m.bone.array() == 0).count());
  CHECK(d.num_bones == 1 && d.num_soft == nt - bone_tets && d.num_unknowns == d.num_soft + 1);
  // each tet in exactly one unknown, tet_unknown and the CSR agreeing, in tet order
  std::vector<int> seen(nt, 0);
  for (int u = 0; u < d.num_unknowns; ++u)
    for (int i = d.unknown_ptr[u]; i < d.unknown_ptr[u + 1]; ++i) {
      const int t = d.unknown_tets[i];
      ++seen[t];
      CHECK(d.tet_unknown(t) == u && (i == d.unknown_ptr[u] || t > d.unknown_tets[i - 1]));
      CHECK((u == d.num_soft) == (m.bone(t) == 0) && d.is_bone_tet(t) == (m.bone(t) == 0));
    }
  CHECK(std::all_of(seen.begin(), seen.end(), [](int c) { return c == 1; }));
  // free vertices: neither pinned nor on the bone, numbered 0 .. num_free - 1 once each
  std::vector<char> pinned(nv, 0), on_bone(nv, 0), numbered(d.num_free, 0);
  for (int p : pins) pinned[p] = 1;
  for (Eigen::Index t = 0; t < nt; ++t)
    if (m.bone(t) == 0)
      for (int a = 0; a < 4; ++a) on_bone[m.tets(t, a)] = 1;
  int free_count = 0;
  for (Eigen::Index v = 0; v < nv; ++v) {
    CHECK(d.vertex_bone(v) == (on_bone[v] && !pinned[v] ? 0 : -1));  // a pin places its vertex, not the bone
    const int f = d.free_index(v);
    CHECK((f >= 0) == (!pinned[v] && !on_bone[v]));
    if (f >= 0) {
      CHECK(f < d.num_free && !numbered[f]);
      numbered[f] = 1;
      ++free_count;
    }
  }
  CHECK(free_count == d.num_free && d.num_free > 0);
  // the pinned bone vertex is the one joint point, with the world
  CHECK(d.joints.size() == 1);
  if (d.joints.size() == 1)
    CHECK(d.joints[0].vertex == top && d.joints[0].bone == 0 && d.joints[0].other == -1 &&
          (d.joints[0].rest - m.rest.row(top).transpose()).norm() == 0.0);
  CHECK(d.lumped_mass.size() == nv && (d.lumped_mass.array() >= 0).all());
}

TEST_MAIN()
