#pragma once
// The linear algebra of one EMU Newton step, apart from the iterate it serves:
// the Hessian's blocks and the preconditioner built on them (refreshed when
// due), contact's Hessian, the bone coarse space (in joint coordinates, the
// joints' turns) and the step's direction by its kind (Woodbury,
// L-BFGS, or PCG to Eisenstat-Walker's forcing), with CG's recycled directions
// and L-BFGS's memory kept across steps. Private to emu_solver.cpp
// (EmuSolver::NewtonProblem holds one).
#include <array>
#include <vector>

#include <Eigen/Sparse>

#include "emu/solvers/emu/bone_coarse_space.h"
#include "emu/solvers/emu/emu_solver.h"
#include "emu/solvers/newton/lbfgs.h"
#include "emu/solvers/newton/newton_driver.h"
#include "emu/solvers/newton/pcg.h"

namespace emu {

class EmuSolver::StepSolver {
 public:
  /// CG is cut at max(kCgStallMin, kCgStallRatio x the last step's CG) where
  /// the coarse space learns modes (step_solver.cpp, stall_limit).
  static constexpr int kCgStallMin = 30, kCgStallRatio = 2;
  /// The problem's iterate F, its Euclidean and Riemannian gradients g, gR
  /// with |gR| now and at the start (gn, g0), and the direction d it reads:
  /// kept by reference (the problem's members, updated in place).
  StepSolver(EmuSolver& s, const Context& c, const Mat9X& F, const Mat9X& g, const Mat9X& gR, const double& gn,
             const double& g0, Mat9X& d);

  /// d = the step's direction at the iterate (positions x for contact's
  /// Hessian), with H's exact blocks where `exact`; dir's counters and slope.
  /// False: dir has failed.
  bool direction(int it, bool exact, const Eigen::MatrixX3d& x, SearchDirection& dir, PhaseTimes& time);
  /// After the step s d: CG's count for the refresh rule; for L-BFGS the
  /// pair (s d, dgR), dgR the change of the tangent gradient.
  void stepped(double s, int cg_iterations, const Mat9X& dgR);
  const std::vector<NeutralMode>& neutral_modes() const { return coarse_.neutral_modes(); }

 private:
  bool refresh_blocks(int it, bool exact, SearchDirection& dir, PhaseTimes& time, bool& refreshed);
  void hessian_product(const std::vector<Mat9>& H, bool exact, const Mat9X& v, Mat9X& out) const;
  template <class Product>
  void build_coarse_space(const std::vector<Mat9>& H, bool exact, const Product& product);
  template <class Product>
  bool step_direction(const Product& product, SearchDirection& dir);
  void recycle(const Mat9X& d);
  bool learns_modes() const;
  int stall_limit() const;
  void precondition(const Mat9X& in, Mat9X& out) const;

  EmuSolver& s_;
  const Context& c_;
  const bool bones_;
  const Mat9X &F_, &g_, &gR_;
  const double &gn_, &g0_;
  Mat9X& d_;
  std::vector<Mat9> A_, A_exact_;
  Eigen::SparseMatrix<double> Hc_;  // the position terms' Hessian at the iterate (3 #V square)
  int since_refresh_ = 0, cg_after_refresh_ = -1, last_cg_ = 0;
  BoneCoarseSpace coarse_;
  std::vector<Mat9X> recycled_;
  Pcg<Mat9X> pcg_;
  LbfgsMemory<Mat9X> lbfgs_;
};

}  // namespace emu
