#pragma once
// What the recursive estimator's test suites share: the paper's config, its
// settings with other forgetting or warm-up, and simple plants and inputs.
#include <string>
#include <utility>
#include <vector>

#include "modalwatch/estimator.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/record.hpp"
#include "modalwatch/simulator.hpp"

namespace modalwatch::test_support {

inline Config paper_config() { return load_config(std::string(MODALWATCH_SOURCE_DIR) + "/config/paper-sim.yaml"); }

inline EstimatorSettings settings_for(const Config& c, std::vector<double> forgetting, int warmup) {
  EstimatorSettings s = c.estimator;  // completed from the rest of the file by load_config
  s.forgetting = std::move(forgetting);
  s.random_walks.clear();    // the shipped random walks go with the shipped forgetting: lambda alone here
  s.stabilisations.clear();  // estimator.stabilisation for every submodel, whatever their number
  s.min_memories.clear();    // estimator.min_memory likewise
  s.warmup_samples = warmup;
  return s;
}

// The default initialisation (section 4.7): theta(t0), P(t0) from the offline fit
// on the warm-up window. config/paper-sim.yaml gives them instead, as the paper does.
inline EstimatorSettings with_warmup_fit(EstimatorSettings s) {
  s.fit_on_warmup = true;
  s.initial_covariance.clear();
  return s;
}

inline PlantSpec time_invariant(PlantSpec p, double noise_variance) {
  for (auto& m : p.modes) m.wn.points.clear(), m.zeta.points.clear(), m.gain.points.clear();
  p.noise_variance = noise_variance;
  return p;
}

// The paper's closed loop at 60 dB below its output (noise variance 1e-6),
// time-invariant but for mode 3's wn stepping by `step` at t = `at` (600 s in
// all), with lambda 0.999 for every submodel and the warm-up fit: `config`
// carries those settings, so the daemon and a RecursiveEstimator run the same.
struct PaperModeThreeStep {
  Config config;
  Record record;
  double wn_after = 0.0;
  std::vector<double> wn_others;
};

inline PaperModeThreeStep paper_mode_three_step(double step = -0.03, double at = 400.0) {
  PaperModeThreeStep out;
  out.config = paper_config();
  Config& c = out.config;
  PlantSpec plant = time_invariant(*c.plant, 1e-6);
  out.wn_after = (1.0 + step) * plant.modes[2].modal.wn;
  plant.modes[2].wn.points = {{at, plant.modes[2].modal.wn}, {at + 1.0 / 64, out.wn_after}};
  for (int i = 0; i < 2; ++i) out.wn_others.push_back(plant.modes[static_cast<std::size_t>(i)].modal.wn);
  ExperimentSpec e = *c.experiment;
  e.duration = 600.0;
  out.record = simulate(plant, e).record;
  c.estimator = with_warmup_fit(settings_for(c, {0.999, 0.999, 0.999}, 1000));
  return out;
}

inline SignalSpec prbs(double amplitude, int bits = 12, int clock = 2) {
  SignalSpec s;
  s.kind = SignalSpec::Kind::prbs;
  s.register_bits = bits;
  s.clock_period = clock;
  s.amplitude = amplitude;
  return s;
}

inline void run(RecursiveEstimator& est, const Record& r) {
  for (Eigen::Index k = 0; k < r.size(); ++k) est.step({r.t(k), r.u(k), r.y(k), r.has_reference() ? r.r(k) : 0.0});
}

}  // namespace modalwatch::test_support
