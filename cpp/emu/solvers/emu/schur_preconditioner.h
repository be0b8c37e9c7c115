#pragma once
// An alternative Newton-Krylov preconditioner: the exact inverse of the
// (filtered) EMU Hessian through its position-space Schur complement,
//   H^-1 r = A^-1 r + alpha A^-1 C^T S^-1 C A^-1 r,
//   S = K - alpha C A^-1 C^T = sum_t G_t^T [w V (I - alpha w V A_t^-1)] G_t,
// a 3 #free x 3 #free sparse SPD matrix with the FEM pattern (as alpha grows,
// S / alpha tends to the FEM Hessian). It costs a numeric factorisation per
// rebuild, so it is rebuilt only every few Newton steps (lagged); between
// rebuilds each application is two back-substitutions' worth of work.
#include <memory>
#include <vector>

#include "emu/linalg/cholmod_factor.h"
#include "emu/mesh/block_pattern.h"
#include "emu/model/unknown_layout.h"
#include "emu/solvers/emu/acap.h"
#include "emu/solvers/emu/block_preconditioner.h"
#include "emu/solvers/emu/schur_form.h"

namespace emu {

class SchurPreconditioner final : public BlockPreconditioner {
 public:
  SchurPreconditioner(const Model& model, const UnknownLayout& layout, const AcapOperator& acap, double alpha);

  /// Rebuild from SPD blocks A_t; false if S could not be factorised.
  bool update(const std::vector<Mat9>& A) override;
  const char* failure() const override { return "Schur-complement preconditioner could not be factorised"; }
  bool factorises_on_update() const override { return true; }

  /// out = H^-1 r (9 x #T each).
  void apply(const Mat9X& r, Mat9X& out) const override;

  double factor_nnz() const { return factor_.factor_nnz(); }
  /// Bytes held: the factor's entries, the block inverses and the assembly buffers.
  double bytes() const {
    return 8.0 * (factor_nnz() + element_.size() + values_.size()) + sizeof(Mat9) * double(Ainv_.size());
  }
  /// A new alpha for the following update() calls.
  void set_alpha(double alpha) override { alpha_ = alpha; }
  void add_structures(std::vector<std::pair<std::string, double>>& out) const override {
    out.emplace_back("Schur preconditioner", bytes());
  }

 private:
  const Model& model_;
  const UnknownLayout& layout_;
  const AcapOperator& acap_;
  double alpha_;
  BlockPattern pattern_;
  CholmodFactor factor_;
  std::vector<Mat9> Ainv_;
  mutable SchurFormWork work_;  // apply()'s work arrays, kept between calls
  std::vector<double> element_, values_;
  bool ok_ = false;
};

}  // namespace emu
