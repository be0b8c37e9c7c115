#pragma once
// What a solve returns: the state, the statistics, a record per iteration.
#include <string>
#include <vector>

#include <Eigen/Core>

namespace emu {

struct IterationRecord {
  int iteration = 0;
  double energy = 0, grad_norm = 0, step = 0, time_s = 0;
  int cg_iterations = 0, backtracks = 0;
};

/// A turn of a movable bone that nothing resists (no curvature of the energy
/// along it): the step leaves it alone and the solve reports it.
struct NeutralMode {
  int bone;
  Eigen::Vector3d axis;  // unit rotation axis (or, for a free bone that can slide, the direction)
};

/// Seconds a solve spent per phase (time_s minus their sum: the solve's own
/// setup, convergence tests, bookkeeping).
struct PhaseTimes {
  double hessian = 0;         // element Hessian blocks (FEM: and their assembly into the matrix)
  double preconditioner = 0;  // EMU: Woodbury / Schur rebuilds and the bone coarse space
  double linear_solve = 0;    // FEM: factorisations and back-substitutions; EMU: CG
  double line_search = 0;     // trial energies (EMU with bones: a fit per trial)
  double step = 0;            // moving to the accepted step and the gradient there
};

struct SolveResult {
  Eigen::MatrixX3d positions;  // #V by 3
  Eigen::MatrixXd F;           // EMU: F per tet of the scene (Model::scene_tet_count() by 9, F row-major per row; identity where a tet has no unknown); FEM: empty
  bool converged = false;
  std::string status;
  int iterations = 0, cg_iterations = 0;
  int filtered_steps = 0;  // iterations that needed the PSD-filtered Hessian (not the exact one)
  int exact_attempts_failed = 0;  // FEM: factorisations of the exact Hessian that found it indefinite
  int factorizations = 0;  // sparse Cholesky factorisations of a Newton matrix (FEM; EMU's Schur rebuilds)
  int negative_curvature_steps = 0;  // FEM: steps that added a negative-curvature direction (saddles)
  double energy = 0, grad_norm = 0, grad_norm0 = 0, rel_energy_change = 0;
  double time_s = 0;  // solve time (setup excluded)
  PhaseTimes phases;
  std::vector<IterationRecord> history;  // entry 0 is the initial state
  // Neutral modes met by the last step: movable bone ids and unit axes (rows).
  std::vector<int> neutral_bones;
  Eigen::MatrixX3d neutral_axes;

  void set_neutral_modes(const std::vector<NeutralMode>& modes) {
    neutral_bones.clear();
    neutral_axes.resize(static_cast<Eigen::Index>(modes.size()), 3);
    for (size_t i = 0; i < modes.size(); ++i) {
      neutral_bones.push_back(modes[i].bone);
      neutral_axes.row(static_cast<Eigen::Index>(i)) = modes[i].axis.transpose();
    }
  }
};

}  // namespace emu
