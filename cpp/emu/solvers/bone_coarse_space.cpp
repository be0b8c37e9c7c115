#include "emu/solvers/bone_coarse_space.h"

#include <algorithm>
#include <limits>

#include <Eigen/Eigenvalues>

namespace emu {

BoneCoarseSpace::BoneCoarseSpace(const UnknownLayout& layout, double alpha) : layout_(layout), alpha_(alpha) {}

void BoneCoarseSpace::build(const Mat9X& F, const Turn& turn, const Product& product,
                            const std::vector<Mat9X>& extra) {
  const int nb = layout_.num_bones, nu = layout_.num_unknowns, nz = 3 * nb + static_cast<int>(extra.size());
  std::vector<Mat9X> Z(nz), HZ(nz);
  for (int b = 0; b < nb; ++b)
    for (int k = 0; k < 3; ++k) {
      Mat3 W = Mat3::Zero();  // [e_k]_x
      W((k + 2) % 3, (k + 1) % 3) = 1.0;
      W((k + 1) % 3, (k + 2) % 3) = -1.0;
      turn(b, Mat3(W * unflatten(F.col(layout_.num_soft + b))), Z[3 * b + k], HZ[3 * b + k]);
    }
  for (size_t e = 0; e < extra.size(); ++e) {
    Z[3 * nb + e] = extra[e];
    product(Z[3 * nb + e], HZ[3 * nb + e]);
  }
  Eigen::MatrixXd E(nz, nz);
  for (int j = 0; j < nz; ++j)
    for (int i = 0; i < nz; ++i) E(i, j) = dot(Z[i], HZ[j]);
  const Eigen::Index entries = 9 * static_cast<Eigen::Index>(nu);
  Z_.resize(entries, nz);
  HZ_.resize(entries, nz);
  for (int j = 0; j < nz; ++j) {
    Z_.col(j) = flat(Z[j]);
    HZ_.col(j) = flat(HZ[j]);
  }
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (E + E.transpose()));
  double scale = std::numeric_limits<double>::infinity();
  for (int u = layout_.num_soft; u < nu; ++u) {
    double vol = 0;
    for (int i = layout_.unknown_ptr[u]; i < layout_.unknown_ptr[u + 1]; ++i)
      vol += layout_.geometry.volume(layout_.unknown_tets[i]);
    scale = std::min(scale, 2.0 * alpha_ * vol);
  }
  inv_.setZero(nz, nz);
  neutral_.clear();
  balancing_ = true;
  for (int i = 0; i < nz; ++i) {
    const Eigen::VectorXd v = es.eigenvectors().col(i);
    if (es.eigenvalues()(i) > 1e-9 * scale) {
      inv_ += v * v.transpose() / es.eigenvalues()(i);
      continue;
    }
    balancing_ = false;
    if (es.eigenvalues()(i) < -1e-9 * scale) continue;  // negative curvature: not a neutral mode
    if (v.head(3 * nb).norm() < 0.5) continue;            // mostly a recycled direction: not a bone's mode
    int best = 0;
    for (int b = 1; b < nb; ++b)
      if (v.segment<3>(3 * b).norm() > v.segment<3>(3 * best).norm()) best = b;
    neutral_.push_back({best, v.segment<3>(3 * best).normalized()});
  }
  built_ = true;
}

void BoneCoarseSpace::project(const Eigen::MatrixXd& M, const Mat9X& v, Eigen::VectorXd& c) const {
  const Flat x = flat(v);
  chunked_sum_into(
      M.rows(), M.cols(),
      [&](Eigen::Index lo, Eigen::Index hi, auto& part) {
        part.noalias() = M.middleRows(lo, hi - lo).transpose() * x.segment(lo, hi - lo);
      },
      parts_, c);
}

void BoneCoarseSpace::combine(const Mat9X& a, double s, const Eigen::MatrixXd& M, const Eigen::VectorXd& c,
                              Mat9X& out) {
  if (&out != &a) out.resize(a.rows(), a.cols());
  const Eigen::Index n = M.rows();
  const Flat x = flat(a);
  auto y = flat(out);
#pragma omp parallel for schedule(static)
  for (int k = 0; k < kSumChunks; ++k) {
    const Eigen::Index lo = n * k / kSumChunks, hi = n * (k + 1) / kSumChunks;
    if (&out != &a) y.segment(lo, hi - lo) = x.segment(lo, hi - lo);
    y.segment(lo, hi - lo).noalias() += s * (M.middleRows(lo, hi - lo) * c);
  }
}

}  // namespace emu
