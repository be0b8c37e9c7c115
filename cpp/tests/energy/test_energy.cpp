// Element kernels against central finite differences and invariants.
#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <vector>

#include "check.h"
#include "emu/energy/acap_coupling.h"
#include "emu/energy/fiber.h"
#include "emu/energy/gravity_work.h"
#include "emu/energy/joint_spring.h"
#include "emu/energy/material.h"
#include "emu/energy/psd_project.h"
#include "emu/energy/snh_eigensystem.h"
#include "emu/energy/stable_neo_hookean.h"
#include "emu/linalg/rotation.h"
#include "emu/mesh/tet_geometry.h"

using namespace emu;

namespace {
const double mu = 2.0e4, lam = 1.0e6;
std::mt19937 rng(7);
Mat3 random_F(double spread) {
  std::normal_distribution<double> n(0.0, spread);
  Mat3 F = Mat3::Identity();
  for (int i = 0; i < 9; ++i) F.data()[i] += n(rng);
  return F;
}
Mat3 fd_stress(const Mat3& F, const std::function<double(const Mat3&)>& e) {
  const double h = 1e-6;
  Mat3 P;
  for (int i = 0; i < 9; ++i) {
    Mat3 a = F, b = F;
    a.data()[i] += h;
    b.data()[i] -= h;
    P.data()[i] = (e(a) - e(b)) / (2 * h);
  }
  return P;
}
Mat9 fd_hessian(const Mat3& F, const std::function<Mat3(const Mat3&)>& p) {
  const double h = 1e-6;
  Mat9 H;
  for (int i = 0; i < 9; ++i) {
    Mat3 a = F, b = F;
    a.data()[i] += h;
    b.data()[i] -= h;
    H.col(i) = flatten((p(a) - p(b)) / (2 * h));
  }
  return H;
}
}  // namespace

// The F the kernels meet: near rest, spread out, compressed (principal
// stretches 0.6, 0.8, 1.3), inverted, and inverted flat (-0.2, 0.9, 1.1).
std::vector<Mat3> sample_Fs() {
  std::vector<Mat3> out;
  const auto rotation = [] {
    return Mat3(Eigen::AngleAxisd(random_F(1.0).norm(), random_F(1.0).col(0).normalized()).toRotationMatrix());
  };
  for (int k = 0; k < 4; ++k) {
    out.push_back(random_F(1e-3));
    out.push_back(random_F(0.3));
    Mat3 inverted = random_F(0.3);
    if (inverted.determinant() > 0) inverted.col(0) *= -1;
    out.push_back(inverted);
    const Mat3 R = rotation(), Q = rotation();
    out.push_back(R * Vec3(0.6, 0.8, 1.3).asDiagonal() * Q.transpose());
    out.push_back(R * Vec3(-0.2, 0.9, 1.1).asDiagonal() * Q.transpose());
  }
  return out;
}

// soft and stiff muscle-like, nearly incompressible, and bone-like materials
const std::vector<std::array<double, 2>> kMaterials = {{2e4, 1e6}, {2e4, 2e4}, {1.5e8, 7e9}};

TEST(snh_stress_matches_finite_differences) {
  for (const auto& [m, l] : kMaterials)
    for (const Mat3& F : sample_Fs()) {
      const Mat3 P = snh::stress(F, m, l);
      const Mat3 Pfd = fd_stress(F, [&](const Mat3& G) { return snh::energy(G, m, l); });
      const double scale = m + l * std::max(1.0, std::abs(F.determinant()));
      CHECK((P - Pfd).cwiseAbs().maxCoeff() <= 1e-7 * scale);
    }
}

TEST(snh_hessian_matches_finite_differences) {
  for (const auto& [m, l] : kMaterials)
    for (const Mat3& F : sample_Fs()) {
      const Mat9 H = snh::hessian(F, m, l);
      const Mat9 Hfd = fd_hessian(F, [&](const Mat3& G) { return snh::stress(G, m, l); });
      const double scale = Hfd.cwiseAbs().maxCoeff();
      CHECK((H - Hfd).cwiseAbs().maxCoeff() <= 1e-7 * scale);
      CHECK((H - H.transpose()).cwiseAbs().maxCoeff() <= 1e-12 * scale);
    }
}

TEST(snh_hessian_action_matches_the_hessian) {
  // Near rest, spread out and inverted F, random directions D.
  for (double spread : {0.05, 0.3, 1.5})
    for (int trial = 0; trial < 20; ++trial) {
      const Mat3 F = random_F(spread), D = random_F(1.0) - Mat3::Identity();
      const Vec9 ref = snh::hessian(F, 1.3e4, 9.0e5) * flatten(D);
      const Vec9 got = flatten(snh::hessian_action(F, 1.3e4, 9.0e5, D));
      CHECK((got - ref).norm() <= 1e-12 * (ref.norm() + 1e4));
    }
}

TEST(snh_zero_energy_and_stress_at_rest_and_under_rotation) {
  for (const auto& [m, l] : {std::array<double, 2>{2e4, 1e6}, {2e4, 2e4}, {3.4e9, 1.6e11}}) {
    CHECK_CLOSE(snh::energy(Mat3::Identity(), m, l), 0.0, 1e-12 * l);
    CHECK(snh::stress(Mat3::Identity(), m, l).cwiseAbs().maxCoeff() <= 1e-12 * l);
    for (int k = 0; k < 5; ++k) {
      const Mat3 R = Eigen::AngleAxisd(0.7 * (k + 1), random_F(1.0).col(k % 3).normalized()).toRotationMatrix();
      CHECK_CLOSE(snh::energy(R, m, l), 0.0, 1e-12 * l);
      CHECK(snh::stress(R, m, l).cwiseAbs().maxCoeff() <= 1e-12 * l);
    }
    // and not zero away from rest: the checks above can fail
    const Mat3 F = Vec3(1.1, 1.0, 1.0).asDiagonal();
    CHECK(snh::energy(F, m, l) > 1e-4 * m);
    CHECK(snh::stress(F, m, l).cwiseAbs().maxCoeff() > 1e-2 * m);
  }
}

TEST(fiber_derivatives_and_rest_value) {
  const Vec3 u = Vec3(0.3, -0.2, 0.9).normalized();
  const double a = 5e4;
  CHECK_CLOSE(fiber::energy(Mat3::Identity(), u, a), 0.0, 1e-9);
  for (int k = 0; k < 10; ++k) {
    const Mat3 F = random_F(0.3);
    const Mat3 Pfd = fd_stress(F, [&](const Mat3& G) { return fiber::energy(G, u, a); });
    CHECK((fiber::stress(F, u, a) - Pfd).norm() <= 1e-5 * (1 + Pfd.norm()));
    const Mat9 Hfd = fd_hessian(F, [&](const Mat3& G) { return fiber::stress(G, u, a); });
    CHECK((fiber::hessian(u, a) - Hfd).norm() <= 1e-5 * (1 + Hfd.norm()));
  }
}

TEST(psd_projection_is_psd_and_keeps_psd_input) {
  for (int k = 0; k < 20; ++k) {
    const Mat9 H = snh::hessian(random_F(0.4), mu, lam);
    const Mat9 P = psd_project<9>(H);
    Eigen::SelfAdjointEigenSolver<Mat9> es(P);
    CHECK(es.eigenvalues().minCoeff() >= -1e-9 * H.norm());
    CHECK((P - P.transpose()).norm() <= 1e-9 * H.norm());
    // the projection is idempotent up to roundoff, and a PD input is returned bit for bit
    const Mat9 PD = P + 1e-3 * H.norm() * Mat9::Identity();
    CHECK((psd_project<9>(PD) - PD).norm() == 0.0);
    // reflection keeps |eigenvalues|
    Eigen::SelfAdjointEigenSolver<Mat9> e0(H), e1(psd_project<9>(H, EigenFilter::Abs));
    Eigen::Matrix<double, 9, 1> a0 = e0.eigenvalues().cwiseAbs();
    std::sort(a0.data(), a0.data() + 9);
    CHECK((a0 - e1.eigenvalues()).norm() <= 1e-9 * H.norm());
  }
}

// Deformation gradients where the closed-form projection must agree with the
// numerical one: random, near rest, rotations, inverted, degenerate (flat,
// collapsed, repeated singular values).
std::vector<Mat3> eigensystem_cases() {
  std::vector<Mat3> Fs;
  for (int k = 0; k < 12; ++k) Fs.push_back(random_F(0.5));
  for (int k = 0; k < 6; ++k) Fs.push_back(random_F(1e-4));
  const Mat3 R = rotation_exp(Vec3(0.3, -1.1, 0.7));
  Fs.push_back(Mat3::Identity());
  Fs.push_back(R);
  Fs.push_back(1.3 * R);
  Fs.push_back(R * Vec3(0.5, 0.5, 2.0).asDiagonal());                 // two equal singular values
  Fs.push_back(R * Vec3(1.0, 1.0, -0.5).asDiagonal());                // inverted
  Fs.push_back(R * Vec3(-1.2, 0.8, 0.9).asDiagonal() * R.transpose()); // inverted, reflected in the SVD
  Fs.push_back(R * Vec3(1.1, 0.7, 0.0).asDiagonal());                 // flat: J = 0
  Fs.push_back(R * Vec3(0.3, 1e-9, 1e-9).asDiagonal());               // collapsed to a line
  Fs.push_back(Mat3::Zero());
  for (int k = 0; k < 6; ++k) {
    Mat3 F = random_F(0.5);
    F.col(0) = -F.col(0);  // inverted random
    Fs.push_back(F);
  }
  return Fs;
}

TEST(snh_analytic_eigensystem_matches_the_numerical_one) {
  for (double l : {lam, 10.0 * mu, 0.5 * mu}) {
    for (const Mat3& F : eigensystem_cases()) {
      const Mat9 H = snh::hessian(F, mu, l);
      const snh::Eigensystem es = snh::eigensystem(F, mu, l);
      CHECK((es.U * es.sigma.asDiagonal() * es.V.transpose() - F).norm() <= 1e-12 * (1.0 + F.norm()));
      CHECK(std::abs(es.U.determinant() - 1.0) < 1e-12 && std::abs(es.V.determinant() - 1.0) < 1e-12);
      Eigen::Matrix<double, 9, 1> analytic;
      analytic << es.twist, es.flip, es.scaling;
      const double scale = H.norm();
      for (int k = 0; k < 3; ++k) {  // each mode is a unit eigenvector with its eigenvalue
        const Vec9 q[3] = {snh::twist_flip_mode(es, k, false), snh::twist_flip_mode(es, k, true),
                           snh::scaling_mode(es, k)};
        const double lam_k[3] = {es.twist(k), es.flip(k), es.scaling(k)};
        for (int m = 0; m < 3; ++m) {
          CHECK(std::abs(q[m].norm() - 1.0) < 1e-12);
          CHECK((H * q[m] - lam_k[m] * q[m]).norm() <= 1e-10 * scale);
        }
      }
      std::sort(analytic.data(), analytic.data() + 9);
      const Eigen::SelfAdjointEigenSolver<Mat9> numerical(H);
      CHECK((analytic - numerical.eigenvalues()).norm() <= 1e-10 * scale);
    }
  }
}

TEST(snh_closed_form_projection_matches_the_numerical_one) {
  for (EigenFilter filter : {EigenFilter::Clamp, EigenFilter::Abs}) {
    int projected = 0;
    for (const Mat3& F : eigensystem_cases()) {
      const Mat9 H = snh::hessian(F, mu, lam);
      const Mat9 closed = snh::hessian_psd(F, mu, lam, filter);
      const Mat9 numerical = psd_project<9>(H, filter);
      CHECK((closed - numerical).norm() <= 1e-10 * H.norm());
      CHECK((closed - closed.transpose()).norm() <= 1e-12 * H.norm());
      const Eigen::SelfAdjointEigenSolver<Mat9> es(closed);
      CHECK(es.eigenvalues().minCoeff() >= -1e-10 * H.norm());
      const Eigen::SelfAdjointEigenSolver<Mat9> e0(H);
      if (e0.eigenvalues().minCoeff() > 1e-9 * H.norm()) CHECK((closed - H).norm() == 0.0);  // PD: unchanged
      else ++projected;
    }
    CHECK(projected >= 10);  // the cases do exercise the projection
  }
}

TEST(material_hessians_match_the_single_versions) {
  const TetMaterial m{mu, lam, 3e4, Vec3(0.2, 0.3, -0.9).normalized()};
  for (int k = 0; k < 10; ++k) {
    const Mat3 F = random_F(0.4);
    Mat9 psd, exact;
    material_hessians(m, F, EigenFilter::Clamp, &psd, &exact);
    CHECK((psd - material_hessian_psd(m, F)).norm() == 0.0);
    CHECK((exact - material_hessian(m, F)).norm() == 0.0);
    const Mat9 Hfd = fd_hessian(F, [&](const Mat3& G) { return material_stress(m, G); });
    CHECK((exact - Hfd).norm() <= 1e-6 * (1.0 + exact.norm()));
  }
}

TEST(position_hessian_matches_finite_differences_and_the_dense_product) {
  // E(x) = W(F(x)), F = sum_a x_a b_a^T: its 12x12 Hessian in the corner
  // positions against central differences of its gradient corner_vectors(b,
  // P(F(x))), and against the dense product G^T H G with dF = G dx.
  std::normal_distribution<double> n(0.0, 1.0);
  for (int k = 0; k < 10; ++k) {
    ShapeGrads b;
    for (int i = 0; i < 12; ++i) b.data()[i] = n(rng);
    Vec12 x;
    for (int i = 0; i < 12; ++i) x(i) = 0.3 * n(rng) + (i % 3 == i / 3 % 3 ? 1.0 : 0.0);
    auto F_of = [&](const Vec12& y) {
      Mat3 F = Mat3::Zero();
      for (int a = 0; a < 4; ++a) F += y.segment<3>(3 * a) * b.row(a);
      return F;
    };
    const Mat12 K = position_hessian(b, snh::hessian(F_of(x), mu, lam));
    const double h = 1e-6;
    Mat12 Kfd;
    for (int j = 0; j < 12; ++j) {
      Vec12 p = x, m = x;
      p(j) += h, m(j) -= h;
      Kfd.col(j) = (corner_vectors(b, snh::stress(F_of(p), mu, lam)) - corner_vectors(b, snh::stress(F_of(m), mu, lam))) /
                   (2 * h);
    }
    CHECK((K - Kfd).norm() <= 1e-5 * K.norm());
    Mat9 A = Mat9::Zero();
    for (int i = 0; i < 81; ++i) A.data()[i] = n(rng);
    const Mat9 H = A + A.transpose();
    Eigen::Matrix<double, 9, 12> G = Eigen::Matrix<double, 9, 12>::Zero();
    for (int a = 0; a < 4; ++a)
      for (int kk = 0; kk < 3; ++kk)
        for (int i = 0; i < 3; ++i) G(i + 3 * kk, 3 * a + i) = b(a, kk);
    const Mat12 Kh = position_hessian(b, H);
    CHECK((Kh - G.transpose() * H * G).norm() <= 1e-13 * (G.transpose() * H * G).norm());
    CHECK((Kh - Kh.transpose()).norm() <= 1e-13 * Kh.norm());
  }
}

TEST(acap_coupling_derivatives_match_finite_differences) {
  const double alpha = 3e5, wv = 0.7;
  std::normal_distribution<double> n(0.0, 0.3);
  for (int k = 0; k < 10; ++k) {
    Vec9 f, fx;
    for (int i = 0; i < 9; ++i) f(i) = n(rng), fx(i) = n(rng);
    const Vec9 g = acap_coupling::gradient(f, fx, alpha, wv);
    const double h = 1e-6;
    Vec9 gfd, gxfd;
    Mat9 Hfd;
    for (int i = 0; i < 9; ++i) {
      Vec9 a = f, b = f, ax = fx, bx = fx;
      a(i) += h, b(i) -= h, ax(i) += h, bx(i) -= h;
      gfd(i) = (acap_coupling::energy(a, fx, alpha, wv) - acap_coupling::energy(b, fx, alpha, wv)) / (2 * h);
      gxfd(i) = (acap_coupling::energy(f, ax, alpha, wv) - acap_coupling::energy(f, bx, alpha, wv)) / (2 * h);
      Hfd.col(i) = (acap_coupling::gradient(a, fx, alpha, wv) - acap_coupling::gradient(b, fx, alpha, wv)) / (2 * h);
    }
    CHECK((g - gfd).norm() <= 1e-6 * (1 + g.norm()));
    CHECK((-g - gxfd).norm() <= 1e-6 * (1 + g.norm()));  // dE/dfx = -dE/df
    CHECK((Hfd - acap_coupling::hessian_diagonal(alpha, wv) * Mat9::Identity()).norm() <= 1e-6 * alpha * wv);
  }
  CHECK(acap_coupling::energy(Vec9::Ones(), Vec9::Ones(), alpha, wv) == 0.0);
}

TEST(gravity_work_derivatives_match_finite_differences) {
  const int n = 5;
  Eigen::VectorXd mass(n);
  mass << 1.0, 0.5, 2.0, 0.25, 3.0;
  const Vec3 g(0.1, -9.81, 0.3);
  std::normal_distribution<double> nd(0.0, 1.0);
  Eigen::MatrixX3d x(n, 3);
  for (int i = 0; i < 3 * n; ++i) x.data()[i] = nd(rng);
  const double h = 1e-5;
  double err = 0;
  for (int v = 0; v < n; ++v)
    for (int c = 0; c < 3; ++c) {
      Eigen::MatrixX3d a = x, b = x;
      a(v, c) += h, b(v, c) -= h;
      const double fd = (gravity_work::energy(mass, a, g) - gravity_work::energy(mass, b, g)) / (2 * h);
      err = std::max(err, std::abs(fd - gravity_work::vertex_gradient(mass(v), g)(c)));
    }
  CHECK(err <= 1e-8);
  // linear: the work of a sum is the sum of the works (zero Hessian)
  const Eigen::MatrixX3d y = 2.0 * x;
  CHECK_CLOSE(gravity_work::energy(mass, x + y, g), gravity_work::energy(mass, x, g) + gravity_work::energy(mass, y, g),
              1e-10 * (1 + std::abs(gravity_work::energy(mass, x, g))));
}

TEST(joint_spring_derivatives_match_finite_differences) {
  const double k = 2.5;
  for (int trial = 0; trial < 10; ++trial) {
    const Mat3 R = nearest_rotation(random_F(0.8));
    // Euclidean gradient in R
    const Mat3 G = fd_stress(R, [&](const Mat3& M) { return joint_spring::energy(M, k); });
    CHECK((G - joint_spring::gradient(k)).norm() <= 1e-7);
    // exponential-map coordinates R(w) = exp([w]_x) R at w = 0
    auto E = [&](const Vec3& w) { return joint_spring::energy(rotation_exp(w) * R, k); };
    const double h = 1e-4;
    Vec3 gfd;
    Mat3 Hfd;
    for (int i = 0; i < 3; ++i) {
      const Vec3 ei = h * Vec3::Unit(i);
      gfd(i) = (E(ei) - E(-ei)) / (2 * h);
      for (int j = 0; j < 3; ++j) {
        const Vec3 ej = h * Vec3::Unit(j);
        Hfd(i, j) = (E(ei + ej) - E(ei - ej) - E(ej - ei) + E(-ei - ej)) / (4 * h * h);
      }
    }
    CHECK((gfd - joint_spring::expmap_gradient(R, k)).norm() <= 1e-7 * k);
    CHECK((Hfd - joint_spring::expmap_hessian(R, k)).norm() <= 1e-5 * k);
  }
  CHECK_CLOSE(joint_spring::energy(Mat3::Identity(), k), 0.0, 1e-15);
  // k (1 - cos theta)
  CHECK_CLOSE(joint_spring::energy(rotation_exp(Vec3(0, 0, 0.6)), k), k * (1 - std::cos(0.6)), 1e-14);
}

TEST(rotation_helpers) {
  const Vec3 w(0.3, -0.5, 0.2);
  const Mat3 R = rotation_exp(w);
  CHECK((R.transpose() * R - Mat3::Identity()).norm() <= 1e-14);
  CHECK_CLOSE(R.determinant(), 1.0, 1e-14);
  CHECK((R - Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix()).norm() <= 1e-14);
  CHECK((nearest_rotation(1.7 * R) - R).norm() <= 1e-13);
  Eigen::MatrixX3d X(5, 3);
  X << 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 3, 1, 1, 1;
  const Eigen::MatrixX3d Y = (X * R.transpose()).rowwise() + Eigen::RowVector3d(1, 2, 3);
  CHECK((best_rotation(X, Y) - R).norm() <= 1e-12);
  const Vec3 a = Vec3(1, 2, 0).normalized(), b = Vec3(0, -1, 3).normalized();
  CHECK((rotation_between(a, b) * a - b).norm() <= 1e-14);
  CHECK((rotation_between(a, -a) * a + a).norm() <= 1e-14);
  const Mat3 T = project_to_tangent(R, random_F(1.0));
  const Mat3 K = R.transpose() * T;
  CHECK((K + K.transpose()).norm() <= 1e-13);  // R^T T is skew
}

TEST_MAIN()
