#pragma once
// Soft-tissue density per unit rest volume: Stable Neo-Hookean plus the active
// fibre term. The Hessian is made PSD per element before any Newton-type use:
// only the Neo-Hookean part can be indefinite (the fibre Hessian is PSD and
// constant), and it is projected in closed form from its analytic eigensystem
// (snh_eigensystem.h; psd_project.h is the numerical reference).
#include "emu/energy/fiber.h"
#include "emu/energy/snh_eigensystem.h"
#include "emu/energy/stable_neo_hookean.h"

namespace emu {

struct TetMaterial {
  double mu, lambda;  // Lame parameters
  double activation;  // a >= 0
  Vec3 fiber;         // unit fibre direction (ignored when activation is 0)
};

inline double material_energy(const TetMaterial& m, const Mat3& F) {
  double e = snh::energy(F, m.mu, m.lambda);
  if (m.activation != 0.0) e += fiber::energy(F, m.fiber, m.activation);
  return e;
}

inline Mat3 material_stress(const TetMaterial& m, const Mat3& F) {
  Mat3 P = snh::stress(F, m.mu, m.lambda);
  if (m.activation != 0.0) P += fiber::stress(F, m.fiber, m.activation);
  return P;
}

inline Mat9 material_hessian_psd(const TetMaterial& m, const Mat3& F,
                                 EigenFilter filter = EigenFilter::Clamp) {
  Mat9 H = snh::hessian_psd(F, m.mu, m.lambda, filter);
  if (m.activation != 0.0) H += fiber::hessian(m.fiber, m.activation);
  return H;
}

/// The unfiltered Hessian (may be indefinite).
inline Mat9 material_hessian(const TetMaterial& m, const Mat3& F) {
  Mat9 H = snh::hessian(F, m.mu, m.lambda);
  if (m.activation != 0.0) H += fiber::hessian(m.fiber, m.activation);
  return H;
}

/// Both Hessians from one Neo-Hookean evaluation: the PSD-filtered one into
/// *psd and the unfiltered one into *exact (either may be nullptr). The same
/// numbers as material_hessian_psd and material_hessian.
inline void material_hessians(const TetMaterial& m, const Mat3& F, EigenFilter filter, Mat9* psd, Mat9* exact) {
  const Mat9 H = snh::hessian(F, m.mu, m.lambda);
  Mat9 fib = Mat9::Zero();
  if (m.activation != 0.0) fib = fiber::hessian(m.fiber, m.activation);
  if (psd) *psd = snh::project_hessian(H, F, m.mu, m.lambda, filter) + fib;
  if (exact) *exact = H + fib;
}

}  // namespace emu
