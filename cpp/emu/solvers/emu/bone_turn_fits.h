#pragma once
// The turns of EMU's bone coarse space (bone_coarse_space.h) without a fit
// per turn. The fit is linear and acts per coordinate (K = L (x) I3): targets
// M T_t fit to positions X M^T, whose F_t are M F_t(X). So the fit of a bone
// turned by M with the soft F_t following is M times that of the unit turn
// M = I. Per movable bone two fits once at setup: F_t of the unit turn's fit
// on the soft unknowns (follow, 9 x #soft) and F_t of the fit of that
// followed field (fit, 9 x #T), in place of six fits per Newton step.
#include <array>
#include <vector>

#include "emu/model/unknown_layout.h"
#include "emu/solvers/emu/fit_jacobian.h"

namespace emu {

class BoneTurnFits {
 public:
  /// The two fits of every movable bone's unit turn through the fit's Jacobian.
  BoneTurnFits(const UnknownLayout& layout, const FitJacobian& jacobian);

  int bones() const { return static_cast<int>(fits_.size()); }
  /// Per movable bone its unit turn's follow field (what BoneCoarseSpace takes).
  std::vector<const Mat9X*> follow_fields() const;
  double bytes() const;

  /// Bone b turned by each tangent M[k] (9 x #unknowns: M[k] on the bone, the
  /// soft F_t following, other bones 0) into Z[k], and the Euclidean Hessian
  /// product H Z[k] = A Z[k] - alpha C^T K_c^-1 C Z[k] into HZ[k], from the
  /// blocks A (one per unknown) and the ACAP weights times volumes wv (#T).
  /// The N turns share one pass over A (each block read once); each product is
  /// a 9x9 times one vector, so N = 1 and N = 3 give the same bits.
  template <int N>
  void turns(const std::vector<Mat9>& A, int b, const std::array<Mat3, N>& M, double alpha,
             const Eigen::VectorXd& wv, std::array<Mat9X, N>& Z, std::array<Mat9X, N>& HZ) const;

 private:
  struct UnitTurn {
    Mat9X follow, fit;
  };
  const UnknownLayout& layout_;
  std::vector<UnitTurn> fits_;
};

}  // namespace emu
