#include "emu/solvers/fem_solver.h"

#include <chrono>
#include <cmath>

#include "emu/energy/material.h"

namespace emu {
namespace {
using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}
double bbox_diagonal(const Eigen::MatrixX3d& X) {
  return (X.colwise().maxCoeff() - X.colwise().minCoeff()).norm();
}
}  // namespace

FemSolver::FemSolver(const Model& model, const SolverOptions& options)
    : model_((model.validate(), model)),
      disc_(model_),
      options_(options),
      pattern_(model_.tets, disc_.free_index, disc_.num_free, 3) {
  const auto t0 = Clock::now();
  factor_.analyze(pattern_.rows(), pattern_.col_ptr().data(), pattern_.row_index().data());
  const Eigen::Index m = model_.tets.rows();
  element_.resize(m * 144);
  values_.resize(pattern_.nnz());
  corner_.resize(m * 12);
  tet_energy_.resize(m);
  setup_seconds_ = seconds_since(t0);
}

double FemSolver::energy_with(const Eigen::MatrixX3d& x, const Eigen::VectorXd& act,
                              const Eigen::Vector3d& grav) const {
  const Eigen::Index m = model_.tets.rows();
  const auto& geo = disc_.geometry;
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    const TetMaterial mat{model_.mu(t), model_.lambda(t), act(t), model_.fiber.row(t).transpose()};
    tet_energy_[t] = geo.volume(t) * material_energy(mat, deformation_gradient(geo.grad[t], x, model_.tets, t));
  }
  double E = 0;
  for (Eigen::Index t = 0; t < m; ++t) E += tet_energy_[t];  // fixed order: reproducible
  if (grav.squaredNorm() > 0) E -= (disc_.lumped_mass.transpose() * x).dot(grav.transpose());
  return E;
}

void FemSolver::free_gradient(const LoadCase& load, const Eigen::MatrixX3d& x,
                              const Eigen::VectorXd& act, Eigen::VectorXd& g) const {
  const Eigen::Index m = model_.tets.rows();
  const auto& geo = disc_.geometry;
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    const TetMaterial mat{model_.mu(t), model_.lambda(t), act(t), model_.fiber.row(t).transpose()};
    const Mat3 P = material_stress(mat, deformation_gradient(geo.grad[t], x, model_.tets, t));
    Eigen::Map<Vec12>(corner_.data() + t * 12) = geo.volume(t) * corner_vectors(geo.grad[t], P);
  }
  g.resize(disc_.num_free * 3);
  pattern_.gather(corner_.data(), 3, g.data());
  if (load.gravity.squaredNorm() > 0)
    for (Eigen::Index v = 0; v < model_.rest.rows(); ++v)
      if (disc_.free_index(v) >= 0) g.segment<3>(3 * disc_.free_index(v)) -= disc_.lumped_mass(v) * load.gravity;
}

void FemSolver::assemble_hessian(const Eigen::MatrixX3d& x, const Eigen::VectorXd& act, bool exact) {
  const EigenFilter filter = options_.eigen_filter == 1 ? EigenFilter::Abs : EigenFilter::Clamp;
  const Eigen::Index m = model_.tets.rows();
  const auto& geo = disc_.geometry;
#pragma omp parallel for schedule(static)
  for (Eigen::Index t = 0; t < m; ++t) {
    const TetMaterial mat{model_.mu(t), model_.lambda(t), act(t), model_.fiber.row(t).transpose()};
    const Mat3 F = deformation_gradient(geo.grad[t], x, model_.tets, t);
    const Mat9 H = exact ? material_hessian(mat, F) : material_hessian_psd(mat, F, filter);
    Eigen::Map<Mat12>(element_.data() + t * 144) = geo.volume(t) * position_hessian(geo.grad[t], H);
  }
  pattern_.assemble(element_.data(), values_.data());
}

double FemSolver::energy(const LoadCase& load, const Eigen::MatrixX3d& x) const {
  validate_load(model_, load);
  return energy_with(x, tet_activation(model_, load), load.gravity);
}

Eigen::MatrixX3d FemSolver::gradient(const LoadCase& load, const Eigen::MatrixX3d& x) const {
  validate_load(model_, load);
  Eigen::VectorXd g;
  free_gradient(load, x, tet_activation(model_, load), g);
  Eigen::MatrixX3d out = Eigen::MatrixX3d::Zero(x.rows(), 3);
  for (Eigen::Index v = 0; v < x.rows(); ++v)
    if (disc_.free_index(v) >= 0) out.row(v) = g.segment<3>(3 * disc_.free_index(v)).transpose();
  return out;
}

SolveResult FemSolver::solve(const LoadCase& load, const Eigen::MatrixX3d* initial) {
  validate_load(model_, load);
  const auto t0 = Clock::now();
  const Eigen::VectorXd act = tet_activation(model_, load);
  SolveResult res;
  Eigen::MatrixX3d x = pinned_positions(model_, load);
  if (initial) {
    if (initial->rows() != x.rows()) throw std::invalid_argument("initial positions have the wrong number of rows");
    for (Eigen::Index v = 0; v < x.rows(); ++v)
      if (disc_.free_index(v) >= 0) x.row(v) = initial->row(v);
  }
  const int nf = disc_.num_free;
  auto scatter = [&](const Eigen::VectorXd& d, double s, Eigen::MatrixX3d& out) {
    for (Eigen::Index v = 0; v < out.rows(); ++v)
      if (disc_.free_index(v) >= 0) out.row(v) += s * d.segment<3>(3 * disc_.free_index(v)).transpose();
  };
  double E = energy_with(x, act, load.gravity);
  Eigen::VectorXd g;
  free_gradient(load, x, act, g);
  // Round-off in P(F) scales with the largest modulus (lambda at nu near 0.5).
  const double force_scale =
      (disc_.geometry.volume.array() * (model_.mu.array() + model_.lambda.array() + act.array())).sum() /
      bbox_diagonal(model_.rest);
  Convergence conv{options_.rtol_grad, options_.rtol_energy, E, g.norm(), 1e-13 * force_scale};
  res.grad_norm0 = conv.g0;
  res.history.push_back({0, E, conv.g0, 0.0, seconds_since(t0), 0, 0});
  res.status = "max iterations reached";
  if (conv.initial()) {
    res.converged = true;
    res.status = "converged: initial state is in equilibrium";
  }
  Eigen::VectorXd d(nf * 3);
  Eigen::MatrixX3d trial(x.rows(), 3);
  bool last_exact_ok = true;
  for (int it = 1; !res.converged && it <= options_.max_iterations; ++it) {
    if (options_.interrupted && options_.interrupted()) {
      res.status = "interrupted";
      break;
    }
    // Newton with the true Hessian where it is definite (near a stable
    // equilibrium). A failed attempt costs a factorisation, so after one it is
    // retried only once the iteration is in the Newton regime (last step full).
    const bool try_exact = options_.exact_when_definite &&
                           (last_exact_ok || res.history.back().step == 1.0);
    if (try_exact) {
      assemble_hessian(x, act, true);
      if (factor_.factorize(values_.data())) {
        factor_.solve(g.data(), d.data(), 1);
        d = -d;
        if (g.dot(d) < 0) {
          last_exact_ok = true;
          goto have_direction;
        }
      }
      ++res.exact_attempts_failed;
      last_exact_ok = false;
    }
    ++res.filtered_steps;
    {
    assemble_hessian(x, act, false);
    bool ok = factor_.factorize(values_.data());
    // Projected element Hessians make H PSD; a pinned scene makes it definite.
    // Roundoff can still break the Cholesky: shift the diagonal and retry.
    double shift = 0;
    for (int retry = 0; !ok && retry < 8; ++retry) {
      double dmax = 0;
      for (int j = 0; j < pattern_.rows(); ++j) dmax = std::max(dmax, values_[pattern_.col_ptr()[j + 1] - 1]);
      const double add = (shift == 0 ? 1e-10 * dmax : shift * 9.0);
      for (int j = 0; j < pattern_.rows(); ++j) values_[pattern_.col_ptr()[j + 1] - 1] += add;
      shift += add;
      ok = factor_.factorize(values_.data());
    }
    if (!ok) {
      res.status = "Newton matrix is not positive definite even after regularisation";
      break;
    }
    factor_.solve(g.data(), d.data(), 1);
    d = -d;
    }
  have_direction:
    const double slope = g.dot(d);
    if (!(slope < 0)) {
      res.status = "Newton direction is not a descent direction";
      break;
    }
    auto ls = armijo_backtracking(
        [&](double s) {
          trial = x;
          scatter(d, s, trial);
          return energy_with(trial, act, load.gravity);
        },
        E, slope, options_);
    if (!ls.success) {
      trial = x;
      scatter(d, 1.0, trial);
      const double E1 = energy_with(trial, act, load.gravity);
      Eigen::VectorXd g1;
      free_gradient(load, trial, act, g1);
      if (accept_at_roundoff(E1, g1.norm(), E, g.norm(), conv.E0)) {
        ls.success = true;
        ls.step = 1.0;
        ls.energy = E1;
      } else {
        res.status = "stalled: no step along the Newton direction decreases the energy or the gradient "
                     "(round-off level reached; loosen rtol_grad / rtol_energy)";
        break;
      }
    }
    scatter(d, ls.step, x);
    const double E_prev = E;
    E = ls.energy;
    free_gradient(load, x, act, g);
    const double gn = g.norm();
    res.iterations = it;
    res.history.push_back({it, E, gn, ls.step, seconds_since(t0), 0, ls.backtracks});
    if (conv.test(E_prev, E, gn)) {
      res.converged = true;
      res.status = "converged";
    }
  }
  res.positions = x;
  res.energy = E;
  res.grad_norm = res.history.back().grad_norm;
  res.rel_energy_change = conv.rel_energy_change;
  res.time_s = seconds_since(t0);
  return res;
}

}  // namespace emu
