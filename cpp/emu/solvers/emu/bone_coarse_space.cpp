#include "emu/solvers/emu/bone_coarse_space.h"

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <utility>

#include <Eigen/Eigenvalues>

namespace emu {

BoneCoarseSpace::BoneCoarseSpace(const UnknownLayout& layout, double alpha, std::vector<const Mat9X*> follow)
    : layout_(layout), alpha_(alpha), follow_(std::move(follow)) {}

void BoneCoarseSpace::build(const Mat9X& F, const Turn& turn, const Product& product,
                            const std::vector<Mat9X>& extra, const Eigen::MatrixXd* turn_map) {
  const int nb = layout_.num_bones, nz = 3 * nb + static_cast<int>(extra.size());
  if (static_cast<int>(follow_.size()) != nb)
    throw std::logic_error("BoneCoarseSpace: one follow field per movable bone expected");
  std::vector<Mat9X> Z(nz), HZ(nz);
  turn_.resize(3 * nb);
  for (int b = 0; b < nb; ++b) {
    std::array<Mat3, 3> M;
    for (int k = 0; k < 3; ++k) M[k] = turn_[3 * b + k] = cross_matrix(Vec3::Unit(k)) * unflatten(F.col(layout_.num_soft + b));
    std::array<Mat9X, 3> Zb, HZb;
    turn(b, M, Zb, HZb);
    for (int k = 0; k < 3; ++k) {
      Z[3 * b + k] = std::move(Zb[k]);
      HZ[3 * b + k] = std::move(HZb[k]);
    }
  }
  for (size_t e = 0; e < extra.size(); ++e) {
    Z[3 * nb + e] = extra[e];
    product(Z[3 * nb + e], HZ[3 * nb + e]);
  }
  // the coarse coordinates: the bones' turns (or the turn map's combinations
  // of them), then the extra directions, Zc = Z Tc
  const int nt = turn_map ? static_cast<int>(turn_map->cols()) : 3 * nb, nc = nt + nz - 3 * nb;
  Tc_ = Eigen::MatrixXd::Zero(nz, nc);
  if (turn_map) Tc_.topLeftCorner(3 * nb, nt) = *turn_map;
  else Tc_.topLeftCorner(3 * nb, nt).setIdentity();
  Tc_.bottomRightCorner(nz - 3 * nb, nc - nt).setIdentity();
  invert_coarse_matrix(coarse_products(Z, HZ));
  built_ = true;
}

// H Zc is kept (an application streams nc columns, not nz); E = Z^T H Z and
// H Zc come from one pass over the entries, chunk by chunk (each chunk's rows
// of Z and H Z gathered once, then small products): the same bits for any
// number of threads. Returns Ec = Zc^T H Zc.
Eigen::MatrixXd BoneCoarseSpace::coarse_products(const std::vector<Mat9X>& Z, const std::vector<Mat9X>& HZ) {
  const int nz = static_cast<int>(Z.size()), nx = nz - 3 * layout_.num_bones;
  const Eigen::Index entries = 9 * static_cast<Eigen::Index>(layout_.num_unknowns);
  HZ_.resize(entries, Tc_.cols());
  Zx_.resize(entries, nx);  // the extra directions; the turns are M_bk Phi_b
  Eigen::VectorXd e;
  Eigen::MatrixXd parts;
  chunked_sum_into(
      entries, static_cast<Eigen::Index>(nz) * nz,
      [&](Eigen::Index lo, Eigen::Index hi, auto& part) {
        const Eigen::Index n = hi - lo;
        Eigen::MatrixXd Zr(n, nz), HZr(n, nz);
        for (int i = 0; i < nz; ++i) {
          Zr.col(i) = flat(Z[i]).segment(lo, n);
          HZr.col(i) = flat(HZ[i]).segment(lo, n);
        }
        Eigen::Map<Eigen::MatrixXd>(part.data(), nz, nz).noalias() = Zr.transpose() * HZr;
        HZ_.middleRows(lo, n).noalias() = HZr * Tc_;
        Zx_.middleRows(lo, n) = Zr.rightCols(nx);
      },
      parts, e);
  return Tc_.transpose() * Eigen::Map<const Eigen::MatrixXd>(e.data(), nz, nz) * Tc_;
}

// inv_: the pseudo-inverse of Ec's positive part. A direction of zero
// curvature, against the curvature 2 alpha sum_t V_t of turning the smallest
// bone's volume against an ACAP term of weight 1, is a neutral mode (reported
// by bone and axis); any eigenvalue not clearly positive makes the form additive.
void BoneCoarseSpace::invert_coarse_matrix(const Eigen::MatrixXd& Ec) {
  const int nb = layout_.num_bones, nu = layout_.num_unknowns, nc = static_cast<int>(Ec.rows());
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (Ec + Ec.transpose()));
  double scale = std::numeric_limits<double>::infinity();
  for (int u = layout_.num_soft; u < nu; ++u) {
    double vol = 0;
    for (int i = layout_.unknown_ptr[u]; i < layout_.unknown_ptr[u + 1]; ++i)
      vol += layout_.geometry.volume(layout_.unknown_tets[i]);
    scale = std::min(scale, 2.0 * alpha_ * vol);
  }
  inv_ = Eigen::MatrixXd::Zero(nc, nc);
  neutral_.clear();
  balancing_ = true;
  for (int i = 0; i < nc; ++i) {
    const Eigen::VectorXd vc = es.eigenvectors().col(i);
    if (es.eigenvalues()(i) > 1e-9 * scale) {
      inv_ += vc * vc.transpose() / es.eigenvalues()(i);
      continue;
    }
    balancing_ = false;
    if (es.eigenvalues()(i) < -1e-9 * scale) continue;  // negative curvature: not a neutral mode
    const Eigen::VectorXd v = Tc_ * vc;  // as the bones' world turns
    if (v.head(3 * nb).norm() < 0.5 * v.norm()) continue;  // mostly a recycled direction: not a bone's mode
    int best = 0;
    for (int b = 1; b < nb; ++b)
      if (v.segment<3>(3 * b).norm() > v.segment<3>(3 * best).norm()) best = b;
    neutral_.push_back({best, v.segment<3>(3 * best).normalized()});
  }
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

void BoneCoarseSpace::project_Z(const Mat9X& v, Eigen::VectorXd& c) const {
  const int nb = layout_.num_bones, ns = layout_.num_soft, nx = static_cast<int>(Zx_.cols());
  Eigen::VectorXd sums;
  // sums: G_b column-major in 9 b .. 9 b + 8, then the recycled columns' dots
  chunked_sum_into(
      layout_.num_unknowns, 9 * nb + nx,
      [&](Eigen::Index lo, Eigen::Index hi, auto& part) {
        part.setZero();
        for (Eigen::Index u = lo; u < hi; ++u) {
          const double* r = v.col(u).data();  // R(i, l) = r[i + 3 l]
          if (u < ns) {
            for (int b = 0; b < nb; ++b) {  // G_b += R Phi^T: G(i, j) = sum_l R(i, l) Phi(j, l)
              const double* f = follow_[b]->col(u).data();
              for (int j = 0; j < 3; ++j)
                for (int i = 0; i < 3; ++i)
                  part(9 * b + i + 3 * j) += r[i] * f[j] + r[i + 3] * f[j + 3] + r[i + 6] * f[j + 6];
            }
          } else {  // bone b's own unknown: Phi = I
            const int b = static_cast<int>(u - ns);
            for (int q = 0; q < 9; ++q) part(9 * b + q) += r[q];
          }
          for (int e = 0; e < nx; ++e) part(9 * nb + e) += Zx_.col(e).segment<9>(9 * u).dot(Eigen::Map<const Vec9>(r));
        }
      },
      parts_z_, sums);
  c.resize(3 * nb + nx);
  for (int b = 0; b < nb; ++b)
    for (int k = 0; k < 3; ++k)
      c(3 * b + k) = (turn_[3 * b + k].array() * Eigen::Map<const Mat3>(sums.data() + 9 * b).array()).sum();
  c.tail(nx) = sums.tail(nx);
}

void BoneCoarseSpace::combine_Z(const Mat9X& a, double s, const Eigen::VectorXd& c, Mat9X& out) const {
  const int nb = layout_.num_bones, ns = layout_.num_soft, nu = layout_.num_unknowns;
  const int nx = static_cast<int>(Zx_.cols());
  if (&out != &a) out.resize(a.rows(), a.cols());
  combined_.resize(nb);
  for (int b = 0; b < nb; ++b) {  // N_b = s sum_k c_bk M_bk
    combined_[b].setZero();
    for (int k = 0; k < 3; ++k) combined_[b] += c(3 * b + k) * turn_[3 * b + k];
    combined_[b] *= s;
  }
#pragma omp parallel for schedule(static)
  for (int u = 0; u < nu; ++u) {
    Vec9 add = Vec9::Zero();
    if (u < ns) {
      // follow's column read in place (a copy through the stack stalls the loads)
      for (int b = 0; b < nb; ++b) add += flatten(Mat3(combined_[b] * Eigen::Map<const Mat3>(follow_[b]->col(u).data())));
    } else {
      add = flatten(combined_[u - ns]);
    }
    for (int e = 0; e < nx; ++e) add += (s * c(3 * nb + e)) * Zx_.col(e).segment<9>(9 * static_cast<Eigen::Index>(u));
    out.col(u) = a.col(u) + add;
  }
}

}  // namespace emu
