#pragma once
// The chain rule through the ACAP fit x*(F) (acap.h) for a term of the
// positions, E(x*(F)): contact on EMU's fitted positions, and the load's
// share of EMU's gradient. The fit is affine in F; its Jacobian is the
// homogeneous fit
//   J = dx*/dF = S K_c^-1 C,
// so, for vertex forces f = dE/dx and the term's Hessian H in positions,
//   dE/dF   = J^T f = C^T K_c^-1 S^T f      (one back-substitution)
//   H_F v   = J^T H J v                      (two: the fit of v, then J^T).
// C^T u per tet is w_t V_t F_t(S u): the fit of the forces, weighted.
#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "emu/solvers/emu/acap.h"

namespace emu {

class FitJacobian {
 public:
  FitJacobian(const Model& model, const UnknownLayout& layout, const AcapOperator& acap)
      : model_(model), layout_(layout), acap_(acap) {}

  /// J v: dx (#V by 3, zero at pinned vertices) and Fd = F_t(dx) (9 x #T) for
  /// per-unknown v (9 x #unknowns).
  void apply(const Mat9X& v, Eigen::MatrixX3d& dx, Mat9X& Fd) const;
  /// out (9 x #T) = F_t(S K_c^-1 S^T f) for vertex forces f (#V by 3): the fit of the forces.
  void force_fit(const Eigen::MatrixX3d& f, Mat9X& out) const;
  /// out (9 x #unknowns) = J^T f: w_t V_t times the fit of the forces, summed per unknown.
  void transpose_apply(const Eigen::MatrixX3d& f, Mat9X& out) const;
  /// out += J^T H J v for a position Hessian H (3 #V square, dof 3 v + i).
  void add_hessian_product(const Eigen::SparseMatrix<double>& H, const Mat9X& v, Mat9X& out) const;

 private:
  const Model& model_;
  const UnknownLayout& layout_;
  const AcapOperator& acap_;
};

}  // namespace emu
