#pragma once
// EMU: the same energy as FEM with one deformation gradient per tet as the
// unknowns; positions are the ACAP fit x*(F) through one prefactored matrix.
//
//   E(F) = sum_t V_t Psi_t(F_t) + alpha/2 sum_t w_t V_t |F_t(x*) - F_t|^2 - W(x*)
//   dE/dF_t = V_t P_t(F_t) + alpha w_t V_t (F_t - F_t(x*)) - w_t V_t F_t(L^-1 f)
// (envelope theorem for the coupling term; the load term needs one extra
// constant solve with the gravity forces f).
//
// Steps: the paper's Woodbury quasi-Newton step, or Newton-Krylov: conjugate
// gradients on the exact Hessian H v = A v - alpha C^T K_c^-1 C v (one
// back-substitution per product), preconditioned by the Woodbury step.
// Never a factorisation after setup.
//
// Movable bones: all tets of bone b share one unknown F_b, kept a rotation
// (rigid: no elastic energy); steps, retraction and the Riemannian Hessian
// on SO(3) are in bone_rotations.h. The gradient norm reported and tested is the Riemannian one (bone blocks
// projected to the tangent space): the normal part is the rigidity reaction.
//
// Unknowns: one per soft tet (tet order), then one per bone. The pieces one
// at a time (energy, gradient, Hessian products, preconditioner solves) are
// in emu_solver_testing.h, for tests and benchmarks.
#include <array>
#include <memory>

#include <Eigen/SparseCore>
#include <string>
#include <utility>

#include "emu/linalg/modes.h"
#include "emu/contact/position_term.h"
#include "emu/model/unknown_layout.h"
#include "emu/solvers/emu/acap.h"
#include "emu/solvers/emu/block_preconditioner.h"
#include "emu/solvers/emu/bone_turn_fits.h"
#include "emu/solvers/emu/fit_jacobian.h"
#include "emu/solvers/emu/joint_coordinates.h"
#include "emu/solvers/newton/result.h"
#include "emu/solvers/solver_options.h"

namespace emu {

class EmuSolver {
 public:
  /// contact  barriers on the fitted positions x*(F) (an inactive term: none)
  EmuSolver(const Model& model, const SolverOptions& options, const EmuSolverOptions& emu_options,
            PositionTerm contact = {});
  // Its parts hold references to the model and layout it owns: not copied or moved.
  EmuSolver(const EmuSolver&) = delete;
  EmuSolver& operator=(const EmuSolver&) = delete;

  /// F0  start: one F per tet of the scene (Model::scene_tet_count() by 9, F
  ///     row-major per row, as SolveResult::F); a bone's F is read from its
  ///     first tet, a tet without unknowns ignored; nullptr: identity
  SolveResult solve(const LoadCase& load, const Eigen::MatrixXd* F0 = nullptr);

  /// Called with every iterate of the following solves (see SolverOptions::on_iteration); empty: none.
  void set_on_iteration(std::function<bool(const IterationRecord&, const Eigen::MatrixX3d&)> f) {
    options_.on_iteration = std::move(f);
  }

  /// The ACAP modes of the Woodbury preconditioner (0 with another one).
  int modes() const { return modes_; }
  double alpha() const { return emu_.alpha; }
  /// A new (absolute) alpha for the following solves. The ACAP matrix and its
  /// modes do not depend on alpha; the constant Schur preconditioner's S0
  /// does, and is factorised again.
  void set_alpha(double alpha);
  /// The Eisenstat-Walker cap eta_max for the following solves (0 < eta_max < 1).
  void set_cg_forcing_max(double eta_max);
  double cg_forcing_max() const { return emu_.cg_forcing_max; }
  double factor_seconds() const { return factor_seconds_; }
  double modes_seconds() const { return modes_seconds_; }
  double setup_seconds() const { return factor_seconds_ + modes_seconds_; }
  /// The structures this solver built for its scene and their bytes (the
  /// per-solve work arrays aside): what a scene without bones, joints or a
  /// Schur preconditioner does not pay for is not listed.
  std::vector<std::pair<std::string, double>> structures() const;
  double factor_nnz() const { return acap_->factor().factor_nnz(); }
  /// The model as this solver stores it (tets along_curve, tet_order.h).
  const Model& model() const { return model_; }
  int num_unknowns() const { return layout_.num_unknowns; }
  /// The F unknown each tet of model() uses (#T; see UnknownLayout).
  const Eigen::VectorXi& tet_unknown() const { return layout_.tet_unknown; }
  /// How movable bones turn: "joint coordinates" (a hinge joins two movable
  /// bones), "per bone: <why>" (no such hinge, a loop or weld of joints, or
  /// EmuSolverOptions::joint_coordinates off), "" without bones.
  const std::string& bone_coordinates() const { return bone_coordinates_; }
  /// Why the movable bones form no tree of joints (a loop, or two bones
  /// welded), as BoneForest says; "" for a tree or without bones. FEM, and so
  /// EMU's error estimate, takes trees only.
  const std::string& bone_forest_error() const { return bone_forest_error_; }

 private:
  struct Context {  // per-load data: activations, pinned share of F, joint targets, gravity terms
    Eigen::VectorXd act;         // #T activation
    Eigen::MatrixX3d x_pinned;   // #V by 3: pinned rows at targets, other rows zero
    Mat9X F_pinned;              // F_t(x_pinned)
    Eigen::MatrixX3d h;          // joint targets
    Eigen::Vector3d gravity = Eigen::Vector3d::Zero();
    bool has_gravity = false;
    Mat9X F_gravity;             // F_t(L^-1 f): the load's share of the gradient
    double inertia_weight = 0;   // a time step's inertia (LoadCase; 0: none)
    Eigen::MatrixX3d inertia_target;
    Eigen::SparseMatrix<double> inertia_hessian;  // its constant Hessian (3 #V square, diagonal)
  };
  class NewtonProblem;  // one solve's problem, as the Newton driver minimises it (emu_solver.cpp)
  class StepSolver;     // the linear algebra of its steps (step_solver.h)
  friend struct EmuSolverTesting;  // the pieces one at a time, for tests and benchmarks (emu_solver_testing.h)
  /// Setup: the preconditioner EmuSolverOptions choose (with the ACAP modes for Woodbury's).
  void build_preconditioner();
  /// The ks lowest scalar modes of the ACAP operator K (with movable bones, of K_c^-1 by its solves).
  Modes acap_modes(int ks) const;
  Context make_context(const LoadCase& load) const;
  /// The round-off level of the gradient norm (see Convergence).
  double gradient_floor(const Context& c) const;
  /// Apply the preconditioner without the bone coarse correction (tangent-projected).
  void base_precondition(const Mat9X& F, const Mat9X& in, Mat9X& out) const;
  /// The work of the load at positions x (0 without gravity).
  double load_work(const Context& c, const Eigen::MatrixX3d& x) const;
  /// |g| (tangent-projected, without contact) at the cold start F = I under
  /// c's load: the step test's scale for a warm-started solve
  /// (newton_minimize), and at rest the gradient's round-off.
  double cold_gradient_norm(const Context& c) const;
  /// The start unknowns (9 x #unknowns) from F0 in the scene's rows (see solve; nullptr: identity).
  Mat9X start_unknowns(const Eigen::MatrixXd* F0) const;
  /// F (9 x #unknowns) as one row per tet of the scene (F row-major; identity
  /// where a tet has no unknown): SolveResult::F.
  Eigen::MatrixXd scene_rows(const Mat9X& F) const;
  // F: 9 x #unknowns; Fx, Fd: 9 x #T (F_t of the fit).
  double energy_along(const Context& c, const Mat9X& F, const Mat9X& Fx, const Mat9X* D,
                      const Mat9X* Fd, double s) const;
  /// The total energy at F (Fx: the F_t of its fit x): energy_along's terms
  /// (elastic, ACAP coupling, bone springs) minus the load's work plus contact;
  /// summed here only (a straight trial line sums the same terms linearised).
  double total_energy(const Context& c, const Mat9X& F, const Mat9X& Fx, const Eigen::MatrixX3d& x) const;
  void gradient_into(const Context& c, const Mat9X& F, const Mat9X& Fx, Mat9X& g) const;
  void blocks_into(const Context& c, const Mat9X& F, std::vector<Mat9>* A, std::vector<Mat9>* A_exact) const;
  void hessian_product_into(const std::vector<Mat9>& A, const Mat9X& v, Mat9X& out) const;
  /// The same with v's fit given: Fd (9 x #T) = F_t(x*(v)).
  void hessian_product_from_fit(const std::vector<Mat9>& A, const Mat9X& v, const Mat9X& Fd, Mat9X& out) const;
  void fit_into(const Context& c, const Mat9X& F, Eigen::MatrixX3d& x, Mat9X& Fx) const;
  void fit_linear_into(const Mat9X& D, Eigen::MatrixX3d& dx, Mat9X& Fd) const;
  // Bones on SO(3) (bone_rotations.h), in joint coordinates where the joints
  // form a forest (joint_coordinates.h): projection of v's bone columns onto
  // the tangents at F; F + s d retracted to rotations; the Riemannian Hessian
  // product (with the chain's curvature where `curvature`).
  void project_tangent(const Mat9X& F, Mat9X& v) const;
  void retract(const Mat9X& F, const Mat9X& d, double s, Mat9X& out) const;
  void riemannian_product(const std::vector<Mat9>& A, const Mat9X& F, const Mat9X& g, const Mat9X& v,
                          bool curvature, Mat9X& out) const;
  /// out's bone columns (holding the Euclidean H v) made the Riemannian product's.
  void riemannian_bone_columns(const Mat9X& F, const Mat9X& g, const Mat9X& v, bool curvature, Mat9X& out) const;
  /// Setup: joint coordinates where the movable bones' joints form a forest.
  void set_bone_coordinates();
  Mat9X to_cols(const Eigen::MatrixXd& rows) const;
  // Terms of the fitted positions x = x*(F), through the fit's chain rule
  // (fit_jacobian.h): contact, and a time step's inertia (energy/inertia.h).
  bool has_contact() const { return contact_.active(); }
  double contact_energy(const Eigen::MatrixX3d& x) const { return has_contact() ? contact_.energy(x) : 0.0; }
  bool has_position_terms(const Context& c) const { return has_contact() || c.inertia_weight > 0; }
  /// Their energy at the fit x.
  double position_energy(const Context& c, const Eigen::MatrixX3d& x) const;
  /// g += their dE/dF at the fit x.
  void add_position_gradient(const Context& c, const Eigen::MatrixX3d& x, Mat9X& g) const;
  /// Their Hessian in positions at the fit x (3 #V square; contact's PSD one, the inertia's diagonal).
  Eigen::SparseMatrix<double> position_hessian(const Context& c, const Eigen::MatrixX3d& x) const;

  Model model_;
  UnknownLayout layout_;
  SolverOptions options_;
  EmuSolverOptions emu_;
  PositionTerm contact_;
  std::unique_ptr<AcapOperator> acap_;
  std::unique_ptr<FitJacobian> jacobian_;  // the chain rule through acap_'s fit
  std::unique_ptr<BlockPreconditioner> preconditioner_;  // EmuSolverOptions::preconditioner's (block_preconditioner.h)
  int modes_ = 0;
  double factor_seconds_ = 0, modes_seconds_ = 0;
  // |g| at the exact rest equilibrium (F = I, no load) per unit alpha: the
  // round-off of the fit, which the ACAP matrix's conditioning (bone weights
  // 1e4) lifts above gradient_floor's scale estimate: a start below 10x it is
  // converged. Only the start: as a floor for every iterate it stops large-alpha
  // solves too early (docs/DESIGN.md, "Stopping and round-off").
  double rest_gradient_per_alpha_ = 0;
  mutable std::vector<double> tet_energy_;
  std::unique_ptr<BoneTurnFits> turn_fits_;  // movable bones with the coarse space, else empty
  std::unique_ptr<JointCoordinates> joints_;  // movable bones in a forest of joints, else per-bone rotations
  std::string bone_coordinates_;
  std::string bone_forest_error_;
};

}  // namespace emu
