#include "emu/solvers/woodbury.h"

#include <algorithm>

extern "C" void dsyrk_(const char* uplo, const char* trans, const int* n, const int* k, const double* alpha,
                       const double* a, const int* lda, const double* beta, double* c, const int* ldc);

namespace emu {

Woodbury::Woodbury(const Model& model, const Discretization& disc, const Modes& modes,
                   const Eigen::VectorXd& wv, double alpha)
    : ks_(static_cast<int>(modes.values.size())), alpha_(alpha), values_(modes.values), wv_(wv) {
  const Eigen::Index m = model.tets.rows();
  mode_grad_.setZero(3 * ks_, m);
  if (ks_ > 0) {
#pragma omp parallel for schedule(static)
    for (Eigen::Index t = 0; t < m; ++t) {
      const ShapeGrads& b = disc.geometry.grad[t];
      for (int a = 0; a < 4; ++a) {
        const int v = disc.free_index(model.tets(t, a));
        if (v < 0) continue;
        for (int l = 0; l < ks_; ++l) mode_grad_.block<3, 1>(3 * l, t) += modes.vectors(v, l) * b.row(a).transpose();
      }
    }
  }
  L_.resize(m);
}

bool Woodbury::update(const std::vector<Mat9>& A) {
  const long m = static_cast<long>(A.size());
#pragma omp parallel for schedule(static)
  for (long t = 0; t < m; ++t) L_[t] = Eigen::LLT<Mat9>(A[t]).matrixL();
  x_ok_ = false;
  if (ks_ == 0) return true;
  const int k = 3 * ks_;
  // X = Lambda/alpha - sum_t M_t M_t^T with M_t = B_t L_t^-T, accumulated by SYRK
  // over chunks of tets (rows of the chunk buffer: 9 per tet; columns: modes).
  Eigen::MatrixXd X = Eigen::MatrixXd::Zero(k, k);
  for (int l = 0; l < ks_; ++l)
    for (int c = 0; c < 3; ++c) X(c + 3 * l, c + 3 * l) = values_(l) / alpha_;
  const long chunk = 4096;
  Eigen::MatrixXd buf(9 * chunk, k);
  for (long t0 = 0; t0 < m; t0 += chunk) {
    const long nt = std::min(chunk, m - t0);
#pragma omp parallel for schedule(static)
    for (long i = 0; i < nt; ++i) {
      const long t = t0 + i;
      Eigen::Matrix<double, 9, Eigen::Dynamic> BT = Eigen::Matrix<double, 9, Eigen::Dynamic>::Zero(9, k);
      for (int l = 0; l < ks_; ++l)
        for (int c = 0; c < 3; ++c)
          for (int j = 0; j < 3; ++j) BT(c + 3 * j, c + 3 * l) = wv_(t) * mode_grad_(3 * l + j, t);
      L_[t].triangularView<Eigen::Lower>().solveInPlace(BT);  // L^-1 B^T = M_t^T
      buf.block(9 * i, 0, 9, k) = BT;
    }
    const int n = k, kk = static_cast<int>(9 * nt), lda = static_cast<int>(9 * chunk), ldc = k;
    const double one = 1.0, minus_one = -1.0;
    dsyrk_("L", "T", &n, &kk, &minus_one, buf.data(), &lda, &one, X.data(), &ldc);
  }
  X.triangularView<Eigen::StrictlyUpper>() = X.transpose();
  X_llt_.compute(X);
  x_ok_ = X_llt_.info() == Eigen::Success;
  t_.resize(k);
  return x_ok_;
}

void Woodbury::B_times(const Mat9X& z, Eigen::VectorXd& out) const {
  const long m = z.cols(), chunk = 1024, nchunks = (m + chunk - 1) / chunk;
  const int k = 3 * ks_;
  Eigen::MatrixXd partial = Eigen::MatrixXd::Zero(k, nchunks);
#pragma omp parallel for schedule(static)
  for (long ch = 0; ch < nchunks; ++ch) {
    const long end = std::min(m, (ch + 1) * chunk);
    Eigen::Map<Eigen::MatrixXd> acc(partial.col(ch).data(), 3, ks_);
    for (long t = ch * chunk; t < end; ++t) {
      const Mat3 Z = unflatten(z.col(t));
      acc.noalias() += wv_(t) * Z * Eigen::Map<const Eigen::MatrixXd>(mode_grad_.col(t).data(), 3, ks_);
    }
  }
  out = partial.rowwise().sum();  // fixed chunk order: reproducible
}

void Woodbury::apply(const Mat9X& r, Mat9X& out) const {
  const long m = r.cols();
  out.resize(9, m);
#pragma omp parallel for schedule(static)
  for (long t = 0; t < m; ++t) {
    Vec9 v = r.col(t);
    L_[t].triangularView<Eigen::Lower>().solveInPlace(v);
    L_[t].transpose().triangularView<Eigen::Upper>().solveInPlace(v);
    out.col(t) = v;
  }
  if (!x_ok_ || ks_ == 0) return;
  Eigen::VectorXd Bz;
  B_times(out, Bz);
  const Eigen::VectorXd s = X_llt_.solve(Bz);
  const Eigen::Map<const Eigen::MatrixXd> S(s.data(), 3, ks_);
#pragma omp parallel for schedule(static)
  for (long t = 0; t < m; ++t) {
    // B_t^T s = w V S G_t^T (3 x 3), then A_t^-1 of it.
    const Mat3 R = wv_(t) * S * Eigen::Map<const Eigen::MatrixXd>(mode_grad_.col(t).data(), 3, ks_).transpose();
    Vec9 v = flatten(R);
    L_[t].triangularView<Eigen::Lower>().solveInPlace(v);
    L_[t].transpose().triangularView<Eigen::Upper>().solveInPlace(v);
    out.col(t) += v;
  }
}

Eigen::MatrixXd Woodbury::dense_B() const {
  const long m = mode_grad_.cols();
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(3 * ks_, 9 * m);
  for (long t = 0; t < m; ++t)
    for (int l = 0; l < ks_; ++l)
      for (int c = 0; c < 3; ++c)
        for (int j = 0; j < 3; ++j) B(c + 3 * l, 9 * t + c + 3 * j) = wv_(t) * mode_grad_(3 * l + j, t);
  return B;
}

Eigen::VectorXd Woodbury::lambda() const {
  Eigen::VectorXd lam(3 * ks_);
  for (int l = 0; l < ks_; ++l) lam.segment<3>(3 * l).setConstant(values_(l));
  return lam;
}

}  // namespace emu
