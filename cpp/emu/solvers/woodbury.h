#pragma once
// The paper's approximate inverse Hessian in deformation space.
//
//   H = A - alpha C^T K_c^-1 C   (exact; A block diagonal, one 9x9 block per unknown F)
//   K_c^-1 ~ Phi Lambda^-1 Phi^T  (k lowest ACAP modes)  =>  H_k = A - alpha B^T Lambda^-1 B,
//   B = Phi^T C (k x 9#F).  Woodbury:
//   H_k^-1 r = A^-1 r + A^-1 B^T X^-1 B A^-1 r,   X = Lambda/alpha - B A^-1 B^T.
// Dropping high modes under-estimates K_c^-1, so H_k >= H >= 0: X is SPD and
// every step is a descent direction.
//
// Modes of K = L (x) I_3 come in triples: scalar mode psi_l of L in coordinate
// c is mode index c + 3 l. For tet t let g_tl = sum_a psi_l[v_a] b_a (the
// gradient of psi_l on t); then B_t[(c,l), c + 3 j] = w_t V_t g_tl[j], so
// B_t z = w_t V_t Z_t [g_t0 .. g_t,ks-1] (Z_t = unflatten z) needs no k x 9 storage.
#include <vector>

#include <Eigen/Core>
#include <Eigen/Cholesky>

#include "emu/energy/types.h"
#include "emu/linalg/modes.h"
#include "emu/model/model.h"
#include "emu/solvers/acap.h"

namespace emu {

class Woodbury {
 public:
  /// modes  scalar modes of L (num_free by ks) and their eigenvalues
  /// wv     w_t V_t per tet
  Woodbury(const Model& model, const Discretization& disc, const Modes& modes, const Eigen::VectorXd& wv,
           double alpha);

  /// Factor the blocks A_t (9 x 9 each, column-major, #T of them) and form X
  /// with one symmetric rank update (SYRK). Returns false if X is not SPD
  /// (then apply() falls back to A^-1).
  bool update(const std::vector<Mat9>& A);

  /// out = H_k^-1 r; r, out are 9 x #T.
  void apply(const Mat9X& r, Mat9X& out) const;

  int k() const { return 3 * ks_; }
  /// Dense B (k x 9#T) and Lambda (k), for tests.
  Eigen::MatrixXd dense_B() const;
  Eigen::VectorXd lambda() const;

 private:
  void B_times(const Mat9X& z, Eigen::VectorXd& out) const;  // out = B z

  int ks_;
  double alpha_;
  Eigen::VectorXd values_;     // ks scalar eigenvalues
  Eigen::MatrixXd mode_grad_;  // 3 ks x #T: column t holds g_tl (rows 3l..3l+2)
  Eigen::VectorXd wv_;
  std::vector<Mat9> L_;        // lower Cholesky factors of the A_t
  Eigen::LLT<Eigen::MatrixXd> X_llt_;
  bool x_ok_ = false;
  mutable Mat9X z_;
  mutable Eigen::VectorXd t_, s_;
};

}  // namespace emu
