#include "emu/linalg/cholmod_factor.h"

#include <algorithm>
#include <cstring>
#include <stdexcept>
#include <string>

#include "emu/linalg/blas_info.h"
#include "emu/linalg/serial_openmp_scope.h"
#include "emu/linalg/supernodal_solve.h"

namespace emu {
namespace {
template <typename Scalar>
void solve_lanes(const SupernodalPanels<Scalar>& panels, const SupernodalSchedule& order, int lanes, double* rows,
                 std::vector<double>& scratch) {
  if (lanes == 1) supernodal_solve_in_place<1>(panels, order, rows, scratch);
  else if (lanes == 2) supernodal_solve_in_place<2>(panels, order, rows, scratch);
  else supernodal_solve_in_place<4>(panels, order, rows, scratch);
}

thread_local std::string last_cholmod_error;
void record_error(int status, const char* /*file*/, int /*line*/, const char* message) {
  if (status < 0) last_cholmod_error = message ? message : "unknown CHOLMOD error";
}
}  // namespace

CholmodFactor::CholmodFactor() {
  cholmod_start(&common_);
  common_.supernodal = CHOLMOD_SUPERNODAL;
  // A simplicial factor (make_simplicial) refactorises as LL', not LDL': an
  // indefinite matrix is then reported, as by the supernodal factorisation.
  common_.final_ll = 1;
  common_.print = 0;
  common_.error_handler = record_error;
}

CholmodFactor::~CholmodFactor() {
  if (L_) cholmod_free_factor(&L_, &common_);
  if (A_) cholmod_free_sparse(&A_, &common_);
  if (X_) cholmod_free_dense(&X_, &common_);
  if (Y_) cholmod_free_dense(&Y_, &common_);
  if (E_) cholmod_free_dense(&E_, &common_);
  cholmod_finish(&common_);
}

void CholmodFactor::check(const char* what) const {
  if (common_.status < 0) {
    throw std::runtime_error(std::string("CHOLMOD ") + what + " failed: " + last_cholmod_error);
  }
}

void CholmodFactor::analyze(int n, const int* col_ptr, const int* row_index) {
  if (L_) cholmod_free_factor(&L_, &common_);
  if (A_) cholmod_free_sparse(&A_, &common_);
  factorized_ = false;
  schedule_ = SupernodalSchedule();
  n_ = n;
  if (n == 0) return;  // nothing to factorise (every vertex pinned or on a bone): solves are empty
  const size_t nnz = static_cast<size_t>(col_ptr[n]);
  A_ = cholmod_allocate_sparse(n, n, nnz, /*sorted*/ 1, /*packed*/ 1, /*stype*/ 1, CHOLMOD_REAL,
                               &common_);
  check("allocate");
  if (!A_) throw std::runtime_error("CHOLMOD could not allocate the matrix (out of memory?)");
  std::memcpy(A_->p, col_ptr, sizeof(int) * (n + 1));
  std::memcpy(A_->i, row_index, sizeof(int) * nnz);
  std::memset(A_->x, 0, sizeof(double) * nnz);
  // Orderings: nmethods 3 tries the user's (none: skipped), AMD and METIS and
  // keeps the one with less fill; 0 is CHOLMOD's default (AMD; METIS too only
  // where AMD's is poor, flops per factor entry >= 500 and fill >= 5x).
  common_.nmethods = (metis_from_rows_ > 0 && n >= metis_from_rows_) ? 3 : 0;
  L_ = cholmod_analyze(A_, &common_);
  check("analyze");
  if (!L_) throw std::runtime_error("CHOLMOD analysis failed (out of memory?)");
}

void CholmodFactor::analyze_like(const CholmodFactor& other) {
  if (L_) cholmod_free_factor(&L_, &common_);
  if (A_) cholmod_free_sparse(&A_, &common_);
  factorized_ = false;
  schedule_ = SupernodalSchedule();
  n_ = other.n_;
  if (n_ == 0) return;
  if (!other.A_ || !other.L_) throw std::logic_error("CholmodFactor::analyze_like of a factor not analysed");
  A_ = cholmod_copy_sparse(other.A_, &common_);
  check("copy");
  L_ = cholmod_copy_factor(other.L_, &common_);
  check("copy");
  if (!A_ || !L_) throw std::runtime_error("CHOLMOD could not copy the factor (out of memory?)");
}

bool CholmodFactor::factorize(const double* values) {
  if (n_ == 0) return factorized_ = true;
  if (!A_ || !L_) throw std::logic_error("CholmodFactor::factorize before analyze");
  const size_t nnz = static_cast<const int*>(A_->p)[n_];
  std::memcpy(A_->x, values, sizeof(double) * nnz);
  {
    const SerialOpenMPScope serial_regions;  // CHOLMOD's fixed 4-thread regions (serial_openmp_scope.h)
    // OpenBLAS's threads gain only on large factors; on small ones its worker
    // contends with the spinning OpenMP team (DESIGN.md, "OpenBLAS's threads
    // on small factors").
    const BlasThreadsScope blas(L_->is_super && L_->xsize >= kThreadedBlasFactorEntries ? 0 : 1);
    cholmod_factorize(A_, L_, &common_);
  }
  if (common_.status == CHOLMOD_NOT_POSDEF) {
    factorized_ = false;
    return false;
  }
  check("factorize");
  factorized_ = true;
  if (keep_rounded_) round_panels();
  return true;
}

void CholmodFactor::keep_single_precision_copy() {
  if (keep_rounded_) return;  // kept already (and refreshed by every factorize)
  if (L_ && !L_->is_super) throw std::logic_error("CholmodFactor: a single-precision copy needs a supernodal factor");
  keep_rounded_ = true;
  if (factorized_) round_panels();
}

void CholmodFactor::round_panels() {
  if (n_ == 0) return;
  if (!L_->is_super) throw std::logic_error("CholmodFactor: a single-precision copy needs a supernodal factor");
  const double* x = static_cast<const double*>(L_->x);
  rounded_.assign(x, x + L_->xsize);
}

void CholmodFactor::make_simplicial() {
  if (!factorized_ || n_ == 0 || !L_->is_super) return;
  // xtype real, LL' (not LDL'), simplicial, packed, monotonic
  cholmod_change_factor(CHOLMOD_REAL, /*to_ll*/ 1, /*to_super*/ 0, /*to_packed*/ 1, /*to_monotonic*/ 1, L_, &common_);
  check("change_factor");
}

void CholmodFactor::solve(const double* b, double* x, int nrhs, bool single_precision) const {
  if (!factorized_) throw std::logic_error("CholmodFactor::solve before a successful factorize");
  if (n_ == 0) return;
  if (single_precision) {
    if (!keep_rounded_)
      throw std::logic_error("CholmodFactor::solve in single precision without keep_single_precision_copy");
    for (int c = 0; c < nrhs; c += 4)  // four right-hand sides at a time
      solve_rows(b + static_cast<std::size_t>(c) * n_, x + static_cast<std::size_t>(c) * n_, std::min(4, nrhs - c), true);
    return;
  }
  // 2-4 right-hand sides of a supernodal factor: supernodal_solve_in_place
  // (CHOLMOD's dtrsm / dgemm calls per supernode pack each panel first; one
  // right-hand side goes through dtrsv / dgemv, which do not, and is kept)
  if (L_->is_super && nrhs >= 2 && nrhs <= 4) {
    solve_rows(b, x, nrhs, false);
    return;
  }
  cholmod_dense B;
  std::memset(&B, 0, sizeof(B));
  B.nrow = n_;
  B.ncol = nrhs;
  B.nzmax = static_cast<size_t>(n_) * nrhs;
  B.d = n_;
  B.x = const_cast<double*>(b);
  B.xtype = CHOLMOD_REAL;
  B.dtype = CHOLMOD_DOUBLE;
  {
    // the same rule as factorize: on small factors OpenBLAS's worker, woken
    // by the solve's dtrsv / dgemv, contends with the spinning OpenMP team
    // (DESIGN.md, "OpenBLAS's threads on small factors": the error estimate's
    // PCG, one solve per iteration, 2.5x slower at two threads without it)
    const BlasThreadsScope blas(L_->is_super && L_->xsize >= kThreadedBlasFactorEntries ? 0 : 1);
    cholmod_solve2(CHOLMOD_A, L_, &B, nullptr, &X_, nullptr, &Y_, &E_, &common_);
  }
  check("solve");
  std::memmove(x, X_->x, sizeof(double) * n_ * nrhs);
}

void CholmodFactor::solve_rows(const double* b, double* x, int nrhs, bool single_precision) const {
  // P b into rows of `lanes` entries (the right-hand sides side by side, a
  // zero lane where 3 are padded to 4), L L' solved in place, then P' back
  const int lanes = nrhs == 1 ? 1 : nrhs == 2 ? 2 : 4;
  const int* perm = static_cast<const int*>(L_->Perm);
  rows_.resize(static_cast<std::size_t>(n_) * lanes);
  for (int i = 0; i < n_; ++i) {
    const int p = perm ? perm[i] : i;
    double* row = rows_.data() + static_cast<std::size_t>(i) * lanes;
    for (int r = 0; r < lanes; ++r) row[r] = r < nrhs ? b[p + static_cast<std::size_t>(r) * n_] : 0.0;
  }
  const SupernodalPanels<double> panels = supernodal_panels(*L_);
  if (schedule_.top_slot.size() != static_cast<std::size_t>(n_)) schedule_ = supernodal_schedule(panels);
  if (single_precision) solve_lanes(with_values(panels, rounded_.data()), schedule_, lanes, rows_.data(), scratch_);
  else solve_lanes(panels, schedule_, lanes, rows_.data(), scratch_);
  for (int i = 0; i < n_; ++i) {
    const int p = perm ? perm[i] : i;
    const double* row = rows_.data() + static_cast<std::size_t>(i) * lanes;
    for (int r = 0; r < nrhs; ++r) x[p + static_cast<std::size_t>(r) * n_] = row[r];
  }
}

double CholmodFactor::factor_nnz() const {
  if (!L_) return 0.0;
  if (L_->is_super) {
    // Supernodal: sum over supernodes of (rows x columns).
    const int* super = static_cast<const int*>(L_->super);
    const int* pi = static_cast<const int*>(L_->pi);
    double total = 0;
    for (size_t s = 0; s < L_->nsuper; ++s)
      total += static_cast<double>(pi[s + 1] - pi[s]) * (super[s + 1] - super[s]);
    return total;
  }
  return static_cast<double>(static_cast<const int*>(L_->p)[n_]);
}

double CholmodFactor::factorization_flops() const {
  if (!L_) return 0.0;
  double total = 0;
  if (L_->is_super) {
    const int* super = static_cast<const int*>(L_->super);
    const int* pi = static_cast<const int*>(L_->pi);
    for (size_t s = 0; s < L_->nsuper; ++s) {
      const double r = pi[s + 1] - pi[s], c = super[s + 1] - super[s];
      total += c * r * r - r * c * (c - 1) + (c - 1) * c * (2 * c - 1) / 6.0;  // sum_{j < c} (r - j)^2
    }
    return total;
  }
  const int* p = static_cast<const int*>(L_->p);
  for (int j = 0; j < n_; ++j) total += static_cast<double>(p[j + 1] - p[j]) * (p[j + 1] - p[j]);
  return total;
}

}  // namespace emu
