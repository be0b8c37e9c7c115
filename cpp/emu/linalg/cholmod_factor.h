#pragma once
// One RAII, non-copyable owner of a CHOLMOD supernodal Cholesky factor
// (simplicial after make_simplicial).
// Symbolic analysis (fill-reducing ordering) happens once per pattern;
// numeric factorisations and solves reuse it.
#include <cstddef>
#include <string>
#include <vector>

#include <cholmod.h>

#include "emu/linalg/supernodal_solve.h"

namespace emu {

class CholmodFactor {
 public:
  CholmodFactor();
  ~CholmodFactor();
  CholmodFactor(const CholmodFactor&) = delete;
  CholmodFactor& operator=(const CholmodFactor&) = delete;

  /// Symbolic analysis of an n x n symmetric matrix given by its upper triangle
  /// in compressed-column form (sorted row indices).
  void analyze(int n, const int* col_ptr, const int* row_index);

  /// From the next analyze on, matrices of at least `rows` rows try both AMD
  /// and METIS and keep the ordering with less fill; smaller ones (and every
  /// matrix when rows <= 0, the default) get CHOLMOD's default choice.
  void set_metis_from_rows(int rows) { metis_from_rows_ = rows; }

  /// The pattern and symbolic analysis of another factor (no new ordering):
  /// for a second matrix with the same pattern.
  void analyze_like(const CholmodFactor& other);

  /// Numeric factorisation with the analysed pattern. values: nnz doubles in the
  /// order of row_index. Returns false if the matrix is not positive definite.
  bool factorize(const double* values);

  /// Converts the (factorised) supernodal factor to a simplicial LL': for a
  /// factor solved many times and never refactorised, whose supernodes are
  /// small (a few thousand rows), where the simplicial solve skips CHOLMOD's
  /// per-supernode BLAS calls (docs/DESIGN.md, "The cost of an iteration").
  /// A later factorize refactorises it simplicially.
  void make_simplicial();

  /// Keeps a copy of the factor rounded to single precision, made now and at
  /// every later factorize (supernodal factors only): for solves that may be
  /// inexact (a preconditioner's), half the bytes to stream.
  void keep_single_precision_copy();

  /// x = A^-1 b for nrhs right-hand sides; b and x are n x nrhs column-major
  /// (they may alias). single_precision: with the rounded copy, x = (L~
  /// L~^T)^-1 b for the rounded factor L~.
  void solve(const double* b, double* x, int nrhs, bool single_precision = false) const;

  int rows() const { return n_; }
  bool simplicial() const { return L_ && !L_->is_super; }
  bool factorized() const { return factorized_; }
  double factor_nnz() const;
  /// Multiply-adds of one numeric factorisation, the sum over L's columns of
  /// their squared lengths (supernodal: a supernode of r rows and c columns
  /// counts sum_{j < c} (r - j)^2, its explicit zeros included); 0 before analyze.
  double factorization_flops() const;
  /// The factor itself (null before analyze).
  const cholmod_factor* factor() const { return L_; }
  /// Entries of A (upper triangle) as analysed.
  const cholmod_sparse* matrix() const { return A_; }

  /// Supernodal factors with at least this many entries are factorised with
  /// OpenBLAS's threads as set_threads set them, smaller ones on one BLAS
  /// thread: BLAS threads gain only on large factors, and on small ones
  /// their worker contends with the OpenMP team (docs/DESIGN.md, "OpenBLAS's
  /// threads on small factors").
  static constexpr std::size_t kThreadedBlasFactorEntries = 10'000'000;

 private:
  void check(const char* what) const;
  /// solve() for a supernodal factor and 1-4 right-hand sides: supernodal_solve_in_place
  void solve_rows(const double* b, double* x, int nrhs, bool single_precision) const;
  void round_panels();
  mutable cholmod_common common_;
  cholmod_sparse* A_ = nullptr;
  cholmod_factor* L_ = nullptr;
  mutable cholmod_dense* X_ = nullptr;
  mutable cholmod_dense* Y_ = nullptr;
  mutable cholmod_dense* E_ = nullptr;
  std::vector<float> rounded_;  // keep_single_precision_copy: L's panels rounded
  bool keep_rounded_ = false;
  mutable std::vector<double> rows_, scratch_;  // solve_rows' work: n x lanes, and the kernel's buffers
  mutable SupernodalSchedule schedule_;  // of L's supernodes, made at the first solve_rows after analyze
  int n_ = 0;
  int metis_from_rows_ = 0;
  bool factorized_ = false;
};

}  // namespace emu
