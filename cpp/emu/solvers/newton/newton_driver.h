#pragma once
// The Newton loop, written once for both solvers.
//
// Each iteration: poll for an interrupt, ask the problem for a search
// direction, backtrack along it (Armijo), take the step, record it, test
// convergence. When no step lowers the energy, the full step is taken if the
// energy is unchanged to round-off and the gradient falls; otherwise the solve
// stops as "stalled". The problem decides everything that is specific to it:
// what the unknowns are, how the direction is computed (a Cholesky, CG), how a
// trial state is built (a linear step, a retraction to rotations).
//
// A Problem provides, at its current iterate:
//   double energy() const;          double grad_norm() const;
//   SearchDirection direction(int iteration, PhaseTimes& t);  // at the current iterate; adds
//                                               // its hessian / preconditioner / linear_solve seconds
//   double trial_energy(double s);              // energy at step s along it (non-finite: rejected)
//   double trial_grad_norm();                   // gradient norm at the last trial point (round-off rule)
//   double gradient_noise();                    // round-off of grad_norm() at the current iterate
//   double take_step(int iteration, double s, double E_trial);  // move to the step s of the last
//                                                               // trial_energy call; returns the new energy
//   const Eigen::MatrixX3d& positions() const;  // #V by 3 (only for SolverOptions::on_iteration)
#include <algorithm>
#include <string>

#include "emu/solvers/newton/convergence.h"
#include "emu/solvers/newton/line_search.h"
#include "emu/solvers/newton/result.h"
#include "emu/solvers/newton/step_test.h"
#include "emu/solvers/newton/stopwatch.h"
#include "emu/solvers/solver_options.h"

namespace emu {

struct SearchDirection {
  bool ok = true;
  std::string failure;  // why no direction could be found (the solve's status)
  double slope = 0;     // g . d (< 0 for a descent direction)
  int cg_iterations = 0;
  int filtered = 0;        // 1 if the step fell back to the PSD-filtered Hessian
  int exact_failed = 0;    // failed factorisations of the exact Hessian
  int factorizations = 0;  // sparse Cholesky factorisations made for it
  int negative_curvature = 0;  // 1 if it includes a negative-curvature direction (FEM at a saddle)
  bool cg_cut = false;     // CG was cut short where it stalled: not a Newton step, no step test on it
  /// This direction marked as failed (its counters kept for the result).
  SearchDirection& fail(std::string why) {
    ok = false;
    failure = std::move(why);
    return *this;
  }
};

/// The gradient's round-off is measured at the iterates in the endgame:
/// |g| <= max(kNoiseFrom |g_0|, kNoiseBand rtol_grad |g_0|).
constexpr double kNoiseFrom = 1e-3, kNoiseBand = 100.0;

/// The line search along d from the problem's iterate (energy E): Armijo
/// backtracking, or where no step lowers the energy the full step when the
/// energy is unchanged to round-off and the gradient falls. False: no step;
/// res.status says why (a stall, or the gradient at its round-off: converged).
template <class Problem>
bool line_search_along(Problem& p, const SearchDirection& d, double E, double E0, const SolverOptions& o,
                       LineSearchResult& ls, SolveResult& res) {
  {
    ScopedSeconds timer(res.phases.line_search);
    ls = armijo_backtracking([&](double s) { return p.trial_energy(s); }, E, d.slope, o);
  }
  if (ls.success) return true;
  const double E1 = p.trial_energy(1.0);
  if (accept_at_roundoff(E1, p.trial_grad_norm(), E, p.grad_norm(), E0)) {
    ls.success = true;
    ls.step = 1.0;
    ls.energy = E1;
    return true;
  }
  // a warm start whose |g_0| is near the round-off never enters the
  // endgame band: its stall is measured here
  if (o.noise_factor > 0 && p.grad_norm() <= o.noise_factor * p.gradient_noise()) {
    res.converged = true;
    res.status = "converged: the gradient is at its round-off level";
    return false;
  }
  res.status = "stalled: no step along the search direction decreases the energy or the gradient "
               "(round-off level reached; loosen rtol_grad / rtol_energy)";
  return false;
}

/// The direction's counters into the result; false (res.status its failure) where it failed.
inline bool count_direction(const SearchDirection& d, SolveResult& res) {
  res.filtered_steps += d.filtered;
  res.exact_attempts_failed += d.exact_failed;
  res.factorizations += d.factorizations;
  res.negative_curvature_steps += d.negative_curvature;
  if (!d.ok) res.status = d.failure;
  return d.ok;
}

/// Minimises the problem from its current iterate; fills every field of res
/// but positions, F and the neutral modes (the problem's own output).
/// floor: the round-off level of the gradient norm; start_floor: a start
/// below it is converged (see Convergence); cold_g0: |g| at the problem's
/// cold start (rest) when this solve is warm-started with
/// SolverOptions::step_tol_cold_scale, else 0. The step test's gate |g| <=
/// step_tol_grad g_ref uses g_ref = max(|g_0|, cold_g0): "near equilibrium"
/// on the scale of the load, as for a cold solve, not relative to a warm
/// start's already small |g_0| (which would make a start close to the answer
/// solve 1 / step_tol_grad times tighter than a cold one). Its first step may then
/// be a loose one (Eisenstat-Walker's 0.5 against the warm |g_0|): accuracy
/// mode's error estimate checks the answer (docs/DESIGN.md, "The gate of a
/// warm start").
template <class Problem>
void newton_minimize(Problem& p, const SolverOptions& o, double floor, Clock::time_point t0, SolveResult& res,
                     double start_floor = 0.0, double cold_g0 = 0.0) {
  double E = p.energy();
  Convergence conv{o.rtol_grad, o.rtol_energy, E, p.grad_norm(), floor};
  conv.start_floor = start_floor;
  res.grad_norm0 = conv.g0;
  res.history.push_back({0, E, conv.g0, 0.0, seconds_since(t0), 0, 0});
  res.status = "max iterations reached";
  // The caller sees every iterate (the start included); returning true stops
  // a solve that has not converged.
  auto stop_requested = [&] {
    if (!o.on_iteration || !o.on_iteration(res.history.back(), p.positions()) || res.converged) return false;
    res.status = "stopped by on_iteration";
    return true;
  };
  if (conv.initial()) {
    res.converged = true;
    res.status = "converged: initial state is in equilibrium";
  }
  bool stopped = stop_requested();
  Eigen::MatrixX3d x_prev;  // for the step_tol test
  StepTest step_test;
  for (int it = 1; !res.converged && !stopped && it <= o.max_iterations; ++it) {
    if (o.interrupted && o.interrupted()) {
      res.status = "interrupted";
      break;
    }
    const SearchDirection d = p.direction(it, res.phases);
    LineSearchResult ls;
    if (!count_direction(d, res) || !line_search_along(p, d, E, conv.E0, o, ls, res)) break;
    const double E_prev = E;
    if (o.step_tol > 0) x_prev = p.positions();
    {
      ScopedSeconds timer(res.phases.step);
      E = p.take_step(it, ls.step, ls.energy);
    }
    const double gn = p.grad_norm();
    res.iterations = it;
    res.cg_iterations += d.cg_iterations;
    res.history.push_back({it, E, gn, ls.step, seconds_since(t0), d.cg_iterations, ls.backtracks});
    // In the endgame the gradient's measured round-off joins the floor: a
    // gradient within noise_factor of it is as good as zero (further steps
    // chase rounding errors; docs/DESIGN.md, "The gradient's round-off").
    const double tol = o.rtol_grad * conv.g0;
    if (o.noise_factor > 0 && gn > tol && gn > conv.floor && gn <= std::max(kNoiseFrom * conv.g0, kNoiseBand * tol))
      conv.floor = std::max(conv.floor, o.noise_factor * p.gradient_noise());
    if (conv.test(E_prev, E, gn)) {
      res.converged = true;
      res.status = gn > tol ? "converged: the gradient is at its round-off level" : "converged";
    } else if (o.step_tol > 0 &&
               step_test.passes(o, d.filtered == 0, (p.positions() - x_prev).rowwise().norm().maxCoeff(),
                                ls.step == 1.0 && !d.cg_cut, gn, std::max(conv.g0, cold_g0))) {
      res.converged = true;
      res.status = "converged: a full step moved no vertex by more than step_tol";
    }
    stopped = stop_requested();
  }
  res.energy = E;
  res.grad_norm = res.history.back().grad_norm;
  res.rel_energy_change = conv.rel_energy_change;
}

}  // namespace emu
