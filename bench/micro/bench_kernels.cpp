// Microbenchmarks of emu's element kernels (Google Benchmark), each reported
// beside the machine's memory bandwidth so a kernel's time can be read against
// its memory-traffic bound:
//   cmake -S . -B build/micro -DEMU_BUILD_MICROBENCH=ON && cmake --build build/micro -j 2
//   build/micro/bench_kernels [--benchmark_filter=projection]
// Per-element rates are items_per_second (elements); bytes_per_second is the
// traffic the kernel must at least move (inputs read + outputs written).
#include <random>
#include <vector>

#include <Eigen/Cholesky>
#include <benchmark/benchmark.h>

#include "emu/energy/material.h"
#include "emu/energy/psd_project.h"
#include "emu/energy/snh_eigensystem.h"
#include "emu/linalg/rounded_block.h"
#include "emu/linalg/spd_inverse.h"
#include "emu/solvers/emu/acap.h"

using namespace emu;

namespace {
constexpr double kMu = 2.0e4, kLambda = 1.0e6;

/// n deformation gradients I + N(0, spread^2) per entry (spread 0.3: about
/// half of the SNH Hessians are indefinite, as in a strongly activated muscle).
std::vector<Mat3> random_gradients(int n, double spread, unsigned seed = 1) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0.0, spread);
  std::vector<Mat3> Fs(n);
  for (Mat3& F : Fs) {
    F.setIdentity();
    for (int i = 0; i < 9; ++i) F.data()[i] += g(rng);
  }
  return Fs;
}

constexpr int kElements = 4096;

void element_energy_gradient_hessian(benchmark::State& state) {
  const auto Fs = random_gradients(kElements, 0.3);
  const TetMaterial m{kMu, kLambda, 3e4, Vec3(0.0, 0.0, 1.0)};
  for (auto _ : state)
    for (const Mat3& F : Fs) {
      double e = material_energy(m, F);
      Mat3 P = material_stress(m, F);
      Mat9 H = material_hessian(m, F);
      benchmark::DoNotOptimize(e);
      benchmark::DoNotOptimize(P);
      benchmark::DoNotOptimize(H);
    }
  state.SetItemsProcessed(state.iterations() * kElements);
  state.SetBytesProcessed(state.iterations() * kElements * (9 + 1 + 9 + 81) * 8);
}

// The PSD projection of the SNH Hessian: numerical 9x9 eigen-decomposition
// (closed_form = false) against the analytic eigensystem (state.range(0) =
// 100 x spread of F).
void projection(benchmark::State& state, bool closed_form) {
  const auto Fs = random_gradients(kElements, state.range(0) / 100.0);
  std::vector<Mat9> H(Fs.size());
  for (size_t i = 0; i < Fs.size(); ++i) H[i] = snh::hessian(Fs[i], kMu, kLambda);
  for (auto _ : state)
    for (size_t i = 0; i < Fs.size(); ++i) {
      Mat9 P = closed_form ? snh::project_hessian(H[i], Fs[i], kMu, kLambda) : psd_project<9>(H[i]);
      benchmark::DoNotOptimize(P);
    }
  state.SetItemsProcessed(state.iterations() * kElements);
}

// The per-unknown 9x9 block products of a CG iteration (A v in the H product,
// A^-1 r in the Woodbury application): out_u = A_u v_u over 20k unknowns
// (13 MB of blocks; state.range(1) = 2000: 1.3 MB, in L2, for the compute
// bound without the memory traffic). state.range(0): 0 = Eigen's default
// product on a column block (dispatches to its general GEMV kernel), 1 = the
// coefficient-based fixed-size product (lazyProduct), 2 = blocks rounded to
// float (round_spd_block) through block_times, as the constant Schur
// preconditioner applies them. (A packed upper
// triangle, 45 doubles, with a scalar symmetric product ran at 26 M blocks/s
// against 36 M: compute-bound; not kept.)
void block_products(benchmark::State& state) {
  const int n = static_cast<int>(state.range(1));
  std::mt19937 rng(3);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<Mat9> A(n);
  Mat9X v(9, n), out(9, n);
  for (Mat9& a : A) {
    for (int i = 0; i < 81; ++i) a.data()[i] = g(rng);
    a = (a + a.transpose()).eval();
  }
  for (int i = 0; i < 9 * n; ++i) v.data()[i] = g(rng);
  const bool lazy = state.range(0) == 1, rounded = state.range(0) == 2;
  std::vector<Mat9f> Af(rounded ? n : 0);
  for (int u = 0; u < static_cast<int>(Af.size()); ++u) round_spd_block(A[u], Af[u]);
  for (auto _ : state) {
    if (rounded)
      for (int u = 0; u < n; ++u) out.col(u) = block_times(Af[u], v.col(u));
    else if (lazy)
      for (int u = 0; u < n; ++u) out.col(u).noalias() = A[u].lazyProduct(v.col(u));
    else
      for (int u = 0; u < n; ++u) out.col(u).noalias() = A[u] * v.col(u);
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * n);
  state.SetBytesProcessed(state.iterations() * n * ((rounded ? 40.5 : 81) + 9 + 9) * 8);
}

// The exact SNH Hessian's action from F (matrix-free: 9 doubles of F and the
// direction per element instead of an 81-double block; snh::hessian_action)
// against the stored-block product, over the same 20k (state.range(0)) or 2k
// elements.
void hessian_action(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const auto Fs = random_gradients(n, 0.1, 4);
  const auto Ds = random_gradients(n, 1.0, 5);
  std::vector<Mat3> out(n);
  for (auto _ : state) {
    for (int u = 0; u < n; ++u) out[u] = snh::hessian_action(Fs[u], kMu, kLambda, Ds[u]);
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * n);
  state.SetBytesProcessed(state.iterations() * n * (9 + 9 + 9) * 8);
}

// STREAM triad a = b + s c over arrays far larger than the caches: the
// machine's sustainable bandwidth, the bound for streaming kernels; with
// state.range(0) = 1 over OMP_NUM_THREADS threads (the bound for the
// parallel passes of CG).
void stream_triad(benchmark::State& state) {
  const long n = 1L << 23;  // 3 x 64 MB
  std::vector<double> a(n, 0.0), b(n, 1.0), c(n, 2.0);
  const bool parallel = state.range(0) == 1;
  for (auto _ : state) {
#pragma omp parallel for schedule(static) if (parallel)
    for (long i = 0; i < n; ++i) a[i] = b[i] + 3.0 * c[i];
    benchmark::DoNotOptimize(a.data());
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(state.iterations() * n * 3 * sizeof(double));
}
}  // namespace

/// Blocks as the preconditioners see them: filtered SNH Hessians plus an ACAP diagonal.
static std::vector<Mat9> preconditioner_blocks() {
  const auto Fs = random_gradients(kElements, 0.3);
  const TetMaterial m{kMu, kLambda, 3e4, Vec3(0.0, 0.0, 1.0)};
  std::vector<Mat9> A(kElements);
  for (int e = 0; e < kElements; ++e) {
    Mat9 H_psd;
    material_hessians(m, Fs[e], EigenFilter::Clamp, &H_psd, nullptr);
    A[e] = H_psd;
    A[e].diagonal().array() += 100.0 * kMu;
  }
  return A;
}

/// The 9x9 block inverses of a preconditioner rebuild: Eigen's LLT solve with
/// the identity against spd_inverse (blocks: filtered SNH Hessians plus an
/// ACAP diagonal, as the preconditioners see them).
void block_inverse(benchmark::State& state, bool own) {
  const std::vector<Mat9> A = preconditioner_blocks();
  std::vector<Mat9> inv(kElements);
  for (auto _ : state) {
    for (int e = 0; e < kElements; ++e) {
      if (own) spd_inverse<9>(A[e], inv[e]);
      else inv[e] = Eigen::LLT<Mat9>(A[e]).solve(Mat9::Identity());
    }
    benchmark::DoNotOptimize(inv.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * kElements);
}

// invert_spd_blocks: four blocks side by side per spd_inverse_lanes call (the
// same bits as spd_inverse), as ConstantSchur::update inverts them.
void block_inverse_lanes(benchmark::State& state) {
  const std::vector<Mat9> A = preconditioner_blocks();
  std::vector<Mat9> inv(kElements);
  for (auto _ : state) {
    invert_spd_blocks<9>(A, [&](long u, const Mat9& B, bool) { inv[u] = B; });
    benchmark::DoNotOptimize(inv.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * kElements);
}

BENCHMARK(element_energy_gradient_hessian);
BENCHMARK_CAPTURE(block_inverse, eigen_llt, false);
BENCHMARK_CAPTURE(block_inverse, spd_inverse, true);
BENCHMARK(block_inverse_lanes);
BENCHMARK_CAPTURE(projection, numerical, false)->Arg(1)->Arg(30);
BENCHMARK_CAPTURE(projection, closed_form, true)->Arg(1)->Arg(30);
BENCHMARK(block_products)->ArgsProduct({{0, 1, 2}, {20000, 2000}});
BENCHMARK(hessian_action)->Arg(20000)->Arg(2000);
BENCHMARK(stream_triad)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_MAIN();
