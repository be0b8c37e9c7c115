#include "emu/linalg/merged_pattern_factor.h"

#include <algorithm>

namespace emu {

bool MergedPatternFactor::factorize(int n, const int* col_ptr, const int* row_index, const double* values,
                                    const Eigen::SparseMatrix<double>& E) {
  const Eigen::Map<const Eigen::SparseMatrix<double>> K(n, n, col_ptr[n], col_ptr, row_index, values);
  Eigen::SparseMatrix<double> A = K + E;  // sorted row indices (Eigen merges the columns)
  A.makeCompressed();
  const int* cp = A.outerIndexPtr();
  const int* ri = A.innerIndexPtr();
  const bool same = factor_ && col_ptr_.size() == size_t(n + 1) && std::equal(cp, cp + n + 1, col_ptr_.begin()) &&
                    row_index_.size() == size_t(A.nonZeros()) &&
                    std::equal(ri, ri + A.nonZeros(), row_index_.begin());
  if (!same) {  // a new pattern: a new symbolic analysis
    factor_ = std::make_unique<CholmodFactor>();
    factor_->analyze(n, cp, ri);
    col_ptr_.assign(cp, cp + n + 1);
    row_index_.assign(ri, ri + A.nonZeros());
    ++analyses_;
  }
  return factor_->factorize(A.valuePtr());
}

}  // namespace emu
