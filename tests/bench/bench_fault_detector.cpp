// Cost of FaultDetector::update() per mode. Measured and reported, never
// asserted; it runs once per publish period (10 Hz), so microseconds are fine.
//
//   BM_FaultDetectorUpdate/K       one update of K modes with their 3x3 covariances,
//                                  baselines configured, estimates AR(1) noise about
//                                  them; items_per_second = modes/s
//   BM_FaultDetectorUpdateJoint/K  the same with the modes' joint covariance, every
//                                  gain correlated (0.5) with its neighbours' (the
//                                  named mode's test given the others), and each
//                                  mode's sampling covariance, a quarter of its own
//                                  (the named mode's test against it)
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <Eigen/Core>

#include "modalwatch/fault_detector.hpp"

namespace modalwatch {
namespace {

void run_updates(benchmark::State& state, bool joint_covariance) {
  const auto K = static_cast<std::size_t>(state.range(0));
  FaultDetectorSettings s;
  std::vector<ModalParameters> truth;
  for (std::size_t i = 0; i < K; ++i) {
    truth.push_back({50.0 * static_cast<double>(i + 1), 0.02, 1.0});
    s.mode_names.push_back(std::to_string(i));  // ("m" + ... trips GCC 12 -Wrestrict in Release)
    s.baselines.emplace_back(truth.back());
  }
  FaultDetector detector(s);

  // 4096 updates of estimates, errors AR(1) over the memory with 1 % relative std.
  constexpr int kUpdates = 4096;
  const double rho = std::exp(-s.update_period / kDefaultMemoryTime), sd = std::sqrt(1.0 - rho * rho);
  std::mt19937_64 rng(1);
  std::normal_distribution<double> z;
  std::vector<std::vector<ModalParameters>> value(kUpdates, truth);
  std::vector<double> e(3 * K, 0.0);
  for (auto& v : value)
    for (std::size_t i = 0; i < K; ++i) {
      for (int q = 0; q < 3; ++q) e[3 * i + q] = rho * e[3 * i + q] + sd * z(rng);
      v[i] = {truth[i].wn * (1 + 0.01 * e[3 * i]), truth[i].zeta * (1 + 0.01 * e[3 * i + 1]),
              truth[i].gain * (1 + 0.01 * e[3 * i + 2])};
    }
  std::vector<Eigen::Matrix3d> cov(K);
  const auto n = static_cast<Eigen::Index>(3 * K);
  Eigen::MatrixXd joint = Eigen::MatrixXd::Zero(n, n);
  for (std::size_t i = 0; i < K; ++i) {
    cov[i] = (0.01 * Eigen::Vector3d(truth[i].wn, truth[i].zeta, truth[i].gain)).cwiseAbs2().asDiagonal();
    const auto at = static_cast<Eigen::Index>(3 * i);
    joint.block<3, 3>(at, at) = cov[i];
    if (i + 1 < K) joint(at + 2, at + 5) = joint(at + 5, at + 2) = 0.5 * 1e-4;
  }
  std::vector<Eigen::Matrix3d> sampling(K);
  for (std::size_t i = 0; i < K; ++i) sampling[i] = 0.25 * cov[i];
  std::vector<FlagChange> changes;
  changes.reserve(3 * K);

  long k = 0;
  for (auto _ : state) {
    changes.clear();
    detector.update(0.1 * static_cast<double>(k), value[static_cast<std::size_t>(k % kUpdates)], cov, true, changes,
                    0.0, nullptr, joint_covariance ? &joint : nullptr, joint_covariance ? &sampling : nullptr);
    benchmark::DoNotOptimize(changes.data());
    ++k;
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(K));
}

void BM_FaultDetectorUpdate(benchmark::State& state) { run_updates(state, false); }
void BM_FaultDetectorUpdateJoint(benchmark::State& state) { run_updates(state, true); }
BENCHMARK(BM_FaultDetectorUpdate)->Arg(1)->Arg(3)->Arg(21);
BENCHMARK(BM_FaultDetectorUpdateJoint)->Arg(3)->Arg(21);

}  // namespace
}  // namespace modalwatch

BENCHMARK_MAIN();
