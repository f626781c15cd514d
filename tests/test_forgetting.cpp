// Forgetting where the data leave directions open: a healthy closed loop whose
// square-wave setpoint and slow controller excite few frequencies, so that
// exponential forgetting alone winds P up in some directions of theta and lets
// the estimates wander with the noise. Stabilised forgetting (the default)
// must keep every estimate near the truth for the whole record.
// And forgetting faster than a lightly damped mode's prefilter forgets: the
// memory floor (EstimatorSettings::min_memory) must keep such a mode still.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>

#include <gtest/gtest.h>

#include "support.hpp"

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

// Plain: exponential forgetting alone, lambda fixed (no stabilisation, no memory floor).
std::vector<Excursion> track_excursions(bool plain) {
  const Config c = parse_config(kOpenDirections, "open-directions");
  const SimulationResult sim = simulate(*c.plant, *c.experiment);
  EstimatorSettings s = c.estimator;
  if (plain) s.stabilisation = s.min_memory = 0.0;
  s.stabilisations.clear();  // the config's per-submodel copies would override them
  s.min_memories.clear();
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
  // Healthy: no change of the output error for the CUSUM to find (40 min, 48,000 samples).
  if (!plain) {
    EXPECT_EQ(est.status().boosts, 0u);
  }
  return worst;
}

TEST(RecursiveEstimatorForgetting, StabilisedForgettingKeepsAHealthyLoopWithOpenDirectionsNearTheTruth) {
  const auto worst = track_excursions(false);
  for (int i = 0; i < 3; ++i) {
    EXPECT_LT(worst[i].wn, 0.2) << "mode " << i + 1;
    EXPECT_LT(worst[i].zeta, 0.1) << "mode " << i + 1;
    EXPECT_LT(worst[i].gain, 0.3) << "mode " << i + 1;
  }
}

// The record does leave directions open: with plain exponential forgetting the
// slowest mode wanders far beyond those bounds.
TEST(RecursiveEstimatorForgetting, PlainExponentialForgettingWandersOnTheSameLoop) {
  const auto worst = track_excursions(true);
  EXPECT_GT(worst[0].wn, 0.2);
  EXPECT_GT(worst[0].zeta, 0.1);
  EXPECT_GT(worst[0].gain, 0.3);
}

// A lightly damped mode (zeta 0.005, decay time 1/(zeta wn) = 3 s) driven at
// its resonance by a line of a multisine (lines every 3.5 Hz from 3.5 Hz, the
// mode at 10.5 Hz), open loop, SNR about 40 dB; lambda = 0.9998, a memory of 5 s
// (50 periods of the mode) but under two of its decay times. 200 memories after
// a warm-up fit over one; the model's start a few per cent off the plant.
constexpr const char* kResonantLine = R"(
sample_rate_hz: 1000
model:
  loop: open
  output_hold: zoh
  submodels:
    - {name: mode1, kind: mode, wn: 67.5, zeta: 0.006, gain: 1.0e-3, forgetting: 0.9998}
plant:
  noise_variance: 1.0e-9
  modes:
    - {name: mode1, kind: mode, wn: 65.97, zeta: 0.005, gain: 1.0e-3}
simulation:
  duration: 1000
  seed: 7
  input: {type: multisine, f_min_hz: 3, f_max_hz: 30, period_s: 0.2857142857142857, rms: 1.0}
estimator:
  warmup: 5
  fit_on_warmup: true
)";

struct ResonantLineRun {
  Excursion worst;  // relative, all three, from two memories after the warm-up on
  std::uint64_t resets = 0;
};

ResonantLineRun track_resonant_line(double min_memory, double settled_memory = EstimatorSettings{}.settled_memory,
                                    double damping_deadband = EstimatorSettings{}.damping_deadband) {
  const Config c = parse_config(kResonantLine, "resonant-line");
  const SimulationResult sim = simulate(*c.plant, *c.experiment);
  EstimatorSettings s = c.estimator;
  s.min_memory = min_memory;
  s.settled_memory = settled_memory;
  s.damping_deadband = damping_deadband;
  s.min_memories.clear();  // the config's per-submodel copies would override it
  RecursiveEstimator est(c.model, s);
  const ModalParameters truth = c.plant->modes[0].modal;
  ResonantLineRun run;
  for (Eigen::Index k = 0; k < sim.record.size(); ++k) {
    est.step({sim.record.t(k), sim.record.u(k), sim.record.y(k), 0.0});
    if (sim.record.t(k) < 15.0) continue;
    const ModalParameters e = est.mode(0).value;
    run.worst.wn = std::max(run.worst.wn, std::abs(e.wn / truth.wn - 1.0));
    run.worst.zeta = std::max(run.worst.zeta, std::abs(e.zeta / truth.zeta - 1.0));
    run.worst.gain = std::max(run.worst.gain, std::abs(e.gain / truth.gain - 1.0));
  }
  run.resets = est.status().resets;
  return run;
}

TEST(RecursiveEstimatorForgetting, AResonantModeWithAMemoryUnderTwoDecayTimesStaysAtTheTruth) {
  const ResonantLineRun run = track_resonant_line(EstimatorSettings{}.min_memory);
  EXPECT_EQ(run.resets, 0u);
  EXPECT_LT(run.worst.wn, 1e-3);
  EXPECT_LT(run.worst.zeta, 0.01);
  EXPECT_LT(run.worst.gain, 0.01);
}

// Without the floor, and with prefilters that take every update's damping, the
// same record winds zeta and the gain up together (the prefilter's loop) until
// the output error diverges, again and again. How often is chaotic: 7 to more
// than 10 resets, with the step kernel of another CPU or another way out of a
// reset.
TEST(RecursiveEstimatorForgetting, WithoutTheMemoryFloorOrTheDampingDeadbandTheResonantModeWindsUp) {
  const ResonantLineRun run = track_resonant_line(0.0, 0.0, 0.0);
  EXPECT_GE(run.resets, 3u);
  EXPECT_GT(run.worst.zeta, 0.3);
  EXPECT_GT(run.worst.gain, 0.3);
}

// The deadband alone opens that loop: without any memory floor (a memory of
// under two decay times), the prefilters' damping held within three std of the
// estimate's keeps the mode at the truth.
TEST(RecursiveEstimatorForgetting, TheDampingDeadbandAloneHoldsTheResonantModeWithoutTheMemoryFloor) {
  const ResonantLineRun run = track_resonant_line(0.0, 0.0);
  EXPECT_EQ(run.resets, 0u);
  EXPECT_LT(run.worst.wn, 1e-3);
  EXPECT_LT(run.worst.zeta, 0.01);
  EXPECT_LT(run.worst.gain, 0.01);
}

// One mode excited at one frequency, the Nyquist frequency (a square wave of
// two samples' period), open loop, SNR 57 dB: the data fix one combination of
// wn, zeta and the gain, and leave two directions open. lambda = 0.99707 (a
// memory of 9.6 s, 50 periods of the mode), 100 memories after a warm-up fit
// over one; the model's start a few per cent off the plant.
constexpr const char* kOneLine = R"(
sample_rate_hz: 35.65775
model:
  loop: open
  submodels:
    - {name: mode1, kind: mode, wn: 33.567, zeta: 0.16805, gain: 8.1335e-4, forgetting: 0.99707}
plant:
  noise_variance: 1.9776e-16
  modes:
    - {name: mode1, kind: mode, wn: 32.891, zeta: 0.20807, gain: 8.4224e-4}
simulation:
  duration: 956
  seed: 453466113
  input: {type: square, frequency_hz: 17.828877, amplitude: 1.0}
estimator:
  warmup: 9.563
  fit_on_warmup: true
)";

// Largest relative excursion of wn, zeta and the gain from the truth after the
// warm-up, with the given covariance bound.
Excursion track_one_line(double covariance_bound) {
  const Config c = parse_config(kOneLine, "one-line");
  const SimulationResult sim = simulate(*c.plant, *c.experiment);
  EstimatorSettings s = c.estimator;
  s.covariance_bound = covariance_bound;
  RecursiveEstimator est(c.model, s);
  const ModalParameters truth = c.plant->modes[0].modal;
  Excursion worst;
  for (Eigen::Index k = 0; k < sim.record.size(); ++k) {
    est.step({sim.record.t(k), sim.record.u(k), sim.record.y(k), 0.0});
    if (est.status().warming_up) continue;
    const ModalParameters e = est.mode(0).value;
    worst.wn = std::max(worst.wn, std::abs(e.wn / truth.wn - 1.0));
    worst.zeta = std::max(worst.zeta, std::abs(e.zeta / truth.zeta - 1.0));
    worst.gain = std::max(worst.gain, std::abs(e.gain / truth.gain - 1.0));
  }
  return worst;
}

TEST(RecursiveEstimatorForgetting, AModeExcitedAtOneFrequencyKeepsItsEstimateForAHundredMemories) {
  const Excursion worst = track_one_line(EstimatorSettings{}.covariance_bound);
  EXPECT_LT(worst.wn, 1e-3);
  EXPECT_LT(worst.zeta, 3e-3);
  EXPECT_LT(worst.gain, 3e-3);
}

// The directions the single line leaves open are what the default bound
// holds: ten times looser, the estimate glides along them, its output error
// grows, the change test boosts it further, and wn ends up percents off.
TEST(RecursiveEstimatorForgetting, WithATenTimesLooserCovarianceBoundTheSameModeWanders) {
  const Excursion worst = track_one_line(10.0 * EstimatorSettings{}.covariance_bound);
  EXPECT_GT(worst.wn, 0.05);
  EXPECT_GT(worst.gain, 0.2);
}

// The floor outside a change boost is settled_memory: min_memory, the shortest
// memory a boost may give, does not have to keep a mode still. Without the
// damping deadband, at 3 decay times throughout, the same record winds up
// (measured: 47 resets); with the settled floor of 9 it stays at the truth.
TEST(RecursiveEstimatorForgetting, TheSettledFloorHoldsTheResonantModeWhereMinMemoryAloneWouldNot) {
  const ResonantLineRun short_floor = track_resonant_line(3.0, 0.0, 0.0);
  EXPECT_GE(short_floor.resets, 3u);
  EXPECT_GT(short_floor.worst.zeta, 0.3);
  const ResonantLineRun settled = track_resonant_line(3.0, 9.0, 0.0);
  EXPECT_EQ(settled.resets, 0u);
  EXPECT_LT(settled.worst.wn, 1e-3);
  EXPECT_LT(settled.worst.zeta, 0.01);
  EXPECT_LT(settled.worst.gain, 0.01);
}

// The shipped flexible beam, whose flex mode (decay time 0.18 s, at its memory
// floor) loses 15 % stiffness over t = 30..32 s in closed loop. The change test
// finds the drift; with the settled floor of 9 decay times the mode it names
// is released to min_memory while it re-converges, and settles nearly as soon
// as with min_memory alone (measured: 1.54 s after the drift against 1.33 s;
// held at 9 decay times instead, 2.30 s).
double flex_settling_time(double settled_memory) {
  const Config c = load_config(test_support::source_file("config/flexible-beam-drift.yaml"));
  const SimulationResult sim = simulate(*c.plant, *c.experiment);
  EstimatorSettings s = c.estimator;
  s.settled_memory = settled_memory;
  RecursiveEstimator est(c.model, s);
  const PlantMode& flex = c.plant->modes[1];
  double last_off = 0.0;  // the last time after the drift that wn was 0.3 % or more off
  for (Eigen::Index k = 0; k < sim.record.size(); ++k) {
    const double t = sim.record.t(k);
    est.step({t, sim.record.u(k), sim.record.y(k), sim.record.r(k)});
    if (t < 32.0) continue;
    if (std::abs(est.mode(1).value.wn / flex.wn.at(t, flex.modal.wn) - 1.0) >= 0.003) last_off = t;
  }
  EXPECT_EQ(est.status().resets, 0u);
  return last_off - 32.0;
}

TEST(RecursiveEstimatorForgetting, AModeTheChangeTestNamesLeavesTheSettledFloorWhileItFollowsTheDrift) {
  const double min_memory_alone = flex_settling_time(0.0);
  ASSERT_GT(min_memory_alone, 0.5);  // the drift is followed, not known in advance
  const double settled = flex_settling_time(9.0);
  EXPECT_LT(settled, 1.25 * min_memory_alone);
}

}  // namespace
}  // namespace modalwatch
