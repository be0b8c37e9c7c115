// EMU's units on small meshes: bones on SO(3) and in joint coordinates, the ACAP fit with rigid tets, the
// gradient and Hessian against finite differences and dense solves, the bone coarse space.
#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <random>
#include "bar_model.h"
#include "check.h"
#include "emu/energy/joint_spring.h"
#include "emu/linalg/rotation.h"
#include "emu/solvers/emu/bone_coarse_space.h"
#include "emu/solvers/emu/bone_rotations.h"
#include "emu/solvers/emu/emu_solver.h"
#include "emu/solvers/emu/emu_solver_testing.h"
#include "emu/solvers/emu/joint_coordinates.h"

using namespace emu;


// The joint spring E(R) = k/2 (3 - tr R) is linear in R: its Euclidean
// Hessian is zero and its Riemannian Hessian is the curvature term alone.
// Along R exp(t [w]x): d2E/dt2 at 0 = <v, Hess[v]> with v = R [w]x.
TEST(riemannian_hessian_of_the_joint_spring_matches_finite_differences) {
  const double k = 3.0, h = 1e-4;
  const Mat3 G = joint_spring::gradient(k);
  for (double angle : {0.3, 2.9}) {
    const Mat3 R = rotation_exp(angle * Vec3(1, 2, 2).normalized());
    for (const Vec3& w : {Vec3(1, 0, 0), Vec3(0.3, -1, 0.5), Vec3(1, 2, 2).normalized()}) {
      const Mat3 V = R * cross_matrix(w);
      const double fd = (joint_spring::energy(R * rotation_exp(h * w), k) - 2 * joint_spring::energy(R, k) +
                         joint_spring::energy(R * rotation_exp(-h * w), k)) / (h * h);
      const Mat3 exact = bone_rotations::riemannian_block(R, G, V, Mat3::Zero(), true, 0.0);
      CHECK_CLOSE((V.cwiseProduct(exact)).sum(), fd, 1e-6 * std::max(1.0, std::abs(fd)));
      CHECK((R.transpose() * exact + (R.transpose() * exact).transpose()).norm() < 1e-12);  // tangent
      // The filtered form keeps the spring's curvature clamped PSD: equal
      // where it is convex (small turns), never negative.
      const Mat3 filtered = bone_rotations::riemannian_block(R, Mat3::Zero(), V, Mat3::Zero(), false, k);
      CHECK(V.cwiseProduct(filtered).sum() >= -1e-12);
      if (angle < 1.0) CHECK((filtered - exact).norm() < 1e-10 * k);
    }
  }
}

TEST(bone_columns_are_projected_and_retracted_onto_rotations) {
  const int num_soft = 2;
  Mat9X F = Mat9X::Random(9, 4), d = Mat9X::Random(9, 4);
  F.col(2) = flatten(rotation_exp(Vec3(0.1, 0.2, 0.3)));
  F.col(3) = flatten(rotation_exp(Vec3(-1.0, 0.5, 2.0)));
  Mat9X v = d;
  bone_rotations::project_tangent(F, num_soft, v);
  CHECK((v.leftCols(num_soft) - d.leftCols(num_soft)).norm() == 0.0);  // soft columns untouched
  Mat9X out;
  bone_rotations::retract(F, v, 0.5, num_soft, out);
  CHECK((out.leftCols(num_soft) - (F + 0.5 * v).leftCols(num_soft)).norm() < 1e-15);
  for (int u = num_soft; u < 4; ++u) {
    const Mat3 R = unflatten(F.col(u)), K = R.transpose() * unflatten(v.col(u));
    CHECK((K + K.transpose()).norm() < 1e-12);
    const Mat3 Q = unflatten(out.col(u));
    CHECK((Q.transpose() * Q - Mat3::Identity()).norm() < 1e-12 && Q.determinant() > 0);
  }
}

namespace {
// A chain of three movable bones: a root on a ball joint, a hinge child about
// rest axis a1 and a hinge grandchild about a2, after two soft unknowns; F
// with the bones on their joints (R1 = R0 exp(0.4 a1), R2 = R1 exp(-0.7 a2)).
struct Chain {
  const Vec3 a1 = Vec3(1, 0, 0), a2 = Vec3(0, 0.6, 0.8);
  JointCoordinates joints;
  Mat9X F = Mat9X::Random(9, 5);
  Chain() : joints(forest(), 2) {
    const Mat3 R0 = rotation_exp(Vec3(0.3, -0.5, 0.9)), R1 = R0 * rotation_exp(0.4 * a1);
    F.col(2) = flatten(R0);
    F.col(3) = flatten(R1);
    F.col(4) = flatten(Mat3(R1 * rotation_exp(-0.7 * a2)));
  }
  BoneForest forest() const {
    std::vector<BoneForest::Node> nodes(3);
    nodes[0].kind = BoneForest::Kind::Ball;
    for (int b : {1, 2}) {
      nodes[b].kind = BoneForest::Kind::Hinge;
      nodes[b].parent = b - 1;
    }
    nodes[1].rest_axis = a1;
    nodes[2].rest_axis = a2;
    return BoneForest(nodes, {0, 1, 2});
  }
  Mat3 R(const Mat9X& G, int b) const { return unflatten(G.col(2 + b)); }
  // the hinges' axes agree between child and parent
  double joint_gap(const Mat9X& G) const {
    return (R(G, 1) * a1 - R(G, 0) * a1).norm() + (R(G, 2) * a2 - R(G, 1) * a2).norm();
  }
};
}  // namespace

TEST(joint_coordinates_project_and_retract_along_the_tree) {
  Chain c;
  CHECK(c.joints.size() == 5 && c.joint_gap(c.F) < 1e-14);
  const Mat9X d = Mat9X::Random(9, 5), e = Mat9X::Random(9, 5);
  Mat9X v = d, w = e;
  c.joints.project(c.F, v);
  c.joints.project(c.F, w);
  CHECK((v.leftCols(2) - d.leftCols(2)).norm() == 0.0);  // soft columns untouched
  Mat9X vv = v;
  c.joints.project(c.F, vv);
  CHECK((vv - v).norm() < 1e-13);                                        // idempotent
  CHECK(std::abs(v.rightCols(3).cwiseProduct(e.rightCols(3)).sum() -
                 d.rightCols(3).cwiseProduct(w.rightCols(3)).sum()) < 1e-12);  // orthogonal
  for (double s : {0.7, -2.0}) {  // the joints hold along the whole path, not to first order
    Mat9X out;
    c.joints.retract(c.F, v, s, out);
    CHECK(c.joint_gap(out) < 1e-12);
    for (int b = 0; b < 3; ++b) CHECK((c.R(out, b).transpose() * c.R(out, b) - Mat3::Identity()).norm() < 1e-12);
    CHECK((out.leftCols(2) - (c.F + s * v).leftCols(2)).norm() < 1e-14);
  }
  const double h = 1e-6;  // the path's tangent at 0 is v
  Mat9X plus, minus;
  c.joints.retract(c.F, v, h, plus);
  c.joints.retract(c.F, v, -h, minus);
  CHECK(((plus - minus) / (2 * h) - v).norm() < 1e-8 * v.norm());
  Mat9X off = c.F;  // a start off its joints goes back onto them
  off.col(3) = flatten(Mat3(rotation_exp(Vec3(0.05, 0.1, -0.02)) * c.R(c.F, 1)));
  c.joints.project_onto_joints(off, Eigen::MatrixX3d());
  CHECK(c.joint_gap(off) < 1e-12);
}

// The rotation term is the curvature of the tree's retraction: for the linear
// function f(F) = sum_b <G_b, R_b> (no Euclidean Hessian), d2f/ds2 along
// retract(F, v, s) at 0 is theta' W theta, theta the joint coordinates of v.
TEST(joint_coordinates_rotation_term_matches_finite_differences) {
  Chain c;
  const Mat9X G = Mat9X::Random(9, 5);
  auto f = [&](const Mat9X& F) { return F.rightCols(3).cwiseProduct(G.rightCols(3)).sum(); };
  const Eigen::MatrixXd W = c.joints.rotation_term(c.F, G, false), Wp = c.joints.rotation_term(c.F, G, true);
  CHECK((W - W.transpose()).norm() < 1e-12 * W.norm());
  CHECK(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Wp).eigenvalues().minCoeff() > -1e-12 * W.norm());
  const double h = 1e-4;
  for (int trial = 0; trial < 4; ++trial) {
    Mat9X v = Mat9X::Random(9, 5);
    c.joints.project(c.F, v);
    Mat9X plus, minus;
    c.joints.retract(c.F, v, h, plus);
    c.joints.retract(c.F, v, -h, minus);
    const double fd = (f(plus) - 2 * f(c.F) + f(minus)) / (h * h);
    const Eigen::VectorXd theta = c.joints.coordinates(c.F, v);
    CHECK_CLOSE(theta.dot(W * theta), fd, 1e-6 * std::max(1.0, std::abs(fd)));
    Mat9X out = Mat9X::Zero(9, 5);  // the product as a tangent: <v, out> = theta' W theta
    c.joints.add_rotation_product(c.F, W, v, out);
    CHECK_CLOSE(v.cwiseProduct(out).sum(), theta.dot(W * theta), 1e-10 * std::max(1.0, std::abs(fd)));
  }
}

TEST(emu_gradient_matches_energy) {
  const Model m = bar(2, 3);
  EmuSolverOptions eo;
  eo.alpha = 1e3 * m.mu(0);
  EmuSolver emu(m, SolverOptions{}, eo);
  const LoadCase l = bar_load(3e4);
  std::mt19937 rng(9);
  std::normal_distribution<double> n(0, 0.05);
  Eigen::MatrixXd F(m.tets.rows(), 9);
  for (Eigen::Index t = 0; t < F.rows(); ++t) F.row(t) = Eigen::Map<const Eigen::Matrix<double, 1, 9>>(Mat3::Identity().eval().data());
  for (Eigen::Index i = 0; i < F.size(); ++i) F.data()[i] += n(rng);
  const Eigen::MatrixXd g = EmuSolverTesting::gradient(emu, l, F);
  const double h = 1e-7;
  for (int t : {0, 7, 30}) {
    for (int c = 0; c < 9; ++c) {
      Eigen::MatrixXd a = F, b = F;
      a(t, c) += h;
      b(t, c) -= h;
      CHECK_CLOSE(g(t, c), (EmuSolverTesting::energy(emu, l, a) - EmuSolverTesting::energy(emu, l, b)) / (2 * h), 1e-5 * (1 + g.norm()));
    }
  }
}

TEST(emu_with_all_modes_inverts_the_exact_hessian) {
  const Model m = bar(1, 2);
  UnknownLayout d(m);
  EmuSolverOptions eo;
  eo.alpha = 50 * m.mu(0);
  eo.modes = 3 * d.num_free;  // every mode: the Woodbury inverse is exact
  eo.preconditioner = EmuPreconditioner::Woodbury;  // (the default, constant Schur, builds no modes)
  EmuSolver emu(m, SolverOptions{}, eo);
  const LoadCase l = bar_load(1e4);
  Eigen::MatrixXd F(m.tets.rows(), 9), R = Eigen::MatrixXd::Random(m.tets.rows(), 9);
  for (Eigen::Index t = 0; t < F.rows(); ++t) F.row(t) = Eigen::Map<const Eigen::Matrix<double, 1, 9>>(Mat3::Identity().eval().data());
  const Eigen::MatrixXd Y = EmuSolverTesting::woodbury_solve(emu, l, F, R);
  const Eigen::MatrixXd HY = EmuSolverTesting::hessian_product(emu, l, F, Y);
  CHECK((HY - R).norm() <= 1e-8 * R.norm());
}

TEST(emu_single_precision_preconditioner_changes_cg_not_the_answer) {
  const Model m = bar(3, 16);
  const LoadCase l = bar_load(3e4);
  const double diag = (m.rest.colwise().maxCoeff() - m.rest.colwise().minCoeff()).norm();
  SolveResult r[2];
  for (int single : {0, 1}) {
    EmuSolverOptions eo;
    eo.alpha = 100 * m.mu(0);
    eo.single_precision_preconditioner = single == 1;
    EmuSolver emu(m, SolverOptions{}, eo);
    r[single] = emu.solve(l);
    CHECK(r[single].converged);
    // the rounded factor copy is listed with the preconditioner's bytes (4
    // per factor entry), and its blocks take 81 floats instead of 81 doubles
    double bytes = 0.0;
    for (const auto& [name, b] : emu.structures())
      if (name == "constant Schur preconditioner") bytes = b;
    const double blocks = double(m.tets.rows()) * 81.0 * (single ? 4.0 : 8.0);
    CHECK_CLOSE(bytes, blocks + (single ? 4.0 * emu.factor_nnz() : 0.0), 1e-9 * bytes);
  }
  CHECK((r[1].positions - r[0].positions).rowwise().norm().maxCoeff() <= 1e-6 * diag);
  CHECK(r[1].cg_iterations <= 1.15 * r[0].cg_iterations + 2 && r[0].cg_iterations <= 1.15 * r[1].cg_iterations + 2);
  CHECK(r[0].cg_iterations > 0);
}

// The bar with two movable bones: the top layer of hexes (bone 0) but one
// tet, which stays soft with all four vertices on bone 0 (rigid tissue), and
// the layer below it (bone 1, sharing the vertices between the layers with
// bone 0: joints, those vertices placed by bone 0). Rigid tets (all four
// vertices placed by one bone) are summed in closed form (acap.h): C and C^T
// must stay adjoint, and C^T u must be w V F_t of the positions u places
// (deformation_gradients, the general per-tet path).
namespace {
Model bar_with_two_bones(int& soft_rigid) {
  Model m = bar(2, 5);
  const Eigen::Index nt = m.tets.rows();
  m.num_bones = 2;
  m.bone = Eigen::VectorXi::Constant(nt, -1);
  soft_rigid = -1;
  for (Eigen::Index t = 0; t < nt; ++t) {
    double zmin = 1e9;
    for (int a = 0; a < 4; ++a) zmin = std::min(zmin, m.rest(m.tets(t, a), 2));
    const int b = zmin >= 4.0 ? 0 : zmin >= 3.0 ? 1 : -1;
    if (b == 0 && soft_rigid < 0) {
      soft_rigid = static_cast<int>(t);  // the first hex's first tet stays muscle
      continue;
    }
    if (b >= 0) {
      m.bone(t) = b;
      m.muscle(t) = -1;
    }
  }
  m.bone_stiffness = Eigen::VectorXd::Zero(2);
  return m;
}
}  // namespace

TEST(acap_rigid_tets_keep_c_and_ct_adjoint) {
  int soft_rigid = -1;
  const Model m = bar_with_two_bones(soft_rigid);
  const Eigen::Index nt = m.tets.rows();
  const UnknownLayout layout(m);
  const AcapOperator acap(m, layout);
  CHECK(acap.has_bones() && (m.bone.array() == 0).count() == 23 && (m.bone.array() == 1).count() == 24);
  for (int a = 0; a < 4; ++a) CHECK(layout.vertex_bone(m.tets(soft_rigid, a)) == 0);  // rigid, yet soft
  std::mt19937 rng(4);
  std::normal_distribution<double> n(0, 1);
  Mat9X D(9, nt);
  Eigen::MatrixX3d u(acap.dofs(), 3);
  for (Eigen::Index i = 0; i < D.size(); ++i) D.data()[i] = n(rng);
  for (Eigen::Index i = 0; i < u.size(); ++i) u.data()[i] = n(rng);
  Eigen::MatrixX3d R;
  Mat9X CTu, F;
  acap.apply_C(D, R);
  acap.apply_CT(u, CTu);
  const double lhs = (R.array() * u.array()).sum(), rhs = (D.array() * CTu.array()).sum();
  CHECK_CLOSE(lhs, rhs, 1e-12 * (R.norm() * u.norm()));
  Eigen::MatrixX3d x = Eigen::MatrixX3d::Zero(m.rest.rows(), 3);
  acap.expand(u, x);
  deformation_gradients(layout, m.tets, x, F);
  double worst = 0;
  for (Eigen::Index t = 0; t < nt; ++t)
    worst = std::max(worst, (CTu.col(t) - acap.weight_volume()(t) * F.col(t)).norm());
  CHECK(worst <= 1e-12 * CTu.norm());
  // C of the unknowns (a bone's own rigid tets summed per bone, the soft
  // rigid tet on its own) equals C of the unknowns expanded per tet.
  Mat9X U(9, layout.num_unknowns), per_tet(9, nt);
  for (Eigen::Index i = 0; i < U.size(); ++i) U.data()[i] = n(rng);
  for (Eigen::Index t = 0; t < nt; ++t) per_tet.col(t) = U.col(layout.tet_unknown(t));
  Eigen::MatrixX3d RU, Rt;
  acap.apply_C_of_unknowns(U, RU);
  acap.apply_C(per_tet, Rt);
  CHECK((RU - Rt).norm() <= 1e-12 * Rt.norm());
  CHECK(layout.tet_unknown(soft_rigid) < layout.num_soft);  // the other kind is there too
}


// An operator built in single precision (ConstantSchur's own S0) solves with
// the rounded factor everywhere, the bone elimination included: one
// symmetric operator (u . K~^-1 v = v . K~^-1 u to round-off; the block
// elimination is symmetric for any W, so this guards the solve's structure,
// not the rounding), within float round-off of the exact solve, and not
// equal to it.
TEST(acap_single_precision_operator_with_bones_stays_symmetric) {
  int soft_rigid = -1;
  const Model m = bar_with_two_bones(soft_rigid);
  const UnknownLayout layout(m);
  const AcapOperator exact(m, layout), rounded(m, layout, nullptr, &exact, true);
  CHECK(rounded.has_bones());
  std::mt19937 rng(6);
  std::normal_distribution<double> n(0, 1);
  Eigen::MatrixXd u(exact.dofs(), 3), v(exact.dofs(), 3), Ku, Kv, Ke;
  for (Eigen::Index i = 0; i < u.size(); ++i) u.data()[i] = n(rng);
  for (Eigen::Index i = 0; i < v.size(); ++i) v.data()[i] = n(rng);
  rounded.solve(u, Ku);
  rounded.solve(v, Kv);
  exact.solve(u, Ke);
  const double uKv = (u.array() * Kv.array()).sum(), vKu = (v.array() * Ku.array()).sum();
  CHECK(std::abs(uKv - vKu) <= 1e-11 * Ku.norm() * v.norm());
  CHECK((Ku - Ke).norm() <= 1e-4 * Ke.norm() && (Ku - Ke).norm() > 0.0);
}

// The coarse space's rebuild forms a bone's three turns in one pass over the
// blocks (BoneTurnFits::turns<3>); bone_turn, which the Python tests
// check against the fit and the generic Hessian product, takes one turn
// through the same code (<1>): the two must give the same bits.
TEST(bone_turns_at_once_match_one_at_a_time) {
  int soft_rigid = -1;
  const Model m = bar_with_two_bones(soft_rigid);
  EmuSolverOptions eo;
  eo.alpha = 50.0;
  EmuSolver emu(m, SolverOptions{}, eo);
  const UnknownLayout layout(m);
  const int nu = layout.num_unknowns, ns = layout.num_soft;
  std::mt19937 rng(11);
  std::normal_distribution<double> g(0, 1);
  Eigen::MatrixXd F(nu, 9);
  for (int u = 0; u < nu; ++u) {
    Mat3 f = Mat3::Identity();
    for (int i = 0; i < 9; ++i) f.data()[i] += 0.05 * g(rng);
    if (u >= ns) f = Eigen::AngleAxisd(0.4 + u, Vec3(1, 2, 3).normalized()).toRotationMatrix();
    F.row(u) = flatten(f).transpose();
  }
  for (int b = 0; b < 2; ++b)
    for (bool exact : {false, true}) {
      std::array<Eigen::Matrix3d, 3> M;
      for (int k = 0; k < 3; ++k) M[k] = Eigen::Matrix3d::Random();
      const auto three = EmuSolverTesting::bone_turns(emu, bar_load(0.3), F, b, M, exact);
      for (int k = 0; k < 3; ++k) {
        const auto one = EmuSolverTesting::bone_turn(emu, bar_load(0.3), F, b, M[k], exact);
        CHECK(three[k].first == one.first && three[k].second == one.second);
        CHECK(one.second.norm() > 0);
      }
    }
}

// The bone coarse space never stores Z's turn columns: it takes Z^T r and
// Z c from the bones' shared follow fields (turn k of bone b is M_bk Phi_b).
// Against the dense balancing form M^-1 = Q + (I - Q H) B (I - H Q), Q =
// Z (Z^T H Z)^-1 Z^T, with Z's columns as turn() returned them, a random SPD
// H, a recycled direction and B = I (base: a copy); and the additive form
// Q + B where Z^T H Z is singular (a recycled direction equal to a turn).
TEST(bone_coarse_space_matches_the_dense_balancing_preconditioner) {
  int soft_rigid = -1;
  const Model m = bar_with_two_bones(soft_rigid);
  const UnknownLayout layout(m);
  const int ns = layout.num_soft, nu = layout.num_unknowns, nb = layout.num_bones, n = 9 * nu;
  CHECK(nb == 2);
  std::mt19937 rng(8);
  std::normal_distribution<double> g(0, 1);
  std::vector<Mat9X> follow(nb, Mat9X(9, ns));
  for (Mat9X& f : follow)
    for (Eigen::Index i = 0; i < f.size(); ++i) f.data()[i] = g(rng);
  Eigen::MatrixXd G(n, n);
  for (Eigen::Index i = 0; i < G.size(); ++i) G.data()[i] = g(rng);
  const Eigen::MatrixXd H = G * G.transpose() / n + Eigen::MatrixXd::Identity(n, n);
  auto flat = [](const Mat9X& v) { return Eigen::Map<const Eigen::VectorXd>(v.data(), v.size()); };
  auto hprod = [&](const Mat9X& v, Mat9X& out) {
    out.resize(9, v.cols());
    Eigen::Map<Eigen::VectorXd>(out.data(), out.size()) = H * flat(v);
  };
  Mat9X F = Mat9X::Zero(9, nu);
  for (int b = 0; b < nb; ++b)
    F.col(ns + b) = flatten(Eigen::AngleAxisd(0.3 + b, Vec3(1, 2, 3 - b).normalized()).toRotationMatrix());
  std::vector<Mat9X> turns;
  auto turn = [&](int b, const std::array<Mat3, 3>& M, std::array<Mat9X, 3>& Z, std::array<Mat9X, 3>& HZ) {
    for (int k = 0; k < 3; ++k) {
      Z[k] = Mat9X::Zero(9, nu);
      for (int u = 0; u < ns; ++u) Z[k].col(u) = flatten(Mat3(M[k] * unflatten(follow[b].col(u))));
      Z[k].col(ns + b) = flatten(M[k]);
      hprod(Z[k], HZ[k]);
      turns.push_back(Z[k]);
    }
  };
  Mat9X extra(9, nu), r(9, nu);
  for (Eigen::Index i = 0; i < extra.size(); ++i) extra.data()[i] = g(rng);
  for (Eigen::Index i = 0; i < r.size(); ++i) r.data()[i] = g(rng);
  auto base = [](const Mat9X& in, Mat9X& out) { out = in; };
  // with a turn map: the coarse turns are T's combinations of the bones'
  // (bone 1 hinged to bone 0 about the world x axis: 4 joint coordinates)
  Eigen::MatrixXd T = Eigen::MatrixXd::Zero(3 * nb, 4);
  T.topLeftCorner(3, 3).setIdentity();
  T.block(3, 0, 3, 3).setIdentity();
  T(3, 3) = 1.0;
  for (int mapped : {0, 1})
  for (int deficient : {0, 1}) {
    if (mapped && deficient) continue;
    BoneCoarseSpace coarse(layout, 1.0, {&follow[0], &follow[1]});
    turns.clear();
    coarse.build(F, turn, hprod, {extra}, mapped ? &T : nullptr);
    CHECK(static_cast<int>(turns.size()) == 3 * nb);
    Eigen::MatrixXd Z(n, 3 * nb + 1);
    for (int j = 0; j < 3 * nb; ++j) Z.col(j) = flat(turns[j]);
    Z.col(3 * nb) = flat(extra);
    if (deficient) {  // a recycled direction equal to a turn: Z^T H Z singular, the additive form
      coarse.build(F, turn, hprod, {turns[1]});
      for (int j = 0; j < 3 * nb; ++j) Z.col(j) = flat(turns[3 * nb + j]);
      Z.col(3 * nb) = Z.col(1);
    }
    if (mapped) {  // Z's turn columns combined by T, the recycled direction kept
      const Eigen::MatrixXd Zt = Z.leftCols(3 * nb) * T;
      const Eigen::VectorXd z_extra = Z.col(3 * nb);
      Z.resize(n, 5);
      Z << Zt, z_extra;
    }
    const Eigen::MatrixXd E = Z.transpose() * H * Z;
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(E);
    Eigen::MatrixXd Einv = Eigen::MatrixXd::Zero(E.rows(), E.cols());
    for (int i = 0; i < E.rows(); ++i)
      if (es.eigenvalues()(i) > 1e-9 * es.eigenvalues().maxCoeff())
        Einv += es.eigenvectors().col(i) * es.eigenvectors().col(i).transpose() / es.eigenvalues()(i);
    const Eigen::MatrixXd Q = Z * Einv * Z.transpose(), I = Eigen::MatrixXd::Identity(n, n);
    const Eigen::MatrixXd Minv = deficient ? Eigen::MatrixXd(Q + I) : Eigen::MatrixXd(Q + (I - Q * H) * (I - H * Q));
    Mat9X out;
    coarse.apply(r, out, base);
    const Eigen::VectorXd want = Minv * flat(r);
    CHECK((flat(out) - want).norm() <= 1e-10 * want.norm());
  }
}

namespace {
// F near rest (#unknowns by 9 rows, vec(F) column-major), the bones' F's rotations.
Eigen::MatrixXd near_rest_unknowns(const UnknownLayout& d, std::mt19937& rng, double spread) {
  std::normal_distribution<double> n(0.0, spread);
  Eigen::MatrixXd F(d.num_unknowns, 9);
  for (int u = 0; u < d.num_unknowns; ++u) {
    Mat3 G = Mat3::Identity();
    for (int i = 0; i < 9; ++i) G.data()[i] += n(rng);
    if (u >= d.num_soft) G = nearest_rotation(G);
    F.row(u) = Eigen::Map<const Eigen::Matrix<double, 1, 9>>(G.data());
  }
  return F;
}

EmuSolver emu_with(const Model& m, EmuPreconditioner pc) {
  EmuSolverOptions eo;
  eo.alpha = 50 * m.mu(0);
  eo.preconditioner = pc;
  return EmuSolver(m, SolverOptions{}, eo);
}
}  // namespace

// The fit is linear in F (the bones' affine maps are unknowns of it, their
// joints homogeneous rows): x*(F + D) - x*(F) is the homogeneous fit of D,
// which the directions' fits (fit_jacobian.h) compute.
TEST(fit_of_a_direction_is_the_fits_difference) {
  int soft_rigid = -1;
  for (const Model& m : {bar(2, 3), bar_with_two_bones(soft_rigid)}) {
    const UnknownLayout d(m);
    const EmuSolver emu = emu_with(m, EmuPreconditioner::ConstantSchur);
    std::mt19937 rng(11);
    const Eigen::MatrixXd F = near_rest_unknowns(d, rng, 0.2), D = near_rest_unknowns(d, rng, 0.3) - F;
    const LoadCase l = bar_load(0.0);
    const Eigen::MatrixX3d diff = EmuSolverTesting::fit_positions(emu, l, F + D) - EmuSolverTesting::fit_positions(emu, l, F);
    Mat9X Dc = D.transpose(), Fd;
    Eigen::MatrixX3d dx;
    EmuSolverTesting::fit_linear_into(emu, Dc, dx, Fd);
    for (Eigen::Index v = 0; v < m.rest.rows(); ++v)
      if (d.free_index(v) >= 0 || d.vertex_bone(v) >= 0) CHECK((dx.row(v) - diff.row(v)).norm() <= 1e-10 * diff.norm());
    CHECK(diff.norm() > 1e-3);
  }
}

// The Schur-complement preconditioner is the exact inverse of the filtered
// Hessian H = A - alpha C^T K_c^-1 C (schur_preconditioner.h); it takes no
// movable bones, and says so.
TEST(schur_preconditioner_inverts_the_filtered_hessian) {
  int soft_rigid = -1;
  bool refused = false;
  try {
    emu_with(bar_with_two_bones(soft_rigid), EmuPreconditioner::Schur);
  } catch (const std::invalid_argument& e) {
    refused = std::string(e.what()).find("woodbury") != std::string::npos;
  }
  CHECK(refused);
  for (const Model& m : {bar(1, 3), bar(2, 2)}) {
    const UnknownLayout d(m);
    EmuSolver emu = emu_with(m, EmuPreconditioner::Schur);
    std::mt19937 rng(5);
    const Eigen::MatrixXd F = near_rest_unknowns(d, rng, 0.1), R = Eigen::MatrixXd::Random(d.num_unknowns, 9);
    const LoadCase l = bar_load(2e4);
    const Eigen::MatrixXd Y = EmuSolverTesting::schur_solve(emu, l, F, R);
    CHECK((EmuSolverTesting::hessian_product(emu, l, F, Y) - R).norm() <= 1e-8 * R.norm());
  }
}

// The constant Schur preconditioner (constant_schur.h) approximates H^-1: it
// must be symmetric and positive definite for CG, with bones too.
TEST(constant_schur_preconditioner_is_symmetric_and_positive) {
  int soft_rigid = -1;
  for (const Model& m : {bar(2, 3), bar_with_two_bones(soft_rigid)}) {
    const UnknownLayout d(m);
    EmuSolver emu = emu_with(m, EmuPreconditioner::ConstantSchur);
    std::mt19937 rng(6);
    const Eigen::MatrixXd F = near_rest_unknowns(d, rng, 0.1);
    const Eigen::MatrixXd U = Eigen::MatrixXd::Random(d.num_unknowns, 9), V = Eigen::MatrixXd::Random(d.num_unknowns, 9);
    const LoadCase l = bar_load(2e4);
    const Eigen::MatrixXd MU = EmuSolverTesting::constant_schur_solve(emu, l, F, U);
    const Eigen::MatrixXd MV = EmuSolverTesting::constant_schur_solve(emu, l, F, V);
    const double uMv = (U.array() * MV.array()).sum(), vMu = (V.array() * MU.array()).sum();
    CHECK_CLOSE(uMv, vMu, 1e-10 * MU.norm() * V.norm());
    CHECK((U.array() * MU.array()).sum() > 0 && (V.array() * MV.array()).sum() > 0);
    // not the identity nor the exact inverse, but close to H^-1 on a smooth field: M H v ~ v
    const Eigen::MatrixXd HU = EmuSolverTesting::hessian_product(emu, l, F, U);
    const Eigen::MatrixXd MHU = EmuSolverTesting::constant_schur_solve(emu, l, F, HU);
    CHECK((MHU - U).norm() < U.norm());
  }
}


TEST_MAIN()
