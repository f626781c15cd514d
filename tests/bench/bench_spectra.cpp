// Welch spectra (welch_spectra: Hann windows, 50 % overlap, FFT per segment)
// of a 2^20-sample record. Measured and reported, never asserted.
//
//   BM_Welch/L  segment length L; items_per_second = samples/s
#include <random>

#include <benchmark/benchmark.h>

#include "modalwatch/spectra.hpp"

namespace modalwatch {
namespace {

void BM_Welch(benchmark::State& state) {
  const Eigen::Index n = Eigen::Index{1} << 20;
  std::mt19937_64 rng(1);
  std::normal_distribution<double> z;
  Eigen::VectorXd e(n), u(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    u(i) = z(rng);
    e(i) = 0.5 * u(i) + 0.1 * z(rng);
  }
  for (auto _ : state) benchmark::DoNotOptimize(welch_spectra(e, u, 1e-3, static_cast<int>(state.range(0))));
  state.SetItemsProcessed(state.iterations() * n);
}
BENCHMARK(BM_Welch)->Arg(256)->Arg(2048)->Arg(16384)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace modalwatch

BENCHMARK_MAIN();
