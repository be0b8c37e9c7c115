#pragma once
// Newton-Krylov's preconditioner from a constant Schur complement: the exact
// inverse of the (filtered) EMU Hessian through its position-space Schur
// complement (schur_preconditioner.h),
//   H^-1 r = A^-1 r + alpha A^-1 C^T S^-1 C A^-1 r,
//   S = K - alpha C A^-1 C^T = sum_t G_t^T E_t G_t,  E_t = w V (I - alpha w V A_t^-1),
// with S replaced by a constant matrix of the ACAP matrix's form. A soft tet's
// block A_t = V H_t + alpha w V I gives E_t the eigenvalues
//   w V h / (h + alpha w)        for each curvature h of its material,
// so S0 takes one scalar curvature per tet, h_t = mu_t + lambda_t / 3 (between
// its shear and volume curvatures):
//   S0 = L_e (x) I_3,  L_e = sum_t e_t b b^T,  e_t = w_t V_t h_t / (h_t + alpha w_t).
// A movable bone's tets weigh w V, the limit h -> infinity: its unknown is a
// rotation, so every other affine motion of its fit is infinitely stiff, and
// its turns are the bone coarse space's (bone_coarse_space.h). (In S itself
// they add nothing on the affine maps the fit allows; a token weight costs CG
// iterations, and c w V like the soft tissue, which would make S0 = c K, can
// keep a strict solve from converging: docs/DESIGN.md, "The constant
// Schur-complement preconditioner".) Where every e_t / (w_t V_t) is the same c (one
// tissue without movable bones), S0 = c K and K's factor serves: nothing more
// is factorised, for any alpha. Otherwise S0 is factorised once per alpha (an
// AcapOperator with these weights on the ACAP matrix's symbolic analysis: a
// ninth of FEM's factor entries), never per Newton step; a rebuild only
// inverts the 9x9 blocks.
// A time step's inertia (w / 2) |x(F) - y|^2_M on the fitted positions adds
// J^T w M J (J = K^-1 C, the fit's Jacobian) to H = A - alpha C^T K^-1 C. The
// preconditioner inverts instead the Hessian of F where the positions
// minimise the ACAP coupling and the inertia together,
//   H~ = A - alpha^2 C^T (alpha K + w M)^-1 C,  H~^-1 through S + (w / alpha) M,
// equal to H to first order in w M (alpha K)^-1, which is small on a muscle at
// animation time steps (alpha K's softest mode stands ~1e2 above w M at
// 1/24 s): S0 takes (w / alpha) m_v on each free vertex's diagonal
// (set_inertia), factorised once per alpha and step size. A movable bone's
// inertia stays out of S0 (its turns are the coarse space's).
// The preconditioned eigenvalues are 1 and those of S0^-1 S: how well one
// scalar per tet stands for the material's curvatures (nearly incompressible
// tissue: lambda ~ 25 mu), independent of the mesh size, where the Woodbury
// approximation's k modes cover a shrinking share of the spectrum as the mesh
// grows (docs/DESIGN.md, "The constant Schur-complement preconditioner").
#include <memory>
#include <vector>

#include "emu/model/unknown_layout.h"
#include "emu/solvers/emu/acap.h"
#include "emu/solvers/emu/block_preconditioner.h"
#include "emu/solvers/emu/schur_form.h"

namespace emu {

class ConstantSchur final : public BlockPreconditioner {
 public:
  /// single_precision (EmuSolverOptions::single_precision_preconditioner): S0's
  /// solves with its factor rounded to float (S0's own factor, or, where
  /// S0 = c K on a scene without movable bones, a rounded copy of acap's), and
  /// the block inverses kept rounded (round_spd_block: definite, >= A^-1).
  ConstantSchur(const Model& model, const UnknownLayout& layout, AcapOperator& acap, double alpha,
                bool single_precision = true);

  /// Invert the SPD blocks A_u (one per unknown). False if one is not SPD
  /// (apply() then returns r unchanged).
  bool update(const std::vector<Mat9>& A) override;
  const char* failure() const override { return "a filtered Hessian block is not positive definite (or not finite)"; }

  /// out = M^-1 r; r, out are 9 x #unknowns.
  void apply(const Mat9X& r, Mat9X& out) const override;

  /// A new alpha: S0's weights change, so it is factorised again (numerically).
  void set_alpha(double alpha) override;
  /// A time step's inertia weight w (0: none): S0 + (w / alpha) M, factorised again where w changed.
  void set_inertia(double weight) override;
  void add_structures(std::vector<std::pair<std::string, double>>& out) const override {
    out.emplace_back("constant Schur preconditioner", bytes());
  }

  /// Per-tet weights e_t of S0 (#T).
  static Eigen::VectorXd weights(const Model& model, const UnknownLayout& layout, const Eigen::VectorXd& wv,
                                 double alpha);

  /// The inertia weight S0 was last built with (0: none).
  double inertia() const { return inertia_; }
  /// Entries of S0's own factor (0 where S0 is a multiple of K and K's factor serves).
  double factor_nnz() const { return s0_ ? s0_->factor().factor_nnz() : 0.0; }
  /// Bytes held: S0's own factor (if any) and the block inverses.
  double bytes() const {
    return 8.0 * factor_nnz() + (rounded_ ? 4.0 * s0().factor().factor_nnz() : 0.0) + sizeof(Mat9) * double(Ainv_.size()) +
           sizeof(Mat9f) * double(Ainv_rounded_.size());
  }

 private:
  const Model& model_;
  const UnknownLayout& layout_;
  const AcapOperator& s0() const { return s0_ ? *s0_ : acap_; }
  AcapOperator& acap_;
  bool single_precision_, rounded_ = false;
  double alpha_, inertia_ = 0.0;
  void build_s0();  // S0 at alpha_ and inertia_
  void rebuild_with(double& setting, double value);  // setting = value and S0 again (kept on failure)
  std::unique_ptr<AcapOperator> s0_;  // empty where S0 = scale_ K (K's factor serves)
  double scale_ = 1.0;
  std::vector<Mat9> Ainv_;          // the block inverses in double, or
  std::vector<Mat9f> Ainv_rounded_;  // rounded (single_precision; round_spd_block)
  bool ok_ = false;
  // apply()'s work arrays, kept between calls
  mutable SchurFormWork work_;
  mutable Eigen::MatrixXd rhs_, z_;
};

}  // namespace emu
