#pragma once
// The Cholesky factor of K + E: K on a fixed pattern (its upper triangle,
// CSC), E sparse (upper triangle) with a pattern that changes between calls,
// as contact pairs appear and vanish. The merged pattern is analysed again
// only when it differs from the last one factorised.
#include <memory>
#include <vector>

#include <Eigen/SparseCore>

#include "emu/linalg/cholmod_factor.h"

namespace emu {

class MergedPatternFactor {
 public:
  /// K: n x n upper triangle (col_ptr n + 1, row_index, values); E: n x n
  /// upper triangle. False if K + E is not positive definite.
  bool factorize(int n, const int* col_ptr, const int* row_index, const double* values,
                 const Eigen::SparseMatrix<double>& E);
  /// The factor of the last factorize (call it first).
  const CholmodFactor& factor() const { return *factor_; }
  /// Symbolic analyses so far (one per new merged pattern).
  int analyses() const { return analyses_; }

 private:
  std::unique_ptr<CholmodFactor> factor_;
  std::vector<int> col_ptr_, row_index_;  // the pattern factor_ analysed
  int analyses_ = 0;
};

}  // namespace emu
