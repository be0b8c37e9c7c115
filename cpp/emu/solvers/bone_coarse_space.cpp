#include "emu/solvers/bone_coarse_space.h"

#include <algorithm>
#include <limits>

#include <Eigen/Eigenvalues>

namespace emu {

BoneCoarseSpace::BoneCoarseSpace(const UnknownLayout& layout, double alpha) : layout_(layout), alpha_(alpha) {}

void BoneCoarseSpace::build(const Mat9X& F, const Follow& follow, const Product& product,
                            const std::vector<Mat9X>& extra) {
  const int nb = layout_.num_bones, nu = layout_.num_unknowns, nz = 3 * nb + static_cast<int>(extra.size());
  Z_.assign(nz, Mat9X::Zero(9, nu));
  HZ_.resize(nz);
  for (int b = 0; b < nb; ++b)
    for (int k = 0; k < 3; ++k) {
      Mat9X& Z = Z_[3 * b + k];
      const int ub = layout_.num_soft + b;
      Mat3 W = Mat3::Zero();  // [e_k]_x
      W((k + 2) % 3, (k + 1) % 3) = 1.0;
      W((k + 1) % 3, (k + 2) % 3) = -1.0;
      Z.col(ub) = flatten(Mat3(W * unflatten(F.col(ub))));
      follow(Z);
    }
  for (size_t e = 0; e < extra.size(); ++e) Z_[3 * nb + e] = extra[e];
  Eigen::MatrixXd E(nz, nz);
  for (int j = 0; j < nz; ++j) {
    product(Z_[j], HZ_[j]);
    for (int i = 0; i < nz; ++i) E(i, j) = dot(Z_[i], HZ_[j]);
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

}  // namespace emu
