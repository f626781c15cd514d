// Forgetting where the data leave directions open: a healthy closed loop whose
// square-wave setpoint and slow controller excite few frequencies, so that
// exponential forgetting alone winds P up in some directions of theta and lets
// the estimates wander with the noise. Stabilised forgetting (the default)
// must keep every estimate near the truth for the whole record.
#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include "modalwatch/estimator.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/simulator.hpp"

namespace modalwatch {
namespace {

// Three modes at 20 Hz, closed loop, a symmetric 0.25 Hz square setpoint,
// noise variance 0.01, lambda = 0.999 (memory 50 s), warm-up fit over 50 s.
// The model's start is a few per cent off the plant.
constexpr const char* kOpenDirections = R"(
sample_rate_hz: 20
model:
  loop: closed
  output_hold: zoh
  submodels:
    - {name: mode1, kind: mode, wn: 2.05, zeta: 0.26, gain: 0.97, forgetting: 0.999}
    - {name: mode2, kind: mode, wn: 6.85, zeta: 0.048, gain: 0.52, forgetting: 0.999}
    - {name: mode3, kind: mode, wn: 25.6, zeta: 0.095, gain: 0.19, forgetting: 0.999}
controller:
  numerator: [0.02329, -0.02058, 0.00454]
  denominator: [1, -1, 0]
plant:
  noise_variance: 0.01
  modes:
    - {name: mode1, kind: mode, wn: 2.0, zeta: 0.25, gain: 1.0}
    - {name: mode2, kind: mode, wn: 7.0, zeta: 0.05, gain: 0.5}
    - {name: mode3, kind: mode, wn: 25.0, zeta: 0.1, gain: 0.2}
simulation:
  duration: 2400
  seed: 3
  reference: {type: square, frequency_hz: 0.25, amplitude: 1.0}
estimator:
  warmup: 50
  fit_on_warmup: true
)";

// Largest excursion of each estimate from the truth over the record after the
// warm-up: wn and gain relative, zeta absolute.
struct Excursion {
  double wn = 0.0, zeta = 0.0, gain = 0.0;
};

std::vector<Excursion> track_excursions(double stabilisation) {
  const Config c = parse_config(kOpenDirections, "open-directions");
  const SimulationResult sim = simulate(*c.plant, *c.experiment);
  EstimatorSettings s = c.estimator;
  s.stabilisation = stabilisation;
  s.stabilisations.clear();  // the config's per-submodel copies would override it
  RecursiveEstimator est(c.model, s);
  std::vector<Excursion> worst(3);
  for (Eigen::Index k = 0; k < sim.record.size(); ++k) {
    est.step({sim.record.t(k), sim.record.u(k), sim.record.y(k), sim.record.r(k)});
    if (est.status().warming_up) continue;
    for (int i = 0; i < 3; ++i) {
      const ModalParameters truth = c.plant->modes[i].modal;
      const ModalParameters e = est.mode(i).value;
      worst[i].wn = std::max(worst[i].wn, std::abs(e.wn / truth.wn - 1.0));
      worst[i].zeta = std::max(worst[i].zeta, std::abs(e.zeta - truth.zeta));
      worst[i].gain = std::max(worst[i].gain, std::abs(e.gain / truth.gain - 1.0));
    }
  }
  EXPECT_EQ(est.status().resets, 0u);
  return worst;
}

TEST(RecursiveEstimatorForgetting, StabilisedForgettingKeepsAHealthyLoopWithOpenDirectionsNearTheTruth) {
  const auto worst = track_excursions(EstimatorSettings{}.stabilisation);
  for (int i = 0; i < 3; ++i) {
    EXPECT_LT(worst[i].wn, 0.2) << "mode " << i + 1;
    EXPECT_LT(worst[i].zeta, 0.1) << "mode " << i + 1;
    EXPECT_LT(worst[i].gain, 0.3) << "mode " << i + 1;
  }
}

// The record does leave directions open: with plain exponential forgetting the
// slowest mode wanders far beyond those bounds.
TEST(RecursiveEstimatorForgetting, PlainExponentialForgettingWandersOnTheSameLoop) {
  const auto worst = track_excursions(0.0);
  EXPECT_GT(worst[0].wn, 0.2);
  EXPECT_GT(worst[0].zeta, 0.1);
  EXPECT_GT(worst[0].gain, 0.3);
}

}  // namespace
}  // namespace modalwatch
