#pragma once
// EMU's ACAP coupling for one tet: how far the deformation gradient of the
// fitted positions, fx = vec F_t(x), is from the tet's unknown f = vec F_u,
//   E_C,t(f, fx) = alpha/2 w_t V_t |fx - f|^2
// (w_t the tet's ACAP weight, V_t its rest volume: the volume weight makes
// alpha independent of the mesh resolution).
//   dE/df  = alpha w V (f - fx)      dE/dfx = -dE/df
//   d2E/df2 = alpha w V I_9          (constant; the mesh-level part through
//                                     x*(F), -alpha C^T K_c^-1 C, is EmuSolver's)
// Summed over tets with x = x*(F) the fit's minimiser, the envelope theorem
// drops dx*/dF from the gradient: dE/dF_u = sum_{t of u} alpha w V (F_u - F_t(x*)).
#include "emu/energy/types.h"

namespace emu::acap_coupling {

inline double energy(const Vec9& f, const Vec9& fx, double alpha, double wv) {
  return 0.5 * alpha * wv * (fx - f).squaredNorm();
}

/// dE/df (dE/dfx is its negative).
inline Vec9 gradient(const Vec9& f, const Vec9& fx, double alpha, double wv) { return alpha * wv * (f - fx); }

/// d2E/df2 = hessian_diagonal I_9.
inline double hessian_diagonal(double alpha, double wv) { return alpha * wv; }

}  // namespace emu::acap_coupling
