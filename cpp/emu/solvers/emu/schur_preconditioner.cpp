#include "emu/solvers/emu/schur_preconditioner.h"

#include "emu/linalg/spd_inverse.h"

namespace emu {

SchurPreconditioner::SchurPreconditioner(const Model& model, const UnknownLayout& layout, const AcapOperator& acap,
                                         double alpha)
    : model_(model),
      layout_(layout),
      acap_(acap),
      alpha_(alpha),
      pattern_(model.tets, layout.free_index, layout.num_free, 3),
      Ainv_(model.tets.rows()),
      element_(model.tets.rows() * 144),
      values_(pattern_.nnz()) {
  factor_.analyze(pattern_.rows(), pattern_.col_ptr().data(), pattern_.row_index().data());
}

bool SchurPreconditioner::update(const std::vector<Mat9>& A) {
  const Eigen::VectorXd& wv = acap_.weight_volume();
  const long m = static_cast<long>(A.size());
#pragma omp parallel for schedule(static)
  for (long t = 0; t < m; ++t) {
    if (!spd_inverse<9>(A[t], Ainv_[t]))  // filtered blocks are definite: only non-finite ones get here
        Ainv_[t] = Eigen::LLT<Mat9>(A[t]).solve(Mat9::Identity());
    // w V (I - alpha w V A^-1), symmetrised against roundoff
    Mat9 M = -alpha_ * wv(t) * wv(t) * Ainv_[t];
    M.diagonal().array() += wv(t);
    M = (0.5 * (M + M.transpose())).eval();
    Eigen::Map<Mat12>(element_.data() + t * 144) = position_hessian(layout_.geometry.grad[t], M);
  }
  pattern_.assemble(element_.data(), values_.data());
  ok_ = factor_.factorize(values_.data());
  return ok_;
}

void SchurPreconditioner::apply(const Mat9X& r, Mat9X& out) const {
  apply_schur_form(layout_, acap_, Ainv_, alpha_, r, out, work_,
                   [&](const Eigen::MatrixX3d& y, Eigen::MatrixX3d& u) {
                     // the position unknowns are interleaved (3 v + c), as in the assembled S
                     Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> b = y, ui(y.rows(), 3);
                     factor_.solve(b.data(), ui.data(), 1);
                     u = ui;
                   },
                   !ok_);
}

}  // namespace emu
