// The Newton driver and PCG on small problems with known answers.
#include <cstdint>
#include <cstring>
#include <random>

#include <Eigen/Dense>

#include <limits>

#include "check.h"
#include "emu/solvers/newton/convergence.h"
#include "emu/solvers/newton/line_search.h"
#include "emu/solvers/newton/newton_driver.h"
#include "emu/solvers/newton/lbfgs.h"
#include "emu/solvers/newton/pcg.h"
#include "emu/solvers/newton/rounding_perturbation.h"
#include "emu/solvers/newton/step_test.h"

using namespace emu;

namespace {
// A convex test problem: f(x) = sum_i [exp(x_i) - c_i x_i] + 1/2 x^T Q x with Newton steps.
struct ConvexProblem {
  Eigen::MatrixXd Q;
  Eigen::VectorXd c, x, d, g;
  double noise = 0;  // amplitude of a rounding-like error in grad: a fresh sample for any change of y
  bool fail_direction_at = false;
  int fail_iteration = -1;
  bool cut = false;  // every direction reported as cut short (SearchDirection::cg_cut)
  double f(const Eigen::VectorXd& y) const { return y.array().exp().sum() - c.dot(y) + 0.5 * y.dot(Q * y); }
  Eigen::VectorXd grad(const Eigen::VectorXd& y) const {
    Eigen::VectorXd out = Eigen::VectorXd(y.array().exp()) - c + Q * y;
    for (Eigen::Index i = 0; noise > 0 && i < y.size(); ++i) {
      std::uint64_t bits;
      std::memcpy(&bits, &y(i), sizeof bits);
      bits = (bits + static_cast<std::uint64_t>(i)) * 0x9E3779B97F4A7C15ull;
      out(i) += noise * (static_cast<double>(bits >> 11) * 0x1p-52 - 1.0);  // uniform in [-1, 1)
    }
    return out;
  }
  double energy() const { return f(x); }
  double grad_norm() const { return grad(x).norm(); }
  SearchDirection direction(int it, PhaseTimes& /*time*/) {
    if (it == fail_iteration) return SearchDirection().fail("test failure");
    Eigen::MatrixXd H = Q;
    H.diagonal() += Eigen::VectorXd(x.array().exp());
    g = grad(x);
    d = -H.ldlt().solve(g);
    SearchDirection dir;
    dir.slope = g.dot(d);
    dir.cg_cut = cut;
    return dir;
  }
  double last_s = 0;
  double trial_energy(double s) {
    last_s = s;
    return f(x + s * d);
  }
  double trial_grad_norm() const { return grad(x + last_s * d).norm(); }
  double gradient_noise() {
    Eigen::VectorXd x1 = x;
    perturb_by_rounding(x1);
    return (grad(x1) - grad(x)).norm() / std::sqrt(2.0);
  }
  double take_step(int, double s, double) {
    x += s * d;
    return f(x);
  }
  Eigen::MatrixX3d pos;
  const Eigen::MatrixX3d& positions() {
    pos = Eigen::Map<const Eigen::MatrixX3d>(x.data(), x.size() / 3, 3);  // (x only has to be a multiple of 3 long here)
    return pos;
  }
};

ConvexProblem make_problem(int n) {
  std::mt19937 rng(3);
  std::normal_distribution<double> nd(0.0, 1.0);
  ConvexProblem p;
  Eigen::MatrixXd A(n, n);
  for (int i = 0; i < n * n; ++i) A.data()[i] = nd(rng);
  p.Q = A * A.transpose() / (10.0 * n);
  p.c.resize(n);
  for (int i = 0; i < n; ++i) p.c(i) = 3.0 + nd(rng);
  p.x = Eigen::VectorXd::Constant(n, -4.0);  // far from the minimiser: the first Newton steps overshoot
  return p;
}
}  // namespace

TEST(newton_driver_converges_quadratically_to_the_minimiser) {
  ConvexProblem p = make_problem(8);
  SolverOptions o;
  SolveResult r;
  newton_minimize(p, o, 1e-14, Clock::now(), r);
  CHECK(r.converged);
  CHECK(r.status == "converged");
  CHECK(p.grad(p.x).norm() <= 1e-6 * r.grad_norm0);
  CHECK(r.iterations < 30);
  CHECK(static_cast<int>(r.history.size()) == r.iterations + 1);
  // the energy decreases monotonically and the record matches the state
  for (size_t i = 1; i < r.history.size(); ++i) CHECK(r.history[i].energy < r.history[i - 1].energy);
  CHECK_CLOSE(r.energy, p.f(p.x), 0.0);
  bool some_cut = false;
  for (const auto& h : r.history) some_cut = some_cut || h.backtracks > 0;
  CHECK(some_cut);  // the start is far enough that Armijo backtracked
}

TEST(newton_driver_reports_failures_caps_and_interrupts) {
  {
    ConvexProblem p = make_problem(5);
    p.fail_iteration = 3;
    SolveResult r;
    newton_minimize(p, SolverOptions(), 1e-14, Clock::now(), r);
    CHECK(!r.converged);
    CHECK(r.status == "test failure");
    CHECK(r.iterations == 2);
  }
  {
    ConvexProblem p = make_problem(5);
    SolverOptions o;
    o.max_iterations = 2;
    SolveResult r;
    newton_minimize(p, o, 1e-14, Clock::now(), r);
    CHECK(!r.converged && r.status == "max iterations reached" && r.iterations == 2);
  }
  {
    ConvexProblem p = make_problem(5);
    SolverOptions o;
    int polls = 0;
    o.interrupted = [&] { return ++polls == 2; };
    SolveResult r;
    newton_minimize(p, o, 1e-14, Clock::now(), r);
    CHECK(!r.converged && r.status == "interrupted" && r.iterations == 1);
  }
  {
    // an already-converged start stops at once
    ConvexProblem p = make_problem(5);
    SolveResult r0;
    newton_minimize(p, SolverOptions(), 1e-14, Clock::now(), r0);
    SolveResult r;
    newton_minimize(p, SolverOptions(), 1e-3, Clock::now(), r);
    CHECK(r.converged && r.iterations == 0 && r.status.find("initial state") != std::string::npos);
  }
}

TEST(newton_driver_shows_every_iterate_and_stops_when_asked) {
  ConvexProblem p = make_problem(6);
  SolverOptions o;
  std::vector<int> seen;
  std::vector<double> first_coordinate;
  o.on_iteration = [&](const IterationRecord& r, const Eigen::MatrixX3d& x) {
    seen.push_back(r.iteration);
    first_coordinate.push_back(x(0, 0));
    return r.iteration == 3;
  };
  SolveResult r;
  newton_minimize(p, o, 1e-14, Clock::now(), r);
  CHECK(!r.converged && r.status == "stopped by on_iteration" && r.iterations == 3);
  CHECK((seen == std::vector<int>{0, 1, 2, 3}));
  CHECK_CLOSE(first_coordinate.back(), p.x(0), 0.0);
  CHECK_CLOSE(first_coordinate.front(), -4.0, 0.0);
  // a request to stop at the converged iterate changes nothing
  ConvexProblem q = make_problem(6);
  o.on_iteration = [](const IterationRecord&, const Eigen::MatrixX3d&) { return true; };
  SolveResult r0;
  SolverOptions plain;
  ConvexProblem q0 = make_problem(6);
  newton_minimize(q0, plain, 1e-14, Clock::now(), r0);
  o.max_iterations = 1000;
  SolveResult r1;
  q.x = q0.x;  // start at the minimiser: converged at once, and the callback sees it
  newton_minimize(q, o, 1e-3, Clock::now(), r1);
  CHECK(r1.converged && r1.iterations == 0);
}

TEST(newton_driver_step_tolerance) {
  ConvexProblem strict = make_problem(6);
  SolveResult rs;
  newton_minimize(strict, SolverOptions(), 1e-14, Clock::now(), rs);
  // a full step shorter than step_tol stops the solve early, near the minimiser
  ConvexProblem p = make_problem(6);
  SolverOptions o;
  o.step_tol = 0.05;
  SolveResult r;
  newton_minimize(p, o, 1e-14, Clock::now(), r);
  CHECK(r.converged && r.status.find("step_tol") != std::string::npos);
  CHECK(r.iterations < rs.iterations);
  CHECK((p.x - strict.x).cwiseAbs().maxCoeff() <= 0.05);
  // ... but not before the gradient has fallen to step_tol_grad of its start
  ConvexProblem q = make_problem(6);
  o.step_tol_grad = 1e-12;
  SolveResult rq;
  newton_minimize(q, o, 1e-14, Clock::now(), rq);
  CHECK(rq.converged && rq.status == "converged" && rq.iterations == rs.iterations);
}

TEST(newton_driver_step_tolerance_does_not_stop_on_a_cut_step) {
  // the same problem and step_tol as above, every direction reported as a CG
  // solve cut short: no step is a Newton step, so only the gradient test stops
  ConvexProblem strict = make_problem(6);
  SolveResult rs;
  newton_minimize(strict, SolverOptions(), 1e-14, Clock::now(), rs);
  ConvexProblem p = make_problem(6);
  p.cut = true;
  SolverOptions o;
  o.step_tol = 0.05;
  SolveResult r;
  newton_minimize(p, o, 1e-14, Clock::now(), r);
  CHECK(r.converged && r.status == "converged" && r.iterations == rs.iterations);
}

TEST(newton_driver_step_tolerance_sees_the_contraction) {
  // Steps a tenth of Newton's: full steps that shrink by only 0.9 each, so a
  // short one leaves about nine times its length.
  struct Slow : ConvexProblem {
    SearchDirection direction(int it, PhaseTimes& time) {
      SearchDirection dir = ConvexProblem::direction(it, time);
      d *= 0.1;
      dir.slope *= 0.1;
      return dir;
    }
  };
  ConvexProblem strict = make_problem(6);
  SolveResult rs;
  newton_minimize(strict, SolverOptions(), 1e-14, Clock::now(), rs);
  SolverOptions o;
  o.step_tol = 0.05;
  o.max_iterations = 2000;
  Slow a;
  static_cast<ConvexProblem&>(a) = make_problem(6);
  SolveResult ra;
  newton_minimize(a, o, 1e-14, Clock::now(), ra);   // the rate assumed: stops far from the answer
  CHECK(ra.converged && ra.status.find("step_tol") != std::string::npos);
  CHECK((a.x - strict.x).cwiseAbs().maxCoeff() > 0.1);
  o.step_tol_contraction = 0.5;                     // the rate seen: no short step stops it
  Slow b;
  static_cast<ConvexProblem&>(b) = make_problem(6);
  SolveResult rb;
  newton_minimize(b, o, 1e-14, Clock::now(), rb);
  CHECK(rb.converged && rb.status.find("step_tol") == std::string::npos);
  CHECK((b.x - strict.x).cwiseAbs().maxCoeff() <= 0.05);
  // Newton's own steps contract: the seen rate stops it early, within step_tol
  ConvexProblem c = make_problem(6);
  SolveResult rc;
  newton_minimize(c, o, 1e-14, Clock::now(), rc);
  CHECK(rc.converged && rc.status.find("step_tol") != std::string::npos && rc.iterations < rs.iterations);
  CHECK((c.x - strict.x).cwiseAbs().maxCoeff() <= 0.05);
}

TEST(step_test_needs_a_short_full_step_near_equilibrium_and_two_exact_contractions) {
  SolverOptions o;
  o.step_tol = 1e-3;
  o.step_tol_grad = 1e-2;
  {  // the rate assumed: one short full step near equilibrium stops
    StepTest t;
    CHECK(!t.passes(o, true, 2e-3, true, 1.0, 1000.0));    // too long
    CHECK(!t.passes(o, true, 5e-4, false, 1.0, 1000.0));   // a cut step
    CHECK(!t.passes(o, true, 5e-4, true, 20.0, 1000.0));   // |g| above the gate
    CHECK(t.passes(o, false, 5e-4, true, 1.0, 1000.0));    // filtered steps count when the rate is assumed
  }
  o.step_tol_contraction = 0.5;
  {  // the rate seen: two exact steps in a row, each at most half the one before
    StepTest t;
    CHECK(!t.passes(o, true, 4e-3, true, 1.0, 1000.0));
    CHECK(!t.passes(o, true, 8e-4, true, 1.0, 1000.0));    // one contraction: not yet
    CHECK(t.passes(o, true, 3e-4, true, 1.0, 1000.0));     // the second
  }
  {
    StepTest t;
    CHECK(!t.passes(o, true, 4e-3, true, 1.0, 1000.0));
    CHECK(!t.passes(o, false, 8e-4, true, 1.0, 1000.0));   // a filtered step breaks the run
    CHECK(!t.passes(o, true, 3e-4, true, 1.0, 1000.0));
    CHECK(t.passes(o, true, 1e-4, true, 1.0, 1000.0));
  }
  {
    StepTest t;
    CHECK(!t.passes(o, true, 8e-4, true, 1.0, 1000.0));
    CHECK(!t.passes(o, true, 7e-4, true, 1.0, 1000.0));    // 0.875 of the one before
    CHECK(!t.passes(o, true, 3e-4, true, 1.0, 1000.0));
    CHECK(t.passes(o, true, 1e-4, true, 1.0, 1000.0));
  }
  {  // alternating steps (a softly resisted turn: upper_limb's settle, frame 11, ended 1.5e-3 from
     // strict FEM on the last three): a contraction is against both steps before it
    StepTest t;
    o.step_tol = 5e-3;
    CHECK(!t.passes(o, true, 4.7e-3, true, 1.0, 1000.0));
    CHECK(!t.passes(o, true, 1.4e-3, true, 1.0, 1000.0));   // a contraction
    CHECK(!t.passes(o, true, 3.2e-3, true, 1.0, 1000.0));
    CHECK(!t.passes(o, true, 1.1e-3, true, 1.0, 1000.0));   // a third of 3.2e-3, but 0.79 of 1.4e-3
    CHECK(!t.passes(o, true, 2.6e-4, true, 1.0, 1000.0));   // contracts; the step before did not
    CHECK(t.passes(o, true, 1.0e-4, true, 1.0, 1000.0));
  }
}

TEST(newton_driver_stalls_when_no_step_helps) {
  // An ascent "direction" that the problem claims is descent: no step lowers
  // the energy or the gradient, so the solve stops as stalled (never loops).
  struct Liar : ConvexProblem {
    SearchDirection direction(int it, PhaseTimes& time) {
      SearchDirection dir = ConvexProblem::direction(it, time);
      d = -d;
      dir.slope = -std::abs(dir.slope);
      return dir;
    }
  } p;
  static_cast<ConvexProblem&>(p) = make_problem(4);
  SolveResult r;
  newton_minimize(p, SolverOptions(), 1e-14, Clock::now(), r);
  CHECK(!r.converged);
  CHECK(r.status.rfind("stalled", 0) == 0);
  CHECK(r.iterations == 0);
}

// The minimiser of make_problem(6) and a solve of it whose gradient carries a
// rounding-like error of 1e-6 (a fresh sample for every rounding of x), from
// its start or from the minimiser, with the given noise_factor.
struct NoisySolve {
  ConvexProblem exact = make_problem(6), p = make_problem(6);
  SolveResult r;
  NoisySolve(double noise_factor, bool from_minimiser, double rtol_grad) {
    SolveResult r_exact;
    newton_minimize(exact, SolverOptions(), 1e-14, Clock::now(), r_exact);
    CHECK(r_exact.converged && r_exact.status == "converged");
    if (from_minimiser) p.x = exact.x;
    p.noise = 1e-6;
    SolverOptions o;
    o.rtol_grad = rtol_grad;
    o.noise_factor = noise_factor;
    o.max_iterations = 40;
    newton_minimize(p, o, 1e-14, Clock::now(), r);
  }
};

TEST(newton_driver_stops_at_the_gradients_measured_round_off) {
  // The noise far above rtol_grad |g_0|: without the noise floor no iterate
  // meets the test; with it the solve stops near the minimiser and says why.
  CHECK(!NoisySolve(0.0, false, 1e-12).r.converged);
  NoisySolve s(2.0, false, 1e-12);
  CHECK(s.r.converged && s.r.status == "converged: the gradient is at its round-off level");
  CHECK(s.r.iterations < 15);
  CHECK((s.p.x - s.exact.x).norm() < 1e-5);
  CHECK(s.r.grad_norm > 1e-12 * s.r.grad_norm0);  // not the plain test
}

TEST(newton_driver_measures_the_round_off_of_a_warm_start_that_stalls) {
  // Started at the minimiser: |g_0| is the noise itself, the endgame band
  // (relative to |g_0|) is never entered, and no step lowers the energy. The
  // stall is measured: converged at round-off, not "stalled".
  CHECK(!NoisySolve(0.0, true, SolverOptions().rtol_grad).r.converged);
  NoisySolve s(2.0, true, SolverOptions().rtol_grad);
  CHECK(s.r.converged && s.r.status == "converged: the gradient is at its round-off level");
  CHECK((s.p.x - s.exact.x).norm() < 1e-5);
}

TEST(lbfgs_meets_the_secant_equation_and_skips_pairs_without_curvature) {
  std::mt19937 rng(11);
  std::normal_distribution<double> nd(0.0, 1.0);
  const int n = 12;
  Eigen::MatrixXd M(n, n);
  for (int i = 0; i < n * n; ++i) M.data()[i] = nd(rng);
  const Eigen::MatrixXd A = M * M.transpose() + Eigen::MatrixXd::Identity(n, n);
  const Eigen::VectorXd h0 = Eigen::VectorXd::LinSpaced(n, 0.5, 2.0);  // H0 = diag(h0)
  auto initial = [&](const Eigen::VectorXd& in, Eigen::VectorXd& out) { out = h0.cwiseProduct(in); };
  LbfgsMemory<Eigen::VectorXd> mem(4);
  Eigen::VectorXd s, out;
  for (int k = 0; k < 6; ++k) {
    s = Eigen::VectorXd::NullaryExpr(n, [&] { return nd(rng); });
    mem.push(s, A * s);
  }
  CHECK(mem.size() == 4);  // the oldest dropped
  mem.apply(A * s, initial, out);
  CHECK((out - s).norm() <= 1e-10 * s.norm());  // H_k y_k = s_k for the newest pair
  for (int k = 0; k < 5; ++k) {  // positive definite
    const Eigen::VectorXd g = Eigen::VectorXd::NullaryExpr(n, [&] { return nd(rng); });
    mem.apply(g, initial, out);
    CHECK(g.dot(out) > 0);
  }
  mem.push(s, -(A * s));  // negative curvature: not kept
  CHECK(mem.size() == 4);
  mem.clear();
  const Eigen::VectorXd g = Eigen::VectorXd::Ones(n);
  mem.apply(g, initial, out);
  CHECK((out - h0).norm() <= 1e-15);  // no pairs: H0 g
}

TEST(pcg_solves_spd_systems_and_stops_at_negative_curvature) {
  std::mt19937 rng(5);
  std::normal_distribution<double> nd(0.0, 1.0);
  const int n = 30;
  Eigen::MatrixXd A(n, n);
  for (int i = 0; i < n * n; ++i) A.data()[i] = nd(rng);
  const Eigen::MatrixXd H = A * A.transpose() + 0.1 * Eigen::MatrixXd::Identity(n, n);
  Eigen::VectorXd b(n);
  for (int i = 0; i < n; ++i) b(i) = nd(rng);
  const Eigen::VectorXd diag = H.diagonal();
  Pcg<Eigen::VectorXd> pcg;
  Eigen::VectorXd d;
  auto product = [&](const Eigen::VectorXd& v, Eigen::VectorXd& out) { out = H * v; };
  auto jacobi = [&](const Eigen::VectorXd& r, Eigen::VectorXd& z) { z = r.cwiseQuotient(diag); };
  PcgResult res = pcg.solve(product, jacobi, b, 1e-10 * b.norm(), 500, d);
  CHECK(!res.negative_curvature);
  CHECK((d - H.ldlt().solve(b)).norm() <= 1e-8 * d.norm());
  // the exact inverse as preconditioner: one iteration
  auto exact = [&](const Eigen::VectorXd& r, Eigen::VectorXd& z) { z = H.ldlt().solve(r); };
  res = pcg.solve(product, exact, b, 1e-10 * b.norm(), 500, d);
  CHECK(res.iterations == 1);
  // indefinite: stops at negative curvature; at once it returns M^-1 b
  const Eigen::MatrixXd Hneg = -H;
  auto product_neg = [&](const Eigen::VectorXd& v, Eigen::VectorXd& out) { out = Hneg * v; };
  res = pcg.solve(product_neg, jacobi, b, 1e-10 * b.norm(), 500, d);
  CHECK(res.negative_curvature && res.iterations == 0);
  CHECK((d - b.cwiseQuotient(diag)).norm() == 0.0);
}

TEST(pcg_model_decrease_is_the_quadratic_model_and_its_truncation_test_holds_where_cg_stops) {
  // A stiff block that carries most of |b| (Jacobi resolves it at once) and
  // a soft 1D Laplacian that carries most of the energy: a loose residual
  // test stops while the model still falls fast, the Nash-Sofer test goes on.
  std::mt19937 rng(3);
  std::normal_distribution<double> nd(0.0, 1.0);
  std::uniform_real_distribution<double> ud(0.0, 1.0);
  const int m = 30, n = 2 * m;
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(n, n);
  Eigen::VectorXd b(n);
  for (int i = 0; i < m; ++i) {
    H(i, i) = 1e3 * (1.0 + 0.1 * ud(rng));
    b(i) = nd(rng);
    H(m + i, m + i) = 2.0 + 1e-3;
    if (i + 1 < m) H(m + i, m + i + 1) = H(m + i + 1, m + i) = -1.0;
    b(m + i) = 0.05;
  }
  const Eigen::VectorXd diag = H.diagonal();
  auto product = [&](const Eigen::VectorXd& v, Eigen::VectorXd& out) { out = H * v; };
  auto jacobi = [&](const Eigen::VectorXd& r, Eigen::VectorXd& z) { z = r.cwiseQuotient(diag); };
  auto q = [&](const Eigen::VectorXd& d) { return 0.5 * d.dot(H * d) - b.dot(d); };
  Pcg<Eigen::VectorXd> pcg;
  Eigen::VectorXd d;
  const double tol = 0.5 * b.norm();
  const PcgResult loose = pcg.solve(product, jacobi, b, tol, 500, d);
  CHECK(loose.converged);
  CHECK(std::abs(loose.model - q(d)) <= 1e-10 * std::abs(q(d)));  // the model CG tracks is q at its iterate
  const double c = 0.5;
  const PcgResult truncated = pcg.solve(product, jacobi, b, tol, 500, d, c);
  CHECK(truncated.converged);
  CHECK(truncated.iterations > loose.iterations + 2);
  CHECK(std::abs(truncated.model - q(d)) <= 1e-10 * std::abs(q(d)));
  CHECK(truncated.model < loose.model);  // the longer solve lowered the model further
  // where it stopped the test holds; one iteration before, the residual test
  // held too (it held from loose.iterations on) but the truncation test did not
  const int k = truncated.iterations;
  Eigen::VectorXd d1, d2;  // k - 1 and k - 2 iterations
  pcg.solve(product, jacobi, b, 0.0, k - 1, d1);
  pcg.solve(product, jacobi, b, 0.0, k - 2, d2);
  CHECK(k * (q(d1) - q(d)) <= c * std::abs(q(d)) * (1 + 1e-12));
  CHECK((k - 1) * (q(d2) - q(d1)) > c * std::abs(q(d1)));
  CHECK((b - H * d1).norm() <= tol);
}

// Armijo backtracking on E(s) = (s - 0.3)^2 from s = 1 (slope -0.6 at 0):
// halves to 0.5 (E = 0.04 <= 0.09 - 1e-4 * 0.5 * 0.6); a non-finite energy is a rejected step.
TEST(armijo_backtracking_halves_until_the_energy_falls_enough) {
  SolverOptions o;
  const auto E = [](double s) { return (s - 0.3) * (s - 0.3); };
  const LineSearchResult r = armijo_backtracking(E, E(0.0), -0.6, o);
  CHECK(r.success && r.step == 0.5 && r.backtracks == 1);
  CHECK_CLOSE(r.energy, 0.04, 1e-15);
  const LineSearchResult nan = armijo_backtracking(
      [&](double s) { return s > 0.2 ? std::numeric_limits<double>::quiet_NaN() : E(s); }, E(0.0), -0.6, o);
  CHECK(nan.success && nan.step <= 0.2);
  // no step lowers a flat energy: failure after max_backtracks, and the round-off rule decides
  const LineSearchResult flat = armijo_backtracking([](double) { return 1.0; }, 1.0, -1.0, o);
  CHECK(!flat.success && flat.backtracks == o.max_backtracks);
  CHECK(accept_at_roundoff(1.0, 0.5, 1.0, 1.0, 2.0));
  CHECK(!accept_at_roundoff(1.0 + 1e-6, 0.5, 1.0, 1.0, 2.0));
  CHECK(!accept_at_roundoff(1.0, 2.0, 1.0, 1.0, 2.0));
}

// The stopping test: both the gradient and the energy decrease must be small;
// a gradient under the round-off floor stops at once; a start at rest is converged.
TEST(convergence_needs_both_tests_or_the_floor) {
  Convergence c{1e-6, 1e-10, 10.0, 1.0, 1e-12};
  CHECK(!c.initial());
  CHECK(!c.test(5.0, 4.9, 1e-7));              // decrease 0.1 of a total 5.1: not converged
  CHECK(!c.test(4.0, 4.0 - 1e-12, 1e-3));      // tiny decrease but a large gradient
  CHECK(c.test(4.0, 4.0 - 1e-12, 1e-7));
  CHECK_CLOSE(c.rel_energy_change, 1e-12 / 6.0, 1e-15);
  CHECK(c.test(5.0, 4.0, 1e-13));              // under the floor
  Convergence at_rest{1e-6, 1e-10, 0.0, 1e-14, 1e-12};
  CHECK(at_rest.initial());
}

TEST_MAIN()
