#pragma once
// The reference: Newton on vertex positions with PSD-projected element
// Hessians, assembled deterministically into a fixed pattern and factorised
// by CHOLMOD every iteration (symbolic analysis once), Armijo backtracking.
//
// Movable bones are rigid bodies (rigid_bones.h): exponential-map increments
// re-linearised every iteration, their rows bordering the soft-vertex matrix
// (one factorisation of the soft block, one back-substitution per bone unknown
// and a small dense Schur complement per iteration).
#include <memory>

#include <Eigen/SparseCore>
#include <string>
#include <utility>
#include <vector>

#include "emu/linalg/cholmod_factor.h"
#include "emu/linalg/merged_pattern_factor.h"
#include "emu/mesh/block_pattern.h"
#include "emu/contact/position_term.h"
#include "emu/model/unknown_layout.h"
#include "emu/solvers/newton/result.h"
#include "emu/solvers/fem/rigid_bones.h"
#include "emu/solvers/solver_options.h"

namespace emu {

class FemSolver {
 public:
  /// contact  barriers on the positions, added to the energy, gradient and
  ///          Newton matrix, every step capped by continuous collision
  ///          detection (an inactive term: none)
  FemSolver(const Model& model, const SolverOptions& options, PositionTerm contact = {});
  // Its parts hold references to the model and layout it owns: not copied or moved.
  FemSolver(const FemSolver&) = delete;
  FemSolver& operator=(const FemSolver&) = delete;

  /// initial  #V by 3 start positions (nullptr: rest); pinned rows are replaced by the load's.
  SolveResult solve(const LoadCase& load, const Eigen::MatrixX3d* initial = nullptr);

  /// Which Newton matrix newton_correction uses: the exact one (where it is
  /// definite), the PSD-filtered one, or both and the step that ends at the
  /// lower FEM energy (the best estimate of EMU's error; docs/DESIGN.md,
  /// "EMU's error estimate").
  /// LaggedNewton: the exact Newton step by PCG on the last factorisation only,
  /// nothing factorised; where that PCG fails no step (accuracy mode's cheap
  /// corrections, which only Newton's regime can certify).
  /// Newton: the exact Newton step, by PCG on the last factorisation where it
  /// converges, else by a factorisation; where the exact matrix is not
  /// definite no step (never the filtered one: the certificate's and
  /// accuracy mode's corrections compare Newton steps).
  enum class CorrectionHessian { Exact, Filtered, LowerEnergy, LaggedNewton, Newton };

  /// Positions after full Newton steps of the FEM energy from x0 (#V by 3;
  /// each bone first at the best rigid fit of its rows): the linearised
  /// correction of an approximate equilibrium such as EMU's, whose distance to
  /// x0 estimates x0's distance to the FEM equilibrium. A step that had to use
  /// the filtered matrix (x0 is not yet in Newton's regime) is followed by
  /// another, up to max_steps. Per step a factorisation of the exact matrix
  /// and, where it is not definite, of the filtered one (with movable bones
  /// first with the bones' exact rotation term, then without; diagonal shifts
  /// where even that fails); with a lagged factor
  /// (SolverOptions::lagged_cg_iterations) PCG on it first, and where that PCG
  /// meets negative curvature the exact matrix is known to be indefinite: no
  /// factorisation of it is tried. Where the gradient is at its round-off
  /// floor (FEM's solve would stop at once) no step is taken and nothing is
  /// factorised. Throws std::runtime_error if no Newton direction exists.
  Eigen::MatrixX3d newton_correction(const LoadCase& load, const Eigen::MatrixX3d& x0,
                                     CorrectionHessian hessian = CorrectionHessian::LowerEnergy,
                                     int max_steps = 1);

  /// Called with every iterate of the following solves (see SolverOptions::on_iteration); empty: none.
  void set_on_iteration(std::function<bool(const IterationRecord&, const Eigen::MatrixX3d&)> f) {
    options_.on_iteration = std::move(f);
  }

  double setup_seconds() const { return setup_seconds_; }
  /// The structures this solver built and their bytes (see EmuSolver::structures).
  std::vector<std::pair<std::string, double>> structures() const;
  /// The model as this solver stores it (tets along_curve, tet_order.h).
  const Model& model() const { return model_; }
  double factor_nnz() const { return factor_.factor_nnz(); }
  double factorization_flops() const { return factor_.factorization_flops(); }
  /// Numeric factorisations of the Newton matrix so far (solves and corrections).
  int factorizations() const { return factorizations_; }
  /// PCG iterations on the lagged factor so far (solves and corrections).
  long pcg_iterations() const { return pcg_iterations_; }
  /// With SolverOptions::lagged_refresh: PCG iterations past which the lagged factor has aged.
  int refresh_iterations() const { return refresh_iterations_; }

 private:
  class NewtonProblem;  // one solve's problem, as the Newton driver minimises it (fem_solver.cpp)
  class StepSolver;     // the linear algebra of its steps (step_solver.h)
  friend struct FemSolverTesting;  // the pieces one at a time, for tests (fem_solver_testing.h)
  /// The free rows of the gradient (3 #free) at x; fills the corner forces that vertex_forces reads.
  void free_gradient(const LoadCase& load, const Eigen::MatrixX3d& x, const Eigen::VectorXd& act,
                     Eigen::VectorXd& g) const;
  /// The elastic energy less gravity's work plus the step's inertia (load.inertia_weight > 0) at x.
  double energy_with(const Eigen::MatrixX3d& x, const Eigen::VectorXd& act, const LoadCase& load) const;
  /// The load's inertia for the following assemblies (assemble_hessian, the bones' border).
  void set_inertia(const LoadCase& load);
  /// Element Hessians (144 per tet) at x and the assembled soft block.
  void assemble_hessian(const Eigen::MatrixX3d& x, const Eigen::VectorXd& act, bool exact);
  /// dE/dx at the vertices that move with a bone, from the corner forces of the
  /// last free_gradient call, gravity and the inertia at positions x (#V by 3, zero elsewhere).
  void vertex_forces(const LoadCase& load, const Eigen::MatrixX3d& x, Eigen::MatrixX3d& f) const;
  /// The round-off level of the gradient norm (see Convergence).
  double gradient_floor(const Eigen::VectorXd& act) const;

  // Contact: its energy and gradient at x (0 / zero
  // rows without contact) and the Newton matrix with its Hessian.
  bool has_contact() const { return contact_.active(); }
  /// Whether steps and corrections run PCG on the lagged factor (it exists, has not aged, no contact).
  bool lagged_usable() const {
    return options_.lagged_cg_iterations > 0 && lag_.valid && !lag_.aged && !has_contact();
  }
  double contact_energy(const Eigen::MatrixX3d& x) const;
  Eigen::MatrixX3d contact_gradient(const Eigen::MatrixX3d& x) const;
  /// contact_H_ = the contact Hessian at x, and contact_soft_ its free-vertex
  /// block in the soft rows (upper triangle).
  void set_contact_hessian(const Eigen::MatrixX3d& x);
  /// Factorises the soft block values_ (+ contact_soft_ where it has entries, on
  /// the merged pattern, analysed again when that changes); false if it is not
  /// positive definite. newton_factor() is the factor it used.
  bool factorize_newton_matrix();
  const CholmodFactor& newton_factor() const { return use_merged_ ? merged_factor_.factor() : factor_; }

  Model model_;
  UnknownLayout layout_;
  SolverOptions options_;
  PositionTerm contact_;
  BlockPattern pattern_;
  CholmodFactor factor_;
  RigidBones bones_;
  std::vector<double> element_, values_;
  std::vector<int> diagonal_;  // 3 #free: where each free row's diagonal entry is in values_
  double inertia_weight_ = 0;  // set_inertia: w of the load being solved (0: none)
  Eigen::SparseMatrix<double> bone_inertia_;  // its Hessian at the bones' vertices (3 #V square, diagonal)
  mutable std::vector<double> corner_, tet_energy_;
  // The last successful factorisation, kept as Newton-CG's preconditioner
  // (SolverOptions::lagged_cg_iterations) across steps and solves: the factor
  // is factor_; with movable bones also its border Hsb, K^-1 Hsb and the
  // inverse of its bone Schur complement.
  struct LaggedFactor {
    bool valid = false;
    bool aged = false;  // its last PCG took over refresh_iterations_: the next step factorises
    Eigen::MatrixXd Hsb, Wsb, S_inv;
  };
  LaggedFactor lag_;
  Eigen::SparseMatrix<double> contact_H_, contact_soft_;
  MergedPatternFactor merged_factor_;  // soft block + contact, on the merged pattern
  bool use_merged_ = false;
  int factorizations_ = 0;  // numeric factorisations of the Newton matrix so far
  int refresh_iterations_ = 0;  // SolverOptions::lagged_refresh's threshold, from the factor's size
  long pcg_iterations_ = 0;  // PCG iterations on the lagged factor so far
  double setup_seconds_ = 0;
};

}  // namespace emu
