#pragma once
// EmuSolver's pieces one at a time, for tests, diagnostics and the CG
// microbenchmark: not part of the solver's interface (the Python bindings put
// them in _core.testing). F, V, R are #unknowns by 9 (vec(F) column-major per
// row: the soft tets in the solver's order, then one per movable bone);
// gradient and hessian_product are Euclidean (no tangent projection).
#include <array>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "emu/solvers/emu/emu_solver.h"
#include "emu/solvers/emu/woodbury.h"

namespace emu {

struct EmuSolverTesting {
  static double energy(const EmuSolver& s, const LoadCase& load, const Eigen::MatrixXd& F);
  static Eigen::MatrixXd gradient(const EmuSolver& s, const LoadCase& load, const Eigen::MatrixXd& F);
  /// x*(F), #V by 3.
  static Eigen::MatrixX3d fit_positions(const EmuSolver& s, const LoadCase& load, const Eigen::MatrixXd& F);
  /// The Hessian times V: material blocks PSD-filtered, or unfiltered with exact = true
  /// (with contact, plus J^T H_c J V: the contact Hessian as the term gives it).
  static Eigen::MatrixXd hessian_product(const EmuSolver& s, const LoadCase& load, const Eigen::MatrixXd& F,
                                         const Eigen::MatrixXd& V, bool exact = false);
  /// The Riemannian Hessian times V as Newton-Krylov's CG applies it (bones on
  /// SO(3), in joint coordinates where the solver uses them: V projected, the
  /// chain's curvature with exact = true); no contact.
  static Eigen::MatrixXd riemannian_hessian_product(const EmuSolver& s, const LoadCase& load,
                                                    const Eigen::MatrixXd& F, const Eigen::MatrixXd& V,
                                                    bool exact = false);
  /// V's bone rows projected onto the tangents at F (joint-consistent ones in joint coordinates).
  static Eigen::MatrixXd project_tangent(const EmuSolver& s, const Eigen::MatrixXd& F, const Eigen::MatrixXd& V);
  /// F moved by step D: the solver's retraction (bones kept rotations and, in joint coordinates, on their joints).
  static Eigen::MatrixXd retract(const EmuSolver& s, const Eigen::MatrixXd& F, const Eigen::MatrixXd& D,
                                 double step);
  /// Blocks A_u, #unknowns by 81 (column-major 9x9 per row); filtered unless exact.
  static Eigen::MatrixXd block_hessians(const EmuSolver& s, const LoadCase& load, const Eigen::MatrixXd& F,
                                        bool exact = false);
  /// H_k^-1 R with the solver's k modes.
  static Eigen::MatrixXd woodbury_solve(const EmuSolver& s, const LoadCase& load, const Eigen::MatrixXd& F,
                                        const Eigen::MatrixXd& R);
  /// H^-1 R through the Schur-complement preconditioner (the exact inverse of
  /// the filtered Hessian), refactorised at F; a solver built with preconditioner = Schur.
  static Eigen::MatrixXd schur_solve(EmuSolver& s, const LoadCase& load, const Eigen::MatrixXd& F,
                                     const Eigen::MatrixXd& R);
  /// M^-1 R through the constant Schur complement S0 (constant_schur.h), blocks
  /// A_u at F; a solver built with preconditioner = ConstantSchur.
  static Eigen::MatrixXd constant_schur_solve(EmuSolver& s, const LoadCase& load, const Eigen::MatrixXd& F,
                                              const Eigen::MatrixXd& R);
  /// The inertia weight the constant Schur preconditioner's S0 holds (set by each solve).
  static double constant_schur_inertia(const EmuSolver& s);
  /// The bone coarse space's turn of movable bone `bone` by the tangent M
  /// (3x3, W R for a turn W of the bone's rotation R) with the soft tissue
  /// following (bone_coarse_space.h): Z (M on the bone, the soft F_t of the
  /// fitted positions, other bones 0) and the Euclidean H Z at F (filtered
  /// blocks unless exact; no contact term), from the bone's unit-turn fits.
  static std::pair<Eigen::MatrixXd, Eigen::MatrixXd> bone_turn(const EmuSolver& s, const LoadCase& load,
                                                               const Eigen::MatrixXd& F, int bone,
                                                               const Eigen::Matrix3d& M, bool exact = false);
  /// The same for three tangents at once, as the coarse space's rebuild forms them.
  static std::array<std::pair<Eigen::MatrixXd, Eigen::MatrixXd>, 3> bone_turns(
      const EmuSolver& s, const LoadCase& load, const Eigen::MatrixXd& F, int bone,
      const std::array<Eigen::Matrix3d, 3>& M, bool exact = false);
  /// The Woodbury preconditioner's B and Lambda (a solver built with preconditioner = Woodbury).
  static Eigen::MatrixXd mode_matrix(const EmuSolver& s) { return woodbury_of(s).dense_B(); }
  static Eigen::VectorXd mode_values(const EmuSolver& s) { return woodbury_of(s).lambda(); }

  // The kernels of a CG iteration (bench/micro/bench_cg.cpp).
  static const Model& model(const EmuSolver& s) { return s.model_; }
  static const UnknownLayout& layout(const EmuSolver& s) { return s.layout_; }
  static AcapOperator& acap(EmuSolver& s) { return *s.acap_; }
  static Woodbury& woodbury(EmuSolver& s) { return woodbury_of(s); }
  static void hessian_product_into(const EmuSolver& s, const std::vector<Mat9>& A, const Mat9X& v, Mat9X& out) {
    s.hessian_product_into(A, v, out);
  }
  static void fit_linear_into(const EmuSolver& s, const Mat9X& D, Eigen::MatrixX3d& dx, Mat9X& Fd) {
    s.fit_linear_into(D, dx, Fd);
  }

 private:
  static Woodbury& woodbury_of(const EmuSolver& s);
  template <class Preconditioner>
  static Eigen::MatrixXd preconditioner_solve(EmuSolver& s, Preconditioner& pc, const LoadCase& load,
                                              const Eigen::MatrixXd& F, const Eigen::MatrixXd& R, const char* not_spd);
  template <int N>
  static std::array<std::pair<Eigen::MatrixXd, Eigen::MatrixXd>, N> turns_at(const EmuSolver& s, const LoadCase& load,
                                                                             const Eigen::MatrixXd& F, int bone,
                                                                             const std::array<Mat3, N>& M, bool exact);
};

}  // namespace emu
