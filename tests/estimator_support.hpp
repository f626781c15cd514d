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
