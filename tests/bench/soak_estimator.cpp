// Soak of the estimator: hours of simulated data at the config's rate
// through RecursiveEstimator and FaultDetector, faster than real time, on a plant
// that does not drift. Prints the resident set size and the estimates once per
// simulated hour and fails (exit 1) on a NaN, a fault flag, a reset, RSS growth
// after the first hour, or a final estimate off the truth.
//
//   soak_estimator [hours=24] [config=config/flexible-beam.yaml] [record_s=300]
//
// The record (closed loop, the config's plant without its trajectories) is
// simulated once and fed in a loop; at a multiple of the setpoint period the seam
// differs from a continuous run only by the noise.
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "modalwatch/fault_detector.hpp"

namespace {

long rss_kib() {
  std::ifstream statm("/proc/self/statm");
  long pages = 0, resident = 0;
  statm >> pages >> resident;
  return resident * (sysconf(_SC_PAGESIZE) / 1024);
}

}  // namespace

int main(int argc, char** argv) {
  using namespace modalwatch;
  const double hours = argc > 1 ? std::atof(argv[1]) : 24.0;
  const std::string path = argc > 2 ? argv[2] : std::string(MODALWATCH_SOURCE_DIR) + "/config/flexible-beam.yaml";
  const double record_s = argc > 3 ? std::atof(argv[3]) : 300.0;
  if (!(hours > 0.0) || !(record_s > 0.0)) {
    std::fprintf(stderr, "usage: soak_estimator [hours > 0] [config] [record_s > 0]\n");
    return 2;
  }
  const Config config = load_config(path);
  if (!config.plant || !config.experiment) {
    std::fprintf(stderr, "soak_estimator: %s needs plant: and simulation: sections\n", path.c_str());
    return 2;
  }
  PlantSpec plant = *config.plant;
  for (auto& m : plant.modes) m.wn = m.zeta = m.gain = Trajectory{};
  ExperimentSpec experiment = *config.experiment;
  experiment.duration = record_s;
  const Record record = simulate(plant, experiment).record;
  const AdditiveModel truth = plant_model_at(plant, 0.0);

  RecursiveEstimator estimator(config.model, config.estimator);
  const int K = estimator.submodels();
  FaultDetectorSettings fs;
  for (const auto& s : config.model.submodels) fs.mode_names.push_back(s.name);
  for (int i = 0; i < K; ++i) fs.baselines.push_back(modal_parameters(truth.submodels[static_cast<std::size_t>(i)]));
  FaultDetector detector(fs);
  std::vector<ModalParameters> value(static_cast<std::size_t>(K)), std_dev(static_cast<std::size_t>(K));
  std::vector<FlagChange> changes;
  changes.reserve(static_cast<std::size_t>(3 * K));

  const double T = config.sample_time;
  const long long total = std::llround(hours * 3600.0 / T);
  const long long per_hour = std::llround(3600.0 / T);
  const long long publish_every = std::max(1LL, std::llround(0.1 / T));  // 10 Hz, as the daemon
  // Restart the loop after the warm-up window, so the seam is in steady state.
  bench::Feeder feed(record, std::max<Eigen::Index>(config.estimator.warmup_samples, 1));
  long rss_hour1 = 0, rss_max = 0;
  int flags_raised = 0;
  bool nan_seen = false;
  std::printf("%8s %12s %10s", "hour", "samples", "rss_KiB");
  for (int i = 0; i < K; ++i) std::printf(" %10s_wn %10s_zeta", fs.mode_names[i].c_str(), fs.mode_names[i].c_str());
  std::printf(" %7s\n", "resets");
  for (long long k = 1; k <= total; ++k) {
    estimator.step(feed.next());
    if (k % publish_every == 0) {
      const EstimatorStatus& st = estimator.status();
      for (int i = 0; i < K; ++i) {
        const ModeEstimate m = estimator.mode(i);
        value[static_cast<std::size_t>(i)] = m.value;
        std_dev[static_cast<std::size_t>(i)] = m.std;
        if (!std::isfinite(m.value.wn) || !std::isfinite(m.value.zeta) || !std::isfinite(m.value.gain)) nan_seen = true;
      }
      changes.clear();
      detector.update(static_cast<double>(k) * T, value, std_dev, !st.warming_up && !st.low_excitation, changes);
      for (const FlagChange& c : changes) flags_raised += c.raised ? 1 : 0;
    }
    if (k % per_hour == 0 || k == total) {
      const long rss = rss_kib();
      if (k == per_hour) rss_hour1 = rss;
      if (k > per_hour) rss_max = std::max(rss_max, rss);
      std::printf("%8.2f %12lld %10ld", static_cast<double>(k) / static_cast<double>(per_hour), k, rss);
      for (int i = 0; i < K; ++i) {
        const ModeEstimate m = estimator.mode(i);
        std::printf(" %13.6g %15.6g", m.value.wn, m.value.zeta);
      }
      std::printf(" %7llu\n", static_cast<unsigned long long>(estimator.status().resets));
      std::fflush(stdout);
    }
  }

  bool ok = true;
  const auto fail = [&](const std::string& why) {
    std::printf("FAIL: %s\n", why.c_str());
    ok = false;
  };
  if (nan_seen) fail("a non-finite estimate");
  if (flags_raised > 0) fail(std::to_string(flags_raised) + " fault flags on a plant that does not drift");
  if (estimator.status().resets > 0) fail(std::to_string(estimator.status().resets) + " estimator resets");
  // One page of slack per hour would still be a leak over days: allow none beyond 64 KiB.
  if (rss_hour1 > 0 && rss_max > rss_hour1 + 64)
    fail("RSS grew from " + std::to_string(rss_hour1) + " to " + std::to_string(rss_max) + " KiB after the first hour");
  for (int i = 0; i < K; ++i) {
    const ModalParameters t = modal_parameters(truth.submodels[static_cast<std::size_t>(i)]);
    const ModeEstimate m = estimator.mode(i);
    const double e_wn = std::abs(m.value.wn / t.wn - 1.0), e_zeta = std::abs(m.value.zeta / t.zeta - 1.0);
    std::printf("%s: wn error %.3f %%, zeta error %.2f %%\n", fs.mode_names[i].c_str(), 100 * e_wn, 100 * e_zeta);
    if (e_wn > 0.01) fail(fs.mode_names[i] + " frequency off the truth by more than 1 %");
    if (e_zeta > 0.2) fail(fs.mode_names[i] + " damping off the truth by more than 20 %");
  }
  std::printf("%s: %lld samples (%.2f h at %.0f Hz), RSS %ld KiB after 1 h, max %ld KiB after\n", ok ? "PASS" : "FAIL",
              total, hours, 1.0 / T, rss_hour1, rss_max);
  return ok ? 0 : 1;
}
