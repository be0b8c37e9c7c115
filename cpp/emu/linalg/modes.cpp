#include "emu/linalg/modes.h"

#include <algorithm>
#include <numeric>
#include <stdexcept>
#include <string>

#include <Eigen/Eigenvalues>
#include <Spectra/SymEigsShiftSolver.h>
#include <Spectra/SymEigsSolver.h>

namespace emu {
namespace {

// y = K^-1 x through the prefactored matrix (shift fixed at 0).
class FactorInverseOp {
 public:
  using Scalar = double;
  explicit FactorInverseOp(const CholmodFactor& f) : f_(f) {}
  Eigen::Index rows() const { return f_.rows(); }
  Eigen::Index cols() const { return f_.rows(); }
  void set_shift(double sigma) {
    if (sigma != 0.0) throw std::logic_error("FactorInverseOp supports shift 0 only");
  }
  void perform_op(const double* x, double* y) const { f_.solve(x, y, 1); }

 private:
  const CholmodFactor& f_;
};

Eigen::MatrixXd dense_upper_to_full(const cholmod_sparse* A) {
  const int n = static_cast<int>(A->nrow);
  const int* p = static_cast<const int*>(A->p);
  const int* i = static_cast<const int*>(A->i);
  const double* x = static_cast<const double*>(A->x);
  Eigen::MatrixXd K = Eigen::MatrixXd::Zero(n, n);
  for (int j = 0; j < n; ++j)
    for (int e = p[j]; e < p[j + 1]; ++e) {
      K(i[e], j) = x[e];
      K(j, i[e]) = x[e];
    }
  return K;
}

class InverseOp {
 public:
  using Scalar = double;
  InverseOp(int n, const LinearOperator& op) : n_(n), op_(op) {}
  Eigen::Index rows() const { return n_; }
  Eigen::Index cols() const { return n_; }
  void perform_op(const double* x, double* y) const { op_(x, y); }

 private:
  int n_;
  const LinearOperator& op_;
};

}  // namespace

Modes lowest_modes_of_inverse(int n, const LinearOperator& apply_inverse, int count, int nullity, double tolerance) {
  Modes modes;
  count = std::max(0, std::min(count, n - nullity));
  if (count == 0) {
    modes.values.resize(0);
    modes.vectors.resize(n, 0);
    return modes;
  }
  Eigen::VectorXd mu;
  Eigen::MatrixXd vecs;
  if (n <= 400 || 3 * count + 20 > n) {
    Eigen::MatrixXd M(n, n);
    Eigen::VectorXd e = Eigen::VectorXd::Zero(n);
    for (int j = 0; j < n; ++j) {
      e(j) = 1.0;
      apply_inverse(e.data(), M.col(j).data());
      e(j) = 0.0;
    }
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (M + M.transpose()));
    mu = es.eigenvalues().tail(count).reverse();
    vecs = es.eigenvectors().rightCols(count).rowwise().reverse();
  } else {
    InverseOp op(n, apply_inverse);
    const int ncv = std::min(n, std::max(2 * count + 1, count + 20));
    Spectra::SymEigsSolver<InverseOp> eigs(op, count, ncv);
    eigs.init();
    eigs.compute(Spectra::SortRule::LargestAlge, 2000, tolerance);
    if (eigs.info() != Spectra::CompInfo::Successful)
      throw std::runtime_error("Lanczos did not converge for " + std::to_string(count) + " modes; try fewer modes");
    mu = eigs.eigenvalues();  // descending
    vecs = eigs.eigenvectors();
  }
  if (!(mu(count - 1) > 0)) throw std::runtime_error("the constrained ACAP matrix is not positive definite");
  modes.values = mu.cwiseInverse();
  modes.vectors = vecs;
  return modes;
}

Modes lowest_modes(const CholmodFactor& factor, int count, double tolerance) {
  const int n = factor.rows();
  Modes modes;
  if (count <= 0 || n == 0) {
    modes.values.resize(0);
    modes.vectors.resize(n, 0);
    return modes;
  }
  if (count >= n || n <= 400 || 3 * count + 20 > n) {
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(dense_upper_to_full(factor.matrix()));
    const int k = std::min(count, n);
    modes.values = es.eigenvalues().head(k);
    modes.vectors = es.eigenvectors().leftCols(k);
    return modes;
  }
  FactorInverseOp op(factor);
  const int ncv = std::min(n, std::max(2 * count + 1, count + 20));
  Spectra::SymEigsShiftSolver<FactorInverseOp> eigs(op, count, ncv, 0.0);
  eigs.init();
  eigs.compute(Spectra::SortRule::LargestMagn, 2000, tolerance);
  if (eigs.info() != Spectra::CompInfo::Successful)
    throw std::runtime_error("shift-invert Lanczos did not converge for " + std::to_string(count) +
                             " modes; try fewer modes");
  Eigen::VectorXd vals = eigs.eigenvalues();
  Eigen::MatrixXd vecs = eigs.eigenvectors();
  std::vector<int> order(vals.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) { return vals(a) < vals(b); });
  modes.values.resize(count);
  modes.vectors.resize(n, count);
  for (int j = 0; j < count; ++j) {
    modes.values(j) = vals(order[j]);
    modes.vectors.col(j) = vecs.col(order[j]);
  }
  return modes;
}

}  // namespace emu
