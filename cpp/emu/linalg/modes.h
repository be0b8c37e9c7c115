#pragma once
// The lowest eigenpairs of a factorised SPD matrix K, by shift-invert Lanczos
// (Spectra) with shift 0: each Lanczos step is one back-substitution with the
// factor already computed, so no other factorisation or null space is formed.
#include <functional>

#include <Eigen/Core>

#include "emu/linalg/cholmod_factor.h"

namespace emu {

struct Modes {
  Eigen::VectorXd values;   // k eigenvalues, ascending
  Eigen::MatrixXd vectors;  // n x k, orthonormal columns
};

/// factor  a factorised n x n SPD matrix (its analysed upper triangle is read
///         for the dense path)
/// count   number of modes wanted; count >= n, or n small, takes a dense
///         eigen-decomposition of the whole matrix (exact, all modes)
Modes lowest_modes(const CholmodFactor& factor, int count, double tolerance = 1e-10);

}  // namespace emu

namespace emu {

/// y = M x for an n-vector x (M symmetric positive semi-definite).
using LinearOperator = std::function<void(const double* x, double* y)>;

/// The lowest eigenpairs of a constrained SPD problem given only its inverse
/// M = K_c^-1 (symmetric PSD, null space of dimension `nullity` = the
/// constrained directions): Lanczos for the largest eigenvalues mu of M
/// (each step one application), returned as lambda = 1 / mu. Small n takes a
/// dense eigen-decomposition of M built column by column.
Modes lowest_modes_of_inverse(int n, const LinearOperator& apply_inverse, int count, int nullity,
                              double tolerance = 1e-10);

}  // namespace emu
