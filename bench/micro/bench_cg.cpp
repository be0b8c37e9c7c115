// Microbenchmarks of one EMU CG iteration and its kernels (Google Benchmark)
// on pinned bars of about 17k and 4k tets (fusiform_20k's size, the demo's),
// alpha = 100 mu, near-rest F with noise, 1 thread unless OMP_NUM_THREADS:
//   build/micro/bench_cg [--benchmark_filter=woodbury]
// bytes_per_second counts the traffic each kernel streams as written (every
// per-tet array it reads or writes once per pass; vertex-sized arrays, which
// stay in cache, left out), so it reads directly against the STREAM triad of
// bench_kernels: near it, the kernel is at its memory-traffic bound.
#include <memory>
#include <random>
#include <stdexcept>
#include <vector>

#include <benchmark/benchmark.h>

#include "bar_model.h"
#include "emu/solvers/emu/acap.h"
#include "emu/solvers/emu/constant_schur.h"
#include "emu/solvers/emu/emu_solver.h"
#include "emu/solvers/emu/emu_solver_testing.h"
#include "emu/solvers/newton/pcg.h"
#include "emu/solvers/emu/woodbury.h"

namespace emu {

/// A solver and its kernels, reached through EmuSolverTesting.
struct CgKernels {
  explicit CgKernels(const Model& m) {
    EmuSolverOptions eo;
    eo.alpha = 100.0 * m.mu(0);
    eo.preconditioner = EmuPreconditioner::Woodbury;  // its modes; the constant Schur one is built beside it
    solver = std::make_unique<EmuSolver>(m, SolverOptions(), eo);
    constant_schur = std::make_unique<ConstantSchur>(EmuSolverTesting::model(*solver), EmuSolverTesting::layout(*solver), EmuSolverTesting::acap(*solver), eo.alpha);
    constant_schur_double =
        std::make_unique<ConstantSchur>(EmuSolverTesting::model(*solver), EmuSolverTesting::layout(*solver), EmuSolverTesting::acap(*solver), eo.alpha, false);
    const long n = EmuSolverTesting::layout(*solver).num_unknowns;
    std::mt19937 rng(2);
    std::normal_distribution<double> g(0.0, 0.05);
    Eigen::MatrixXd F(n, 9);
    for (long u = 0; u < n; ++u)
      for (int i = 0; i < 9; ++i) F(u, i) = (i % 4 == 0 ? 1.0 : 0.0) + g(rng);
    LoadCase load;
    load.activation = Eigen::VectorXd::Constant(1, 1e4);
    const Eigen::MatrixXd blocks = EmuSolverTesting::block_hessians(*solver, load, F, false);
    A.resize(n);
    for (long u = 0; u < n; ++u)
      for (int i = 0; i < 81; ++i) A[u].data()[i] = blocks(u, i);  // a row: the column-major 9x9 block
    Woodbury& woodbury = EmuSolverTesting::woodbury(*solver);
    woodbury.update(A);
    if (!woodbury.low_rank_term()) throw std::runtime_error("bench_cg: the Woodbury matrix X is not definite");
    if (!constant_schur->update(A) || !constant_schur_double->update(A))
      throw std::runtime_error("bench_cg: a block is not definite");
    v = Mat9X::Zero(9, n);
    for (long i = 0; i < v.size(); ++i) v.data()[i] = g(rng);
  }
  void product(const Mat9X& in, Mat9X& out) const { EmuSolverTesting::hessian_product_into(*solver, A, in, out); }
  void fit(const Mat9X& in) {
    EmuSolverTesting::fit_linear_into(*solver, in, dx, Fd);
  }
  /// which: 0 the Woodbury preconditioner, 1 the constant Schur one (single
  /// precision S0 and blocks, the default), 2 the constant Schur one in double
  void precondition(const Mat9X& in, Mat9X& out, int which = 0) const {
    if (which == 1) constant_schur->apply(in, out);
    else if (which == 2) constant_schur_double->apply(in, out);
    else EmuSolverTesting::woodbury(*solver).apply(in, out);
  }
  void back_substitution(const Eigen::MatrixXd& rhs, Eigen::MatrixXd& Z) const { EmuSolverTesting::acap(*solver).solve(rhs, Z); }
  long position_dofs() const { return EmuSolverTesting::acap(*solver).dofs(); }
  long unknowns() const { return EmuSolverTesting::layout(*solver).num_unknowns; }
  int modes() const { return EmuSolverTesting::woodbury(*solver).k(); }

  std::unique_ptr<EmuSolver> solver;
  std::unique_ptr<ConstantSchur> constant_schur, constant_schur_double;
  std::vector<Mat9> A;
  Mat9X v, Fd;
  Eigen::MatrixX3d dx;
};

}  // namespace emu

using namespace emu;

namespace {
// state.range(0): 0 = 8 x 8 x 45 hexes, 17,280 tets (fusiform_20k's size);
// 1 = 5 x 5 x 28, 4,200 tets (the demo arm's soft tets): where the fixed
// cost of a parallel pass shows; 2 = 12 x 12 x 93, 80,352 tets
// (fusiform_80k's size): every per-tet array streams from memory. Each is
// built on first use.
CgKernels& probe(int size) {
  if (size == 2) {
    static CgKernels huge(bar(12, 93));
    return huge;
  }
  static CgKernels large(bar(8, 45)), small(bar(5, 28));
  return size == 0 ? large : small;
}

constexpr double kB = 8.0;  // bytes per double
// Per-tet doubles streamed (see the header comment):
// fit: v read (9), corner targets written and gathered (12 + 12), F_t of the fit written (9)
constexpr double kFit = 9 + 24 + 9;
// H product: the fit, then A (81), v, F_t(fit) read and the result written (9 each)
constexpr double kProduct = kFit + 81 + 27;
// Woodbury: A^-1 r (81 + 9 + 9), its corner targets (24 + 9 read), the
// correction's per-tet values (9 written, 9 + 9 reduced), A^-1 of it added (81 + 9 + 18)
constexpr double kWoodbury = 99 + 33 + 27 + 108;
// constant Schur: the same per-tet passes as the Woodbury application (the S0
// back-substitution, vertex-sized, in place of the thin mode products); with
// single-precision blocks each block pass streams 81 floats, 40.5 doubles
constexpr double kConstantSchur = kWoodbury;
constexpr double kConstantSchurRounded = kWoodbury - 81;
// PCG's vector work: d, r updated with |r|^2 (4 read, 2 written), r.z and p (3 read, 1 written)
constexpr double kVectors = 6 + 4;

void report(benchmark::State& state, double per_tet) {
  const double n = static_cast<double>(probe(static_cast<int>(state.range(0))).unknowns());
  state.SetItemsProcessed(state.iterations() * static_cast<long>(n));
  state.SetBytesProcessed(static_cast<long>(state.iterations() * n * per_tet * kB));
  state.counters["tets"] = n;
}

void fit(benchmark::State& state) {
  CgKernels& p = probe(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    p.fit(p.v);
    benchmark::DoNotOptimize(p.Fd.data());
  }
  report(state, kFit);
}

void back_substitution(benchmark::State& state) {
  CgKernels& p = probe(static_cast<int>(state.range(0)));
  // The ACAP fit's solve: K_c^-1 R with 3 right-hand sides (L (x) I3).
  const Eigen::MatrixXd rhs = Eigen::MatrixXd::Random(p.position_dofs(), 3);
  Eigen::MatrixXd Z;
  for (auto _ : state) {
    p.back_substitution(rhs, Z);
    benchmark::DoNotOptimize(Z.data());
  }
  state.SetItemsProcessed(state.iterations() * p.position_dofs());
  state.counters["rows"] = static_cast<double>(p.position_dofs());
  state.counters["factor_nnz"] = p.solver->factor_nnz();
}

void hessian_product(benchmark::State& state) {
  CgKernels& p = probe(static_cast<int>(state.range(0)));
  Mat9X out;
  for (auto _ : state) {
    p.product(p.v, out);
    benchmark::DoNotOptimize(out.data());
  }
  report(state, kProduct);
}

void woodbury_apply(benchmark::State& state) {
  CgKernels& p = probe(static_cast<int>(state.range(0)));
  Mat9X out;
  for (auto _ : state) {
    p.precondition(p.v, out);
    benchmark::DoNotOptimize(out.data());
  }
  report(state, kWoodbury);
  state.counters["modes"] = p.modes();
}

// state.range(1): 1 single precision (S0's factor and the blocks, the
// default), 2 double
void constant_schur_apply(benchmark::State& state) {
  CgKernels& p = probe(static_cast<int>(state.range(0)));
  const int which = static_cast<int>(state.range(1));
  Mat9X out;
  for (auto _ : state) {
    p.precondition(p.v, out, which);
    benchmark::DoNotOptimize(out.data());
  }
  report(state, which == 1 ? kConstantSchurRounded : kConstantSchur);
}

// Whole PCG iterations (tolerance 0: none stops early), items = iterations x tets;
// state.range(1): the preconditioner (0 Woodbury, 1 constant Schur, 2 the
// constant Schur one in double).
void cg_iteration(benchmark::State& state) {
  CgKernels& p = probe(static_cast<int>(state.range(0)));
  const int which = static_cast<int>(state.range(1));
  Pcg<Mat9X> pcg;
  Mat9X d;
  const int iterations = 20;
  for (auto _ : state) {
    const PcgResult r = pcg.solve([&](const Mat9X& in, Mat9X& out) { p.product(in, out); },
                                  [&](const Mat9X& in, Mat9X& out) { p.precondition(in, out, which); }, p.v, 0.0,
                                  iterations, d);
    if (r.iterations != iterations) {
      state.SkipWithError("PCG stopped early (negative curvature)");
      break;
    }
    benchmark::DoNotOptimize(d.data());
  }
  const double n = static_cast<double>(p.unknowns());
  state.SetItemsProcessed(state.iterations() * iterations * static_cast<long>(n));
  const double precondition = which == 1 ? kConstantSchurRounded : kWoodbury;
  state.SetBytesProcessed(static_cast<long>(state.iterations() * iterations * n * (kProduct + precondition + kVectors) * kB));
  state.counters["tets"] = n;
}
}  // namespace

BENCHMARK(fit)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);
BENCHMARK(back_substitution)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);
BENCHMARK(hessian_product)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);
BENCHMARK(woodbury_apply)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);
BENCHMARK(constant_schur_apply)
    ->ArgsProduct({{0, 1, 2}, {1, 2}})
    ->Unit(benchmark::kMicrosecond);
BENCHMARK(cg_iteration)
    ->ArgsProduct({{0, 1}, {0, 1, 2}})
    ->Args({2, 1})
    ->Args({2, 2})
    ->Unit(benchmark::kMillisecond);
BENCHMARK_MAIN();
