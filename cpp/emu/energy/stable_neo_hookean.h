#pragma once
// Stable Neo-Hookean (Smith, de Goes, Kim 2018), per unit rest volume:
//   Psi(F) = mu/2 (I_C - 3) + lambda/2 (J - beta)^2 - mu/2 log(I_C + 1) - Psi(I)
//   beta = 1 + 3 mu / (4 lambda)   (makes P(I) = 0: rest-stable)
// The rest value Psi(I) = lambda/2 (1 - beta)^2 - mu/2 log 4 is subtracted: with
// bone-stiff materials it would otherwise dwarf every energy change.
// mu, lambda are the Lame parameters of the material.
#include <cmath>

#include "emu/energy/types.h"

namespace emu::snh {

inline double beta(double mu, double lambda) { return 1.0 + 0.75 * mu / lambda; }

/// dJ/dF: columns f1 x f2, f2 x f0, f0 x f1.
inline Mat3 cofactor(const Mat3& F) {
  Mat3 C;
  C.col(0) = F.col(1).cross(F.col(2));
  C.col(1) = F.col(2).cross(F.col(0));
  C.col(2) = F.col(0).cross(F.col(1));
  return C;
}

inline double energy(const Mat3& F, double mu, double lambda) {
  const double ic = F.squaredNorm(), J = F.determinant(), b = beta(mu, lambda);
  const double rest = 0.5 * lambda * (1.0 - b) * (1.0 - b) - 0.5 * mu * std::log(4.0);
  return 0.5 * mu * (ic - 3.0) + 0.5 * lambda * (J - b) * (J - b) - 0.5 * mu * std::log(ic + 1.0) - rest;
}

/// First Piola-Kirchhoff stress dPsi/dF = mu (1 - 1/(I_C+1)) F + lambda (J - beta) cof(F).
inline Mat3 stress(const Mat3& F, double mu, double lambda) {
  const double ic = F.squaredNorm(), J = F.determinant(), b = beta(mu, lambda);
  return mu * (1.0 - 1.0 / (ic + 1.0)) * F + lambda * (J - b) * cofactor(F);
}

/// d2Psi/dvec(F)^2 (9x9, not projected):
///   mu (1 - 1/(I_C+1)) I + 2 mu/(I_C+1)^2 f f^T + lambda g g^T + lambda (J - beta) d2J/dF2
/// with f = vec F, g = vec cof(F); d2J/dF2 has blocks (col i, col j) = +-[f_k]_x.
inline Mat9 hessian(const Mat3& F, double mu, double lambda) {
  const double ic = F.squaredNorm(), J = F.determinant(), b = beta(mu, lambda);
  const Vec9 f = flatten(F), g = flatten(cofactor(F));
  Mat9 H = (mu * (1.0 - 1.0 / (ic + 1.0))) * Mat9::Identity();
  H.noalias() += (2.0 * mu / ((ic + 1.0) * (ic + 1.0))) * f * f.transpose();
  H.noalias() += lambda * g * g.transpose();
  const double s = lambda * (J - b);
  const Mat3 x0 = s * cross_matrix(F.col(0)), x1 = s * cross_matrix(F.col(1)),
             x2 = s * cross_matrix(F.col(2));
  // d(f1 x f2)/df1 = -[f2]x, d(f1 x f2)/df2 = [f1]x, d(f2 x f0)/df2 = -[f0]x
  H.block<3, 3>(0, 3) -= x2;
  H.block<3, 3>(0, 6) += x1;
  H.block<3, 3>(3, 6) -= x0;
  H.block<3, 3>(3, 0) += x2;
  H.block<3, 3>(6, 0) -= x1;
  H.block<3, 3>(6, 3) += x0;
  return H;
}

}  // namespace emu::snh
