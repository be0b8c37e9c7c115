#pragma once
// Options of the FEM and EMU solvers.
#include <functional>

#include <Eigen/Core>

#include "emu/energy/psd_project.h"

namespace emu {

struct IterationRecord;

struct SolverOptions {
  int max_iterations = 500;
  // Convergence (both must hold, see newton/convergence.h):
  double rtol_grad = 1e-6;     // |g_k| <= rtol_grad |g_0|
  double rtol_energy = 1e-10;  // E_{k-1} - E_k <= rtol_energy (E_0 - E_k)
  // Converged also when |g| <= noise_factor times the gradient's round-off,
  // measured in the endgame (newton_driver.h: kNoiseFrom) (Problem::gradient_noise;
  // 0: off; also tested before a solve is declared stalled). With bones, EMU's
  // fit is ill-conditioned (ACAP weight 1e4) and its gradient's round-off can
  // come within a few times rtol_grad |g_0| (docs/DESIGN.md, "The gradient's
  // round-off").
  double noise_factor = 2.0;
  // Converged also when a full step moves no vertex by more than step_tol
  // (absolute, in position units; 0: off): the accuracy-matched stopping rule,
  // for answers needed to a given vertex error rather than to round-off.
  double step_tol = 0.0;
  // ... and only once |g| <= step_tol_grad |g_0| (a short step far from
  // equilibrium, along a stiff direction, says little about the distance left).
  double step_tol_grad = 1.0;
  // With step_tol_cold_scale a warm-started solve gates on max(|g_0|, |g_cold|)
  // instead, |g_cold| the cold start's gradient under the same load
  // (newton_minimize): accuracy mode, whose error estimate checks each answer.
  bool step_tol_cold_scale = false;
  // ... and (when > 0) only once it and the step before it are steps of the
  // exact Hessian (not the PSD-filtered one), each at most step_tol_contraction
  // of the shorter of the two steps before it: the contraction that lets a short step bound the
  // distance left (rate r <= 1/2 leaves at most r / (1 - r) <= 1 step) is seen,
  // not assumed. Along a softly resisted turn Newton's steps stay about as long
  // for many steps or alternate long and short, and one contracting step among
  // them happens by chance (docs/DESIGN.md, "A short step is evidence only when it is an accurate
  // Newton step"). FEM's accuracy mode and the settle.
  double step_tol_contraction = 0.0;
  double armijo = 1e-4;        // sufficient-decrease constant
  int max_backtracks = 40;     // step halvings before the line search gives up
  // Element Hessians: negative eigenvalues clamped or reflected (energy/psd_project.h).
  EigenFilter eigen_filter = EigenFilter::Clamp;
  // Try the unfiltered Hessian first when it is positive definite (FEM: the
  // Cholesky succeeds; EMU: CG sees no negative curvature); fall back to the
  // filtered one. Restores Newton's quadratic end game.
  bool exact_when_definite = true;
  // FEM: near a stationary point where the exact Hessian is indefinite (a
  // saddle), add its most negative curvature direction to the filtered step
  // (FemSolver::Newton::add_negative_curvature; scenes without movable bones).
  bool negative_curvature = true;
  // FEM: Newton-CG preconditioned by the last factorisation, kept across
  // iterations and solves (frames); a step runs PCG on the current Newton
  // matrix for at most this many iterations to |r| <= eta |g| (eta =
  // min(lagged_cg_forcing, sqrt(|g| / |g_0|))) and factorises afresh only when
  // that fails. 0: off (a factorisation every iteration).
  int lagged_cg_iterations = 0;
  double lagged_cg_forcing = 0.5;
  // FEM with a lagged factor: a PCG solve that converged in more iterations
  // than about half a factorisation costs (FemSolver::refresh_iterations)
  // marks the factor as aged, and the next step or correction factorises
  // afresh instead of running PCG on it (in a sequence an old factor's PCG
  // grows frame by frame). false: only a failed PCG factorises (the core's
  // default; emu.Solver's option lagged_refresh, and the error estimator, turn it on).
  bool lagged_refresh = false;
  // Polled once per iteration; returning true stops the solve with status
  // "interrupted" (the Python bindings use it for Ctrl-C).
  std::function<bool()> interrupted;
  // Called with the record and the positions (#V by 3) of the start and of
  // every accepted iterate; returning true stops the solve with status
  // "stopped by on_iteration" (error-against-time curves, custom stopping).
  std::function<bool(const IterationRecord&, const Eigen::MatrixX3d&)> on_iteration;
};

// EMU's step: the paper's Woodbury quasi-Newton step, Newton-Krylov (PCG on
// the exact Hessian), or L-BFGS with the Woodbury step as its initial inverse.
enum class EmuStep { Woodbury, NewtonKrylov, Lbfgs };
// Newton-Krylov preconditioner: the paper's Woodbury approximation (no
// factorisation after setup), the exact inverse through the position-space
// Schur complement (a factorisation per lagged rebuild), or that inverse with
// the Schur complement replaced by a constant matrix (constant_schur.h; no
// factorisation after setup but one per new alpha).
enum class EmuPreconditioner { Woodbury, Schur, ConstantSchur };

struct EmuSolverOptions {
  double alpha = 0.0;      // absolute ACAP stiffness (Python passes alpha_rel * mu_ref)
  int modes = 24;          // k: ACAP modes in the Woodbury term (rounded up to a multiple of 3)
  EmuStep step = EmuStep::NewtonKrylov;
  int cg_max_iterations = 500;   // per Newton-Krylov step
  double cg_forcing_max = 0.5;       // Eisenstat-Walker eta_k = min(max, max(min, (|g_k| / |g_0|)^exponent))
  double cg_forcing_exponent = 0.5;
  double cg_forcing_min = 0.0;       // a floor where the answer is needed only to an accuracy (0: none)
  // CG also needs the quadratic model to have stopped falling fast:
  // k (q_{k-1} - q_k) <= c |q_k| (Nash-Sofer; newton/pcg.h). 0: residual test alone
  double cg_model_decrease = 0.5;
  EmuPreconditioner preconditioner = EmuPreconditioner::ConstantSchur;
  int preconditioner_refresh = 3;  // Newton-Krylov: rebuild the Woodbury preconditioner every n steps
  bool bone_coarse_space = true;   // movable bones: add the bone-rotation coarse correction (see emu_solver.cpp)
  // Movable bones in joint coordinates over the bone forest (joint_coordinates.h)
  // where a hinge joins two movable bones; other scenes, and those whose joints
  // close a loop or weld two bones, keep per-bone rotations
  bool joint_coordinates = true;
  // Movable bones: directions of CG solves far longer than the last one kept
  // in the coarse space of later steps, at most this many (0: off)
  int recycled_directions = 4;
  // ConstantSchur in single precision: S0's solves (one per CG iteration) with
  // its factor rounded to float, and the 9x9 block inverses rounded
  // (round_spd_block): half the bytes of a back-substitution that streams the
  // whole factor and of the two block passes (docs/DESIGN.md, "The cost of an
  // iteration"); the preconditioner stays one fixed SPD matrix
  bool single_precision_preconditioner = true;
  int lbfgs_memory = 8;  // EmuStep::Lbfgs: the (s, y) pairs kept
};

}  // namespace emu
