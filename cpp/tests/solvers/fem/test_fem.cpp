// FEM on small meshes: its gradient against finite differences of its energy and a solve that
// converges (a bar); the rigid bones of a chain (RigidBones) against finite differences.
#include <Eigen/Dense>
#include <random>
#include "bar_model.h"
#include "check.h"
#include "emu/solvers/fem/rigid_bones.h"
#include "emu/model/unknown_layout.h"
#include "emu/mesh/tet_geometry.h"
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


namespace {
// Three movable bones, one tet each, and one soft tet: bone 0 turns about
// vertex 0 (pinned: a ball joint with the world), bone 1 about the edge 2-3 it
// shares with bone 0 (a hinge), bone 2 about vertex 5 it shares with bone 1 (a
// ball); the soft tet hangs from bone 2 by vertex 8.
Model three_bone_chain() {
  Model m;
  m.rest.resize(11, 3);
  m.rest << 0, 0, 0,  1, 0, 0,  0.2, 1, 0,  0.3, 0.1, 1,  1.4, 1.2, 0.6,  1.5, 0.4, 1.6,
            2.5, 0.5, 1.2,  1.6, 1.4, 2.2,  2.2, 0.2, 2.6,  3.2, 0.1, 2.9,  2.4, 1.1, 3.3;
  m.tets.resize(4, 4);
  m.tets << 0, 1, 2, 3,  2, 3, 4, 5,  5, 6, 7, 8,  8, 9, 10, 7;
  for (Eigen::Index t = 0; t < 4; ++t)
    if (signed_volumes(m.rest, m.tets)(t) < 0) std::swap(m.tets(t, 1), m.tets(t, 2));
  m.mu = Eigen::VectorXd::Constant(4, 1e4);
  m.lambda = Eigen::VectorXd::Constant(4, 1e5);
  m.density = Eigen::VectorXd::Ones(4);
  m.acap_weight = Eigen::VectorXd::Ones(4);
  m.fiber = Eigen::MatrixX3d::Zero(4, 3);
  m.fiber.col(2).setOnes();
  m.muscle = Eigen::VectorXi::Constant(4, -1);
  m.muscle(3) = 0;
  m.num_muscles = 1;
  m.num_bones = 3;
  m.bone.resize(4);
  m.bone << 0, 1, 2, -1;
  m.bone_stiffness = Eigen::Vector3d(0.0, 2.0, 0.5);  // springs on the hinge and the second ball
  m.pinned = Eigen::VectorXi::Zero(1);
  return m;
}
}  // namespace

// RigidBones (rigid_bones.h) on a chain: the forest's unknowns (ball 3, hinge
// 1, ball 3), rigid placements that keep the joints, and the bone rows of
// the gradient against finite differences of an energy of the placed vertices
// plus the springs.
TEST(rigid_bones_keep_their_joints_and_their_gradient_matches_finite_differences) {
  const Model m = three_bone_chain();
  m.validate();
  const UnknownLayout d(m);
  RigidBones bones(m, d);
  CHECK(bones.size() == 3 && bones.dofs() == 7);
  LoadCase load;
  load.activation = Eigen::VectorXd::Zero(1);
  Eigen::MatrixX3d x = m.rest;
  BonePoses poses = bones.begin(load, x, nullptr);
  std::mt19937 rng(2);
  std::normal_distribution<double> n(0.0, 0.3);
  Eigen::VectorXd db(7);
  for (int i = 0; i < 7; ++i) db(i) = n(rng);
  poses = bones.moved(poses, db, 1.0);  // away from rest
  bones.place(poses, x);
  CHECK(x.row(0).norm() == 0.0);  // the world's joint holds
  for (Eigen::Index t = 0; t < 3; ++t)  // each bone moves rigidly (its shared vertices with it)
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) {
        const int u = m.tets(t, a), v = m.tets(t, b);
        CHECK_CLOSE((x.row(u) - x.row(v)).norm(), (m.rest.row(u) - m.rest.row(v)).norm(), 1e-12);
      }
  CHECK((x - m.rest).norm() > 0.1);
  // E(x) = sum_v c_v . x_v + k/2 |x_v|^2 over the bones' vertices, plus the springs
  Eigen::MatrixX3d c = Eigen::MatrixX3d::Random(x.rows(), 3);
  const double k = 3.0;
  const auto energy = [&](const BonePoses& p) {
    Eigen::MatrixX3d y = x;
    bones.place(p, y);
    double e = bones.spring_energy(p);
    for (Eigen::Index v = 0; v < y.rows(); ++v)
      if (d.vertex_bone(v) >= 0) e += c.row(v).dot(y.row(v)) + 0.5 * k * y.row(v).squaredNorm();
    return e;
  };
  Eigen::MatrixX3d f = Eigen::MatrixX3d::Zero(x.rows(), 3);
  for (Eigen::Index v = 0; v < x.rows(); ++v)
    if (d.vertex_bone(v) >= 0) f.row(v) = c.row(v) + k * x.row(v);
  Eigen::VectorXd gb;
  bones.gradient(poses, x, f, gb);
  CHECK(gb.size() == 7);
  const double h = 1e-6;
  for (int i = 0; i < 7; ++i) {
    const Eigen::VectorXd e = Eigen::VectorXd::Unit(7, i);
    const double fd = (energy(bones.moved(poses, e, h)) - energy(bones.moved(poses, e, -h))) / (2 * h);
    CHECK_CLOSE(gb(i), fd, 1e-6 * (1.0 + std::abs(fd)));
  }
}

TEST_MAIN()
