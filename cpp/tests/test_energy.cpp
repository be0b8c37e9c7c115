// Element kernels against central finite differences and invariants.
#include <random>

#include "check.h"
#include "emu/energy/fiber.h"
#include "emu/energy/psd_project.h"
#include "emu/energy/stable_neo_hookean.h"

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

TEST(snh_stress_matches_finite_differences) {
  for (int k = 0; k < 20; ++k) {
    Mat3 F = random_F(0.3);
    if (k % 4 == 0) F.col(0) *= -1;  // inverted
    const Mat3 P = snh::stress(F, mu, lam);
    const Mat3 Pfd = fd_stress(F, [](const Mat3& G) { return snh::energy(G, mu, lam); });
    CHECK((P - Pfd).norm() <= 1e-5 * (1.0 + P.norm()));
  }
}

TEST(snh_hessian_matches_finite_differences) {
  for (int k = 0; k < 20; ++k) {
    Mat3 F = random_F(0.3);
    if (k % 4 == 0) F.col(1) *= -1;
    const Mat9 H = snh::hessian(F, mu, lam);
    const Mat9 Hfd = fd_hessian(F, [](const Mat3& G) { return snh::stress(G, mu, lam); });
    CHECK((H - Hfd).norm() <= 1e-6 * (1.0 + H.norm()));
    CHECK((H - H.transpose()).norm() <= 1e-12 * H.norm());
  }
}

TEST(snh_zero_energy_and_stress_at_rest_and_under_rotation) {
  CHECK_CLOSE(snh::energy(Mat3::Identity(), mu, lam), 0.0, 1e-9 * lam);
  CHECK(snh::stress(Mat3::Identity(), mu, lam).norm() <= 1e-10 * lam);
  const Mat3 R = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  CHECK_CLOSE(snh::energy(R, mu, lam), 0.0, 1e-9 * lam);
  CHECK(snh::stress(R, mu, lam).norm() <= 1e-9 * lam);
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

TEST_MAIN()
