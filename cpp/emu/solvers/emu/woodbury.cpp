#include "emu/solvers/emu/woodbury.h"

#include <algorithm>

#include "emu/linalg/spd_inverse.h"

extern "C" void dsyrk_(const char* uplo, const char* trans, const int* n, const int* k, const double* alpha,
                       const double* a, const int* lda, const double* beta, double* c, const int* ldc);

namespace emu {

Woodbury::Woodbury(const Model& model, const UnknownLayout& layout, const AcapOperator& acap, const Modes& modes,
                   double alpha)
    : model_(model),
      layout_(layout),
      acap_(acap),
      ks_(static_cast<int>(modes.values.size())),
      alpha_(alpha),
      values_(modes.values),
      psi_(modes.vectors),
      Ainv_(layout.num_unknowns) {
  psi_vertex_ = Eigen::MatrixXd::Zero(model.rest.rows(), ks_);
  if (ks_) acap.expand(psi_, psi_vertex_);
  // An Eigen::LLT leaves its status unset until computed: compute the empty one
  // so that copying a Woodbury before its first update reads no uninitialised
  // value (UndefinedBehaviorSanitizer).
  X_llt_.compute(Eigen::MatrixXd());
}

void Woodbury::mode_gradients(Eigen::Index u, Eigen::Matrix<double, 3, Eigen::Dynamic>& g) const {
  g.setZero(3, ks_);
  const Eigen::VectorXd& wv = acap_.weight_volume();
  for (int i = layout_.unknown_ptr[u]; i < layout_.unknown_ptr[u + 1]; ++i) {
    const int t = layout_.unknown_tets[i];
    const ShapeGrads& b = layout_.geometry.grad[t];
    for (int a = 0; a < 4; ++a) g.noalias() += (wv(t) * b.row(a).transpose()) * psi_vertex_.row(model_.tets(t, a));
  }
}

bool Woodbury::update(const std::vector<Mat9>& A) {
  const long m = static_cast<long>(A.size());  // unknowns
  x_ok_ = false;
  if (ks_ == 0) {
#pragma omp parallel for schedule(static)
    for (long t = 0; t < m; ++t)
      if (!spd_inverse<9>(A[t], Ainv_[t]))  // filtered blocks are definite: only non-finite ones get here
        Ainv_[t] = Eigen::LLT<Mat9>(A[t]).solve(Mat9::Identity());
    return true;
  }
  const int k = 3 * ks_;
  // X = Lambda/alpha - sum_t M_t M_t^T with M_t = B_t L_t^-T (A_t = L_t L_t^T),
  // accumulated by SYRK over chunks of tets (rows of the chunk buffer: 9 per tet).
  Eigen::MatrixXd X = Eigen::MatrixXd::Zero(k, k);
  for (int l = 0; l < ks_; ++l)
    for (int c = 0; c < 3; ++c) X(c + 3 * l, c + 3 * l) = values_(l) / alpha_;
  const long chunk = 4096;
  Eigen::MatrixXd buf(9 * std::min(chunk, m), k);
  const int lda = static_cast<int>(buf.rows());
  for (long t0 = 0; t0 < m; t0 += chunk) {
    const long nt = std::min(chunk, m - t0);
#pragma omp parallel
    {
      Eigen::Matrix<double, 9, Eigen::Dynamic> BT(9, k);  // per-thread buffers
      Eigen::Matrix<double, 3, Eigen::Dynamic> g(3, ks_);
#pragma omp for schedule(dynamic, 64)
      for (long i = 0; i < nt; ++i) {
        const long t = t0 + i;
        const Eigen::LLT<Mat9> llt(A[t]);
        Ainv_[t] = llt.solve(Mat9::Identity());
        mode_gradients(t, g);
        BT.setZero();
        for (int l = 0; l < ks_; ++l)
          for (int c = 0; c < 3; ++c)
            for (int j = 0; j < 3; ++j) BT(c + 3 * j, c + 3 * l) = g(j, l);
        llt.matrixL().solveInPlace(BT);  // L^-1 B^T = M_t^T
        buf.block(9 * i, 0, 9, k) = BT;
      }
    }
    const int n = k, kk = static_cast<int>(9 * nt), ldc = k;
    const double one = 1.0, minus_one = -1.0;
    dsyrk_("L", "T", &n, &kk, &minus_one, buf.data(), &lda, &one, X.data(), &ldc);
  }
  X.triangularView<Eigen::StrictlyUpper>() = X.transpose();
  X_llt_.compute(X);
  x_ok_ = X_llt_.info() == Eigen::Success;
  return true;
}

void Woodbury::apply(const Mat9X& r, Mat9X& out) const {
  // A^-1 r + A^-1 B^T X^-1 B (A^-1 r) with B z = Psi^T (C z): the middle is
  // s = X^-1 (Psi^T y), entry c + 3 l of s standing for (l, c), and Psi S.
  apply_schur_form(layout_, acap_, Ainv_, 1.0, r, out, work_,
                   [&](const Eigen::MatrixX3d& y, Eigen::MatrixX3d& u) {
                     const Eigen::MatrixXd Bz = psi_.transpose() * y;  // ks x 3
                     Eigen::VectorXd t(3 * ks_);
                     for (int l = 0; l < ks_; ++l)
                       for (int c = 0; c < 3; ++c) t(c + 3 * l) = Bz(l, c);
                     const Eigen::VectorXd s = X_llt_.solve(t);
                     Eigen::MatrixXd S(ks_, 3);
                     for (int l = 0; l < ks_; ++l)
                       for (int c = 0; c < 3; ++c) S(l, c) = s(c + 3 * l);
                     u = psi_ * S;
                   },
                   !x_ok_ || ks_ == 0);
}

Eigen::MatrixXd Woodbury::dense_B() const {
  const long m = layout_.num_unknowns;
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(3 * ks_, 9 * m);
  Eigen::Matrix<double, 3, Eigen::Dynamic> g(3, ks_);
  for (long u = 0; u < m; ++u) {
    mode_gradients(u, g);
    for (int l = 0; l < ks_; ++l)
      for (int c = 0; c < 3; ++c)
        for (int j = 0; j < 3; ++j) B(c + 3 * l, 9 * u + c + 3 * j) = g(j, l);
  }
  return B;
}

Eigen::VectorXd Woodbury::lambda() const {
  Eigen::VectorXd lam(3 * ks_);
  for (int l = 0; l < ks_; ++l) lam.segment<3>(3 * l).setConstant(values_(l));
  return lam;
}

}  // namespace emu
