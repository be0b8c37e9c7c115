#pragma once
// Linear active fiber energy (the EMU paper's), per unit rest volume, for unit
// fiber direction u and activation a >= 0:
//   Psi(F) = a/2 (|F u|^2 - 1)     (the constant a/2 is subtracted: zero at rest)
//   dPsi/dF = a (F u) u^T
//   d2Psi/dvec(F)^2 = a (u u^T kron I_3)   (constant, PSD)
#include "emu/energy/types.h"

namespace emu::fiber {

/// a/2 (|F u|^2 - |u|^2) = a/2 (2 u.(E u) + |E u|^2) with E = F - I: no cancellation near rest.
inline double energy(const Mat3& F, const Vec3& u, double a) {
  const Vec3 Eu = (F - Mat3::Identity()) * u;
  return 0.5 * a * (2.0 * u.dot(Eu) + Eu.squaredNorm());
}

inline Mat3 stress(const Mat3& F, const Vec3& u, double a) { return a * (F * u) * u.transpose(); }

inline Mat9 hessian(const Vec3& u, double a) {
  Mat9 H;
  for (int j = 0; j < 3; ++j)
    for (int l = 0; l < 3; ++l) H.block<3, 3>(3 * j, 3 * l) = (a * u(j) * u(l)) * Mat3::Identity();
  return H;
}

}  // namespace emu::fiber
