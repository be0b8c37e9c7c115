#include "emu/solvers/constant_schur.h"

#include <algorithm>
#include <cmath>

namespace emu {

Eigen::VectorXd ConstantSchur::weights(const Model& model, const UnknownLayout& layout, const Eigen::VectorXd& wv,
                                       double alpha) {
  const Eigen::Index m = model.tets.rows();
  Eigen::VectorXd e(m);
  for (Eigen::Index t = 0; t < m; ++t) {
    if (layout.is_bone_tet(t)) {  // infinitely stiff: the limit h -> infinity
      e(t) = wv(t);
      continue;
    }
    const double h = model.mu(t) + model.lambda(t) / 3.0;
    e(t) = wv(t) * h / (h + alpha * model.acap_weight(t));
  }
  return e;
}

ConstantSchur::ConstantSchur(const Model& model, const UnknownLayout& layout, const AcapOperator& acap,
                             double alpha)
    : model_(model), layout_(layout), acap_(acap), alpha_(-1.0), Ainv_(layout.num_unknowns) {
  set_alpha(alpha);
}

void ConstantSchur::set_alpha(double alpha) {
  if (alpha == alpha_ && s0_) return;
  alpha_ = alpha;
  const Eigen::VectorXd e = weights(model_, layout_, acap_.weight_volume(), alpha);
  s0_ = std::make_unique<AcapOperator>(model_, layout_, &e, &acap_);  // the ACAP matrix's pattern
}

bool ConstantSchur::update(const std::vector<Mat9>& A) {
  const long n = static_cast<long>(A.size());
  int bad = 0;
#pragma omp parallel for schedule(static) reduction(+ : bad)
  for (long u = 0; u < n; ++u) {
    const Eigen::LLT<Mat9> llt(A[u]);
    if (llt.info() != Eigen::Success) {
      ++bad;
      Ainv_[u].setZero();
    } else {
      Ainv_[u] = llt.solve(Mat9::Identity());
    }
  }
  ok_ = bad == 0;
  return ok_;
}

void ConstantSchur::apply(const Mat9X& r, Mat9X& out) const {
  if (!ok_) {
    out = r;
    return;
  }
  const long n = r.cols();
  out.resize(9, n);
#pragma omp parallel for schedule(static)
  for (long u = 0; u < n; ++u) out.col(u).noalias() = Ainv_[u] * r.col(u);
  // + alpha A^-1 C^T S0^-1 C (A^-1 r): C with the ACAP weights, S0 with its own
  Mat9X per_tet;
  Eigen::MatrixX3d y;
  acap_.apply_C(per_tet_view(layout_, out, per_tet), y);
  Eigen::MatrixXd z;
  s0_->solve(Eigen::MatrixXd(y), z);
  acap_.apply_CT(Eigen::MatrixX3d(z), per_tet);
  Mat9X ct;
  reduce_to_unknowns(layout_, per_tet, ct);
#pragma omp parallel for schedule(static)
  for (long u = 0; u < n; ++u) out.col(u).noalias() += alpha_ * (Ainv_[u] * ct.col(u));
}

}  // namespace emu
