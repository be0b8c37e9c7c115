#pragma once
// The ACAP fit x*(F): the positions whose per-tet deformation gradients best
// match the unknowns F in the weighted least-squares sense,
//   E_C(x, F) = alpha/2 sum_t w_t V_t |F_t(x) - F_t|^2.
// Its matrix K = sum_t w_t V_t G_t^T G_t does not depend on F. Because every
// constraint here acts on whole vertices (pins; later bones' affine maps and
// joints act per coordinate too), K = L (x) I_3 with L the scalar weighted
// Laplacian L_ab = sum_t w_t V_t b_a . b_b over the free vertices: only L is
// factorised (once), and every fit is one back-substitution with 3 right-hand
// sides. alpha cancels from the fit; it enters the energy only.
#include <vector>

#include <Eigen/Core>

#include "emu/linalg/cholmod_factor.h"
#include "emu/mesh/block_pattern.h"
#include "emu/model/model.h"

namespace emu {

using Mat9X = Eigen::Matrix<double, 9, Eigen::Dynamic>;

/// F_t(x) for every tet, as columns vec(F_t) of a 9 x #T matrix. x: #V by 3.
void deformation_gradients(const Discretization& disc, const Eigen::MatrixX4i& T,
                           const Eigen::MatrixX3d& x, Mat9X& out);

class AcapOperator {
 public:
  AcapOperator(const Model& model, const Discretization& disc);

  /// Writes the free rows of x (#V by 3) with the fit to targets F (9 x #T).
  /// F_pinned (9 x #T) is F_t of the positions with free rows zero and pinned
  /// rows at their targets: the pinned vertices' share of every F_t(x).
  void fit(const Mat9X& F, const Mat9X* F_pinned, Eigen::MatrixX3d& x) const;

  /// y = L^-1 b for the free rows: b, y are num_free by 3 (column-major).
  void solve(const Eigen::MatrixX3d& b, Eigen::MatrixX3d& y) const { factor_.solve(b.data(), y.data(), 3); }

  /// y = C D: the right-hand side sum_t w_t V_t D_t b_a per free vertex a
  /// (num_free by 3) for per-tet matrices D (9 x #T).
  void apply_C(const Mat9X& D, Eigen::MatrixX3d& y) const;

  /// out_t = w_t V_t F_t(u) (= C^T u) for a displacement u of the free vertices
  /// (num_free by 3; pinned vertices do not move).
  void apply_CT(const Eigen::MatrixX3d& u, Mat9X& out) const;

  /// Writes the free rows of x from a num_free by 3 block.
  void scatter_free(const Eigen::MatrixX3d& y, Eigen::MatrixX3d& x) const;

  const CholmodFactor& factor() const { return factor_; }
  /// w_t V_t per tet.
  const Eigen::VectorXd& weight_volume() const { return wv_; }

 private:
  const Model& model_;
  const Discretization& disc_;
  BlockPattern pattern_;
  CholmodFactor factor_;
  Eigen::VectorXd wv_;
  mutable std::vector<double> corner_;
  mutable Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> rhs_rows_;
  mutable Eigen::MatrixX3d rhs_, sol_;
};

}  // namespace emu
