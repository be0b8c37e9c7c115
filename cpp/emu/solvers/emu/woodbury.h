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
// c is mode index c + 3 l. B is never stored: B z = Psi^T (C z) and
// B^T s = C^T (Psi S) go through position space (a gather and two thin GEMMs),
// far cheaper per application than per-unknown k x 9 blocks. Only forming X
// needs the blocks B_u[(c,l), c + 3 j] = sum_{t of u} w_t V_t g_tl[j] with
// g_tl = sum_a psi_l[v_a] b_a (psi expanded to the vertices: bone vertices
// through their bone's map), computed on the fly. An unknown is one soft tet
// or one bone (all its tets).
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "emu/energy/types.h"
#include "emu/linalg/modes.h"
#include "emu/model/unknown_layout.h"
#include "emu/solvers/emu/acap.h"
#include "emu/solvers/emu/block_preconditioner.h"
#include "emu/solvers/emu/schur_form.h"

namespace emu {

class Woodbury final : public BlockPreconditioner {
 public:
  /// modes  scalar constrained modes (acap.dofs() by ks) and their eigenvalues
  Woodbury(const Model& model, const UnknownLayout& layout, const AcapOperator& acap, const Modes& modes,
           double alpha);

  /// Invert the blocks A_u (one per unknown, SPD) and form X with one symmetric
  /// rank update (SYRK). Always usable: where X is not SPD apply() uses A^-1
  /// (low_rank_term() says which).
  bool update(const std::vector<Mat9>& A) override;
  const char* failure() const override { return ""; }
  /// Whether the last update's X was SPD (apply() includes the modes' term).
  bool low_rank_term() const { return ks_ == 0 || x_ok_; }

  /// out = H_k^-1 r; r, out are 9 x #unknowns.
  void apply(const Mat9X& r, Mat9X& out) const override;

  int k() const { return 3 * ks_; }
  /// A new alpha for the following update() calls (the modes do not depend on it).
  void set_alpha(double alpha) override { alpha_ = alpha; }
  void add_structures(std::vector<std::pair<std::string, double>>& out) const override {
    if (k() > 0) out.emplace_back("ACAP modes", mode_bytes());
    out.emplace_back("Woodbury block inverses", block_bytes());
  }
  /// Bytes held: the modes (at the position unknowns and the vertices), and
  /// the block inverses (one per unknown) with the k x k system X.
  double mode_bytes() const { return 8.0 * (psi_.size() + psi_vertex_.size() + values_.size()); }
  double block_bytes() const { return sizeof(Mat9) * double(Ainv_.size()) + 8.0 * X_llt_.matrixLLT().size(); }
  /// Dense B (k x 9 #unknowns) and Lambda (k), for tests.
  Eigen::MatrixXd dense_B() const;
  Eigen::VectorXd lambda() const;

 private:
  /// sum_{t of u} w_t V_t g_tl for every l, as the columns of a 3 x ks matrix.
  void mode_gradients(Eigen::Index u, Eigen::Matrix<double, 3, Eigen::Dynamic>& g) const;

  const Model& model_;
  const UnknownLayout& layout_;
  const AcapOperator& acap_;
  int ks_;
  double alpha_;
  Eigen::VectorXd values_;  // ks scalar eigenvalues
  Eigen::MatrixXd psi_;     // dofs x ks scalar modes
  Eigen::MatrixXd psi_vertex_;  // #V x ks: the modes at the vertices (zero at pinned ones)
  std::vector<Mat9> Ainv_;  // A_u^-1 (explicit: one 9x9 product per application)
  mutable SchurFormWork work_;  // apply()'s work arrays, kept between calls
  Eigen::LLT<Eigen::MatrixXd> X_llt_;
  bool x_ok_ = false;
};

}  // namespace emu
