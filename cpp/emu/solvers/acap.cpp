#include "emu/solvers/acap.h"

#include <stdexcept>

namespace emu {

void deformation_gradients(const Discretization& disc, const Eigen::MatrixX4i& T,
                           const Eigen::MatrixX3d& x, Mat9X& out) {
  const Eigen::Index m = T.rows();
  out.resize(9, m);
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) out.col(t) = flatten(deformation_gradient(disc.geometry.grad[t], x, T, t));
}

AcapOperator::AcapOperator(const Model& model, const Discretization& disc)
    : model_(model), disc_(disc), pattern_(model.tets, disc.free_index, disc.num_free, 1) {
  const Eigen::Index m = model.tets.rows();
  wv_ = model.acap_weight.cwiseProduct(disc.geometry.volume);
  std::vector<double> element(m * 16);
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    const ShapeGrads& b = disc.geometry.grad[t];
    Eigen::Map<Eigen::Matrix4d>(element.data() + t * 16) = wv_(t) * b * b.transpose();
  }
  std::vector<double> values(pattern_.nnz());
  pattern_.assemble(element.data(), values.data());
  factor_.analyze(pattern_.rows(), pattern_.col_ptr().data(), pattern_.row_index().data());
  if (!factor_.factorize(values.data()))
    throw std::invalid_argument(
        "the ACAP matrix is singular: some part of the mesh is not connected to a pinned vertex "
        "or fixed bone; pin a vertex of every connected component");
  corner_.resize(m * 12);
  rhs_rows_.resize(disc.num_free, 3);
  rhs_.resize(disc.num_free, 3);
  sol_.resize(disc.num_free, 3);
}

namespace {
template <class TargetOf>
void corner_targets(const Eigen::VectorXd& wv, const Discretization& disc, TargetOf&& target, double* corner) {
  const Eigen::Index m = wv.size();
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    const Mat3 T = target(t);
    const ShapeGrads& b = disc.geometry.grad[t];
    for (int a = 0; a < 4; ++a) Eigen::Map<Vec3>(corner + t * 12 + 3 * a) = wv(t) * T * b.row(a).transpose();
  }
}
}  // namespace

void AcapOperator::fit(const Mat9X& F, const Mat9X* F_pinned, Eigen::MatrixX3d& x) const {
  // Normal equations over the free vertices a:
  //   sum_b L_ab x_b = sum_t w_t V_t (F_t - F_t(x_pinned)) b_a
  corner_targets(wv_, disc_, [&](Eigen::Index t) {
    Mat3 T = unflatten(F.col(t));
    if (F_pinned) T -= unflatten(F_pinned->col(t));
    return T;
  }, corner_.data());
  pattern_.gather(corner_.data(), 3, rhs_rows_.data());
  rhs_ = rhs_rows_;
  solve(rhs_, sol_);
  scatter_free(sol_, x);
}

void AcapOperator::apply_C(const Mat9X& D, Eigen::MatrixX3d& y) const {
  corner_targets(wv_, disc_, [&](Eigen::Index t) { return Mat3(unflatten(D.col(t))); }, corner_.data());
  pattern_.gather(corner_.data(), 3, rhs_rows_.data());
  y = rhs_rows_;
}

void AcapOperator::apply_CT(const Eigen::MatrixX3d& u, Mat9X& out) const {
  const Eigen::Index m = model_.tets.rows();
  out.resize(9, m);
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    const ShapeGrads& b = disc_.geometry.grad[t];
    Mat3 F = Mat3::Zero();
    for (int a = 0; a < 4; ++a) {
      const int v = disc_.free_index(model_.tets(t, a));
      if (v >= 0) F.noalias() += u.row(v).transpose() * b.row(a);
    }
    out.col(t) = wv_(t) * flatten(F);
  }
}

void AcapOperator::scatter_free(const Eigen::MatrixX3d& y, Eigen::MatrixX3d& x) const {
  for (Eigen::Index v = 0; v < x.rows(); ++v)
    if (disc_.free_index(v) >= 0) x.row(v) = y.row(disc_.free_index(v));
}

}  // namespace emu
