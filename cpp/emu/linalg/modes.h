#pragma once
// The lowest eigenpairs of a factorised SPD matrix K, by shift-invert Lanczos
// (Spectra) with shift 0: each Lanczos step is one back-substitution with the
// factor already computed, so no other factorisation or null space is formed.
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
