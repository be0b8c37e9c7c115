#pragma once
// The preconditioner behind EMU's steps: an approximation of H^-1 for the
// Hessian H = A - alpha C^T K_c^-1 C, built from the blocks A_u (one 9x9 SPD
// block per unknown, eigen-filtered) and the constant ACAP operator. EmuSolver
// holds one, chosen by EmuSolverOptions::preconditioner (the Woodbury and L-BFGS
// steps always use Woodbury):
//   Woodbury        H_k^-1 through K's lowest k modes (woodbury.h)
//   Schur           H^-1 through the Schur complement, refactorised per update
//                   (schur_preconditioner.h)
//   ConstantSchur   through the constant Schur complement S0 (constant_schur.h)
#include <string>
#include <utility>
#include <vector>

#include "emu/model/unknown_layout.h"

namespace emu {

class BlockPreconditioner {
 public:
  virtual ~BlockPreconditioner() = default;

  /// Rebuild from the blocks A_u (#unknowns); false: it cannot be applied
  /// until the next update, failure() says why.
  virtual bool update(const std::vector<Mat9>& A) = 0;
  virtual const char* failure() const = 0;
  /// out = M^-1 r; r, out are 9 x #unknowns.
  virtual void apply(const Mat9X& r, Mat9X& out) const = 0;
  /// A new alpha for the following update() calls (the constant Schur
  /// preconditioner factorises its S0 again; the others only keep the value).
  virtual void set_alpha(double alpha) = 0;
  /// A time step's inertia weight w (LoadCase::inertia_weight; 0: none) for the
  /// following update() calls: the constant Schur preconditioner puts (w /
  /// alpha) M on S0's diagonal and factorises it again; the others ignore it.
  virtual void set_inertia(double /*weight*/) {}
  /// Whether update() factorises a sparse matrix (counted in the solve's factorizations).
  virtual bool factorises_on_update() const { return false; }
  /// What it holds, with bytes (EmuSolver::structures).
  virtual void add_structures(std::vector<std::pair<std::string, double>>& out) const = 0;
};

}  // namespace emu
