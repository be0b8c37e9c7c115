#pragma once
// Options, per-iteration records and results shared by the FEM and EMU solvers.
#include <algorithm>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace emu {

struct SolverOptions {
  int max_iterations = 500;
  // Convergence (both must hold, see Convergence below):
  double rtol_grad = 1e-6;     // |g_k| <= rtol_grad |g_0|
  double rtol_energy = 1e-10;  // E_{k-1} - E_k <= rtol_energy (E_0 - E_k)
  double armijo = 1e-4;        // sufficient-decrease constant
  int max_backtracks = 40;     // step halvings before the line search gives up
  // Element Hessians: negative eigenvalues clamped (0) or reflected (1); see psd_project.h.
  int eigen_filter = 0;
  // Try the unfiltered Hessian first when it is positive definite (FEM: the
  // Cholesky succeeds; EMU: CG sees no negative curvature); fall back to the
  // filtered one. Restores Newton's quadratic end game.
  bool exact_when_definite = true;
  // Polled once per iteration; returning true stops the solve with status
  // "interrupted" (the Python bindings use it for Ctrl-C).
  std::function<bool()> interrupted;
};

enum class EmuStep { Woodbury, NewtonKrylov };
// Newton-Krylov preconditioner: the paper's Woodbury approximation (no
// factorisation after setup), or the exact inverse through the position-space
// Schur complement (a factorisation per lagged rebuild).
enum class EmuPreconditioner { Woodbury, Schur };

struct EmuOptions {
  double alpha = 0.0;      // absolute ACAP stiffness (Python passes alpha_rel * mu_ref)
  int modes = 24;          // k: ACAP modes in the Woodbury term (rounded up to a multiple of 3)
  EmuStep step = EmuStep::NewtonKrylov;
  int cg_max_iterations = 500;   // per Newton-Krylov step
  double cg_forcing_max = 0.5;       // Eisenstat-Walker eta_k = min(max, (|g_k| / |g_0|)^exponent)
  double cg_forcing_exponent = 0.5;
  EmuPreconditioner preconditioner = EmuPreconditioner::Woodbury;
  int preconditioner_refresh = 3;  // Newton-Krylov: rebuild the Woodbury preconditioner every n steps
  bool bone_coarse_space = true;   // movable bones: add the bone-rotation coarse correction (see emu_solver.cpp)
};

struct IterationRecord {
  int iteration = 0;
  double energy = 0, grad_norm = 0, step = 0, time_s = 0;
  int cg_iterations = 0, backtracks = 0;
};

struct SolveResult {
  Eigen::MatrixX3d positions;  // #V by 3
  Eigen::MatrixXd F;           // #T by 9 deformation-gradient unknowns (EMU), empty for FEM
  bool converged = false;
  std::string status;
  int iterations = 0, cg_iterations = 0;
  int filtered_steps = 0;  // iterations that needed the PSD-filtered Hessian (not the exact one)
  int exact_attempts_failed = 0;  // FEM: factorisations of the exact Hessian that found it indefinite
  double energy = 0, grad_norm = 0, grad_norm0 = 0, rel_energy_change = 0;
  double time_s = 0;  // solve time (setup excluded)
  std::vector<IterationRecord> history;  // entry 0 is the initial state
  // Neutral modes met on the way: movable bone ids and unit rotation axes
  // (rows) about which nothing resisted the bone's turn (no curvature of the
  // energy); the step left those rotations alone.
  std::vector<int> neutral_bones;
  Eigen::MatrixX3d neutral_axes;
};

/// The scale-aware stopping test. Energies carry no rest offset, so relative
/// tests are meaningful: the last decrease relative to the total decrease so
/// far, and the gradient norm relative to the first one. A gradient below
/// `floor` (a roundoff-level absolute bound from the problem's own scales)
/// counts as zero, which is how an already-converged start stops at once.
struct Convergence {
  double rtol_grad, rtol_energy, E0, g0, floor;
  double rel_energy_change = 0;
  bool initial() const { return g0 <= floor; }
  bool test(double E_prev, double E, double g) {
    const double total = E0 - E;
    rel_energy_change = total > 0 ? (E_prev - E) / total : 0.0;
    if (g <= floor) return true;
    return g <= rtol_grad * g0 && (E_prev - E) <= rtol_energy * std::max(total, 0.0);
  }
};

/// Backtracking (Armijo) line search on a scalar function of the step length.
/// energy_at(s) may return a non-finite value: that step is rejected.
struct LineSearchResult {
  double step = 0, energy = 0;
  int backtracks = 0;
  bool success = false;
};

/// When no step lowers the energy, the energy has hit round-off: it can no
/// longer rank steps, but the gradient can. Accept the full step if it leaves
/// the energy unchanged to round-off and lowers the gradient norm.
inline bool accept_at_roundoff(double E_full, double g_full, double E, double g, double E0) {
  return std::abs(E_full - E) <= 1e-11 * (std::abs(E) + std::abs(E0 - E)) && g_full < g;
}

template <class EnergyAt>
LineSearchResult armijo_backtracking(EnergyAt&& energy_at, double E0, double slope,
                                     const SolverOptions& o, double s0 = 1.0) {
  LineSearchResult r;
  double s = s0;
  for (int b = 0; b <= o.max_backtracks; ++b) {
    const double E = energy_at(s);
    // Strict decrease as well: at round-off the Armijo bound rounds to E0 and
    // would accept zero-length progress forever.
    if (std::isfinite(E) && E <= E0 + o.armijo * s * slope && E < E0) {
      r.step = s;
      r.energy = E;
      r.backtracks = b;
      r.success = true;
      return r;
    }
    s *= 0.5;
  }
  r.backtracks = o.max_backtracks;
  return r;
}

}  // namespace emu
