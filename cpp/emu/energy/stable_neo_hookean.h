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

// Near rest, I_C - 3 and J - 1 are small differences of O(1) numbers, and
// lambda (J - beta)^2 - lambda (1 - beta)^2 cancels O(lambda) terms: evaluated
// naively the energy carries round-off of eps * lambda per unit volume, which at
// nu = 0.49 (and tendon or bone stiffness) swamps the energy changes a line
// search must rank. So both are computed from E = F - I without cancellation:
//   I_C - 3 = |E|^2 + 2 tr E,
//   J - 1   = tr E + ((tr E)^2 - tr(E^2)) / 2 + det E,
//   Psi     = mu/2 (I_C - 3) - mu/2 log1p((I_C - 3)/4) + lambda/2 (J - 1)^2 - 3 mu/4 (J - 1)
// (the last two terms are lambda/2 [(J - beta)^2 - (1 - beta)^2] expanded).

/// I_C - 3, accurate for F near I.
inline double ic_minus_3(const Mat3& F) {
  const Mat3 E = F - Mat3::Identity();
  return E.squaredNorm() + 2.0 * E.trace();
}

/// J - 1, accurate for F near I.
inline double det_minus_1(const Mat3& F) {
  const Mat3 E = F - Mat3::Identity();
  const double tr = E.trace();
  return tr + 0.5 * (tr * tr - (E * E).trace()) + E.determinant();
}

inline double energy(const Mat3& F, double mu, double lambda) {
  const double c = ic_minus_3(F), j = det_minus_1(F);
  return 0.5 * mu * c - 0.5 * mu * std::log1p(0.25 * c) + 0.5 * lambda * j * j - 0.75 * mu * j;
}

/// First Piola-Kirchhoff stress dPsi/dF = mu (1 - 1/(I_C+1)) F + lambda (J - beta) cof(F),
/// with lambda (J - beta) = lambda (J - 1) - 3 mu / 4 (no O(lambda) cancellation).
inline Mat3 stress(const Mat3& F, double mu, double lambda) {
  const double ic = 3.0 + ic_minus_3(F), j = det_minus_1(F);
  return mu * (1.0 - 1.0 / (ic + 1.0)) * F + (lambda * j - 0.75 * mu) * cofactor(F);
}

/// d2Psi/dvec(F)^2 (9x9, not projected):
///   mu (1 - 1/(I_C+1)) I + 2 mu/(I_C+1)^2 f f^T + lambda g g^T + lambda (J - beta) d2J/dF2
/// with f = vec F, g = vec cof(F); d2J/dF2 has blocks (col i, col j) = +-[f_k]_x.
inline Mat9 hessian(const Mat3& F, double mu, double lambda) {
  const double ic = 3.0 + ic_minus_3(F), j = det_minus_1(F);
  const Vec9 f = flatten(F), g = flatten(cofactor(F));
  Mat9 H = (mu * (1.0 - 1.0 / (ic + 1.0))) * Mat9::Identity();
  H.noalias() += (2.0 * mu / ((ic + 1.0) * (ic + 1.0))) * f * f.transpose();
  H.noalias() += lambda * g * g.transpose();
  const double s = lambda * j - 0.75 * mu;  // lambda (J - beta)
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

/// The Hessian's action H vec(D) without forming H (the same terms as
/// hessian(); d2J/dF2 applied as cross products of F's columns):
///   c_id D + c_ff (F:D) F + lambda (cof F:D) cof F + s [f1 x d2 - f2 x d1, f2 x d0 - f0 x d2, f0 x d1 - f1 x d0]
/// with c_id = mu (1 - 1/(I_C+1)), c_ff = 2 mu/(I_C+1)^2, s = lambda (J - beta).
inline Mat3 hessian_action(const Mat3& F, double mu, double lambda, const Mat3& D) {
  const double ic = 3.0 + ic_minus_3(F), j = det_minus_1(F);
  const Mat3 G = cofactor(F);
  const double c_id = mu * (1.0 - 1.0 / (ic + 1.0)), c_ff = 2.0 * mu / ((ic + 1.0) * (ic + 1.0));
  const double s = lambda * j - 0.75 * mu;
  Mat3 out = c_id * D + (c_ff * F.cwiseProduct(D).sum()) * F + (lambda * G.cwiseProduct(D).sum()) * G;
  out.col(0) += s * (F.col(1).cross(D.col(2)) - F.col(2).cross(D.col(1)));
  out.col(1) += s * (F.col(2).cross(D.col(0)) - F.col(0).cross(D.col(2)));
  out.col(2) += s * (F.col(0).cross(D.col(1)) - F.col(1).cross(D.col(0)));
  return out;
}

}  // namespace emu::snh
