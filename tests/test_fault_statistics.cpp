// The fault detector's statistics on simulated estimate streams: estimates as an
// estimator with memory tau reports them (the truth through a first-order lag of
// time constant tau, plus errors AR(1) over tau with the reported covariance).
// Stationary streams raise false alarms at the stated rate and none at the
// defaults; steps and ramps are flagged within a stated delay; a slow drift the
// chi-square misses is caught by the CUSUM; a settling estimate does not become
// the baseline; a baseline's own uncertainty widens the test.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Cholesky>

#include "modalwatch/fault_detector.hpp"

namespace modalwatch {
namespace {

constexpr double kPeriod = 0.1;                 // s between updates (the publish period)
constexpr double kMemory = kDefaultMemoryTime;  // s
const std::vector<ModalParameters> kTruth = {{60.0, 0.05, 2.0}, {150.0, 0.03, 0.5}, {400.0, 0.02, 0.1}};

Eigen::Vector3d vec(const ModalParameters& p) { return {p.wn, p.zeta, p.gain}; }
ModalParameters params(const Eigen::Vector3d& v) { return {v(0), v(1), v(2)}; }

// Covariance with relative std `rel` of each quantity and correlations 0.5
// (wn, zeta), -0.3 (zeta, gain), 0.2 (wn, gain).
Eigen::Matrix3d covariance(const ModalParameters& x, double rel) {
  Eigen::Matrix3d corr;
  corr << 1.0, 0.5, 0.2, 0.5, 1.0, -0.3, 0.2, -0.3, 1.0;
  const Eigen::Vector3d sd = rel * vec(x).cwiseAbs();
  return sd.asDiagonal() * corr * sd.asDiagonal();
}

// One mode's estimates, advanced by kPeriod per call.
struct Estimates {
  Estimates(const ModalParameters& truth, const Eigen::Matrix3d& c, std::uint64_t seed, double tau = kMemory)
      : mean(vec(truth)),
        cov(c),
        l(Eigen::LLT<Eigen::Matrix3d>(c).matrixL()),
        rho(std::exp(-kPeriod / tau)),
        rng(seed) {
    e = Eigen::Vector3d(z(rng), z(rng), z(rng));  // stationary from the start
  }
  ModalParameters next(const ModalParameters& truth) {
    mean += (1.0 - rho) * (vec(truth) - mean);
    const double s = std::sqrt(1.0 - rho * rho);
    for (int q = 0; q < 3; ++q) e(q) = rho * e(q) + s * z(rng);
    return params(mean + l * e);
  }
  Eigen::Vector3d mean, e;
  Eigen::Matrix3d cov, l;
  double rho;
  std::mt19937_64 rng;
  std::normal_distribution<double> z;
};

FaultDetectorSettings configured(const std::vector<ModalParameters>& baseline) {
  FaultDetectorSettings s;
  for (std::size_t i = 0; i < baseline.size(); ++i) {
    s.mode_names.push_back("mode" + std::to_string(i + 1));
    s.baselines.emplace_back(baseline[i]);
  }
  return s;
}

// A detector fed by one Estimates per mode.
struct Feed {
  Feed(FaultDetectorSettings s, std::vector<Estimates> e) : detector(std::move(s)), est(std::move(e)) {
    value.resize(est.size());
    cov.resize(est.size());
    for (std::size_t i = 0; i < est.size(); ++i) cov[i] = est[i].cov;
    changes.reserve(kQuantities * est.size());
  }
  double t() const { return static_cast<double>(k) * kPeriod; }
  const std::vector<FlagChange>& step(const std::vector<ModalParameters>& truth) {
    for (std::size_t i = 0; i < est.size(); ++i) value[i] = est[i].next(truth[i]);
    changes.clear();
    detector.update(t(), value, cov, true, changes);
    log.insert(log.end(), changes.begin(), changes.end());
    ++k;
    return changes;
  }
  const QuantityStatus& q(int mode, Quantity quantity) const {
    return detector.status()[mode].quantity[static_cast<int>(quantity)];
  }
  FaultDetector detector;
  std::vector<Estimates> est;
  std::vector<ModalParameters> value;
  std::vector<Eigen::Matrix3d> cov;
  std::vector<FlagChange> changes, log;
  long k = 0;
};

ModalParameters with(ModalParameters p, Quantity q, double factor) {
  switch (q) {
    case Quantity::wn:
      p.wn *= factor;
      break;
    case Quantity::zeta:
      p.zeta *= factor;
      break;
    default:
      p.gain *= factor;
      break;
  }
  return p;
}

TEST(FaultStatistics, ChiSquareTailOfThreeDegreesOfFreedom) {
  // Tabulated 95 % and 99 % quantiles of chi-square(3).
  EXPECT_NEAR(chi_square3_tail(7.814727903), 0.05, 1e-9);
  EXPECT_NEAR(chi_square3_tail(11.34486673), 0.01, 1e-9);
  EXPECT_EQ(chi_square3_tail(0.0), 1.0);
}

// ------------------------------------------------------------------ false alarms

TEST(FaultStatistics, StationaryEstimatesRaiseFalseAlarmsAtTheStatedRateAndNoneAtTheDefaults) {
  // Three modes, 20 simulated hours each, errors AR(1) over memories of 1, 2 and
  // 4 s with 1 % relative std and correlated quantities, baselines exact.
  // `stated`: a false alarm every half hour per mode, the relative threshold and
  // the hold time off, attribution at 1 std. `defaults`: the default settings
  // (1000 h, 5 %, 2 s hold) but for the memories.
  constexpr double hours = 20.0, interval = 0.5;
  const std::vector<double> memory = {1.0, 2.0, 4.0};
  FaultDetectorSettings stated = configured(kTruth), defaults = configured(kTruth);
  stated.memory_time = defaults.memory_time = memory;
  stated.false_alarm_interval = interval;
  for (auto& th : stated.thresholds) {
    th.relative_threshold = 1e-12;
    th.sigma_threshold = 1.0;
    th.hold_time = th.clear_time = 0.0;
  }
  std::vector<Estimates> est, est_default;
  for (std::size_t i = 0; i < kTruth.size(); ++i) {
    est.emplace_back(kTruth[i], covariance(kTruth[i], 0.01), 100 + i, memory[i]);
    est_default.emplace_back(kTruth[i], covariance(kTruth[i], 0.01), 100 + i, memory[i]);  // the same stream
  }
  Feed a(stated, est), d(defaults, est_default);
  // A longer memory: fewer independent tests per hour, a lower chi-square threshold.
  EXPECT_GT(a.detector.thresholds(0).chi_square, a.detector.thresholds(2).chi_square);
  std::vector<int> per_mode(kTruth.size(), 0);
  int alarms = 0, by_chi = 0, by_cusum = 0;
  std::vector<bool> up(kTruth.size(), false);
  const long n = std::lround(hours * 3600.0 / kPeriod);
  for (long j = 0; j < n; ++j) {
    a.step(kTruth);
    d.step(kTruth);
    for (const FlagChange& c : a.changes) {
      if (!c.raised || up[static_cast<std::size_t>(c.mode)]) continue;
      // A mode's alarm: its first flag rising while none is up.
      ++alarms;
      ++per_mode[static_cast<std::size_t>(c.mode)];
      (c.chi_square > a.detector.thresholds(c.mode).chi_square ? by_chi : by_cusum) += 1;
      up[static_cast<std::size_t>(c.mode)] = true;
    }
    for (std::size_t i = 0; i < kTruth.size(); ++i) {
      bool any = false;
      for (const QuantityStatus& s : a.detector.status()[i].quantity) any = any || s.flagged;
      up[i] = any;
    }
    ASSERT_FALSE(d.detector.any_flag()) << "defaults, update " << j;
  }
  const double expected = kTruth.size() * hours / interval;
  std::printf(
      "  %g mode-hours at %g h between false alarms: %d alarms (%d chi-square, %d CUSUM), %g expected"
      " (%g each)\n",
      kTruth.size() * hours, interval, alarms, by_chi, by_cusum, expected, expected / 2);
  for (std::size_t i = 0; i < kTruth.size(); ++i) {
    const DetectionThresholds& th = a.detector.thresholds(static_cast<int>(i));
    std::printf("  memory %g s: h = %.2f, b = %.2f, k = %.4f; %d alarms, %g expected\n", memory[i], th.chi_square,
                th.cusum, th.cusum_reference, per_mode[i], hours / interval);
    EXPECT_GT(per_mode[i], hours / interval / 2.0) << "memory " << memory[i];
    EXPECT_LT(per_mode[i], hours / interval * 2.0) << "memory " << memory[i];
  }
  EXPECT_GT(alarms, expected / 2.0);
  EXPECT_LT(alarms, expected * 2.0);
  // Each path within a factor 3 of its half.
  EXPECT_GT(by_chi, expected / 6.0);
  EXPECT_LT(by_chi, expected * 1.5);
  EXPECT_GT(by_cusum, expected / 6.0);
  EXPECT_LT(by_cusum, expected * 1.5);
  EXPECT_TRUE(d.log.empty());
}

// ------------------------------------------------------------------ real changes

// Truth steps by +-2x the relative threshold in one quantity after a quiet
// minute; the flag must rise within hold_time + 2 memories (the lagged estimate
// is then 86 % of the way, 8.6 std past the baseline) and nothing else may.
TEST(FaultStatistics, StepsOfTwiceTheRelativeThresholdAreFlaggedWithinHoldPlusTwoMemories) {
  const FaultThresholds th;
  const double bound = th.hold_time + 2.0 * kMemory;
  for (Quantity q : {Quantity::wn, Quantity::zeta, Quantity::gain})
    for (double sign : {1.0, -1.0}) {
      Feed r(configured({kTruth[0]}), {Estimates(kTruth[0], covariance(kTruth[0], 0.01), 7)});
      for (int j = 0; j < 600; ++j) r.step(kTruth);
      ASSERT_TRUE(r.log.empty());
      const double t_step = r.t();
      const ModalParameters changed = with(kTruth[0], q, 1.0 + sign * 2.0 * th.relative_threshold);
      double t_flag = NAN;
      for (int j = 0; j < 600 && std::isnan(t_flag); ++j) {
        const double now = r.t();
        r.step({changed});
        if (r.q(0, q).flagged) t_flag = now;
      }
      std::printf("  %s %+g %%: flagged %.1f s after the step\n",
                  q == Quantity::wn     ? "wn"
                  : q == Quantity::zeta ? "zeta"
                                        : "gain",
                  sign * 200.0 * th.relative_threshold, t_flag - t_step);
      ASSERT_FALSE(std::isnan(t_flag));
      EXPECT_LE(t_flag - t_step, bound);
      EXPECT_GE(t_flag - t_step, th.hold_time - 1e-9);
      ASSERT_EQ(r.log.size(), 1u);
      EXPECT_EQ(r.log[0].quantity, q);
      EXPECT_EQ(r.log[0].deviation_relative > 0.0, sign > 0.0);
    }
}

TEST(FaultStatistics, ARampIsFlaggedBeforeTheTruthIsTwiceTheThresholdOffPlusTheHold) {
  // wn falls 0.2 %/s after a quiet minute: 5 % off at 25 s, 10 % at 50 s.
  const FaultThresholds th;
  Feed r(configured({kTruth[0]}), {Estimates(kTruth[0], covariance(kTruth[0], 0.01), 11)});
  for (int j = 0; j < 600; ++j) r.step(kTruth);
  const double t0 = r.t(), rate = 0.002;
  double t_flag = NAN;
  for (int j = 0; j < 1000 && std::isnan(t_flag); ++j) {
    const double now = r.t();
    r.step({with(kTruth[0], Quantity::wn, 1.0 - rate * (now - t0))});
    if (r.q(0, Quantity::wn).flagged) t_flag = now;
  }
  const double t_twice = 2.0 * th.relative_threshold / rate;
  std::printf("  ramp: flagged at %.1f s, truth %.1f %% off (threshold %.0f %% at %.0f s)\n", t_flag - t0,
              100.0 * rate * (t_flag - t0), 100.0 * th.relative_threshold, th.relative_threshold / rate);
  ASSERT_FALSE(std::isnan(t_flag));
  EXPECT_LE(t_flag - t0, t_twice + th.hold_time);
  EXPECT_GT(t_flag - t0, th.relative_threshold / rate * 0.8) << "not while the change is still well inside 5 %";
  ASSERT_EQ(r.log.size(), 1u);
  EXPECT_EQ(r.log[0].quantity, Quantity::wn);
}

// Where the estimate's std is small beside the relative threshold (0.1 %
// against 5 %), the threshold decides, and the estimate crosses it with its
// memory's lag behind the truth, 0.6 memory or more. The relative test reads
// the estimate with that lag undone down to a fifth of a memory: over steps
// and ramps (over 1 and 5 memories, the bank's range) of twice the threshold,
// the flag comes within the hold and 0.3 memory of the truth's crossing in
// the median and 0.5 memory at most.
TEST(FaultStatistics, WhereTheRelativeThresholdDecidesTheFlagFollowsTheTruthNotTheEstimatesLag) {
  const FaultThresholds th;
  const double twice = 2.0 * th.relative_threshold;
  std::vector<double> beyond_hold;  // memories
  for (Quantity q : {Quantity::wn, Quantity::gain})
    for (const double ramp : {0.0, 1.0, 5.0})  // memories
      for (std::uint64_t seed : {31u, 32u, 33u}) {
        const double sign = q == Quantity::wn ? -1.0 : 1.0;
        Feed r(configured({kTruth[0]}), {Estimates(kTruth[0], covariance(kTruth[0], 0.001), seed)});
        for (int j = 0; j < 600; ++j) r.step(kTruth);
        ASSERT_TRUE(r.log.empty());
        const double t0 = r.t(), span = ramp * kMemory;
        // The truth crosses the threshold halfway along the ramp.
        const double t_cross = t0 + 0.5 * span;
        double t_flag = NAN, t_estimate = NAN;
        for (int j = 0; j < 1200 && std::isnan(t_flag); ++j) {
          const double now = r.t();
          const double share = span > 0.0 ? std::clamp((now - t0) / span, 0.0, 1.0) : 1.0;
          r.step({with(kTruth[0], q, 1.0 + sign * twice * share)});
          if (std::isnan(t_estimate) && std::abs(r.q(0, q).deviation_relative) > th.relative_threshold)
            t_estimate = now;
          if (r.q(0, q).flagged) t_flag = now;
        }
        const char* name = q == Quantity::wn ? "wn" : "gain";
        ASSERT_FALSE(std::isnan(t_flag)) << name << " " << ramp;
        beyond_hold.push_back((t_flag - th.hold_time - t_cross) / kMemory);
        std::printf(
            "  %s, ramp over %g memories, seed %d: flagged %.2f memory after the truth crossed and the"
            " hold, the estimate crossed %.2f after the truth\n",
            name, ramp, static_cast<int>(seed), beyond_hold.back(), (t_estimate - t_cross) / kMemory);
        EXPECT_LE(beyond_hold.back(), 0.5 + 1e-9) << name << " " << ramp << " " << seed;
        EXPECT_GE(t_estimate - t_cross, 0.6 * kMemory) << name << " " << ramp << " " << seed;
        ASSERT_EQ(r.log.size(), 1u);
        EXPECT_EQ(r.log[0].quantity, q);
      }
  std::sort(beyond_hold.begin(), beyond_hold.end());
  const double median = 0.5 * (beyond_hold[beyond_hold.size() / 2 - 1] + beyond_hold[beyond_hold.size() / 2]);
  std::printf("  median %.2f memory after the truth crossed and the hold\n", median);
  EXPECT_LE(median, 0.3);
}

// The lag undone, nothing overshoots: a step of 0.8 times the threshold in any
// quantity stays unflagged, over 20 streams of two minutes each.
TEST(FaultStatistics, AStepUnderTheRelativeThresholdIsNotFlaggedWithTheLagUndone) {
  const FaultThresholds th;
  for (Quantity q : {Quantity::wn, Quantity::zeta, Quantity::gain})
    for (std::uint64_t seed = 40; seed < 60; ++seed) {
      const double sign = seed % 2 == 0 ? 1.0 : -1.0;
      Feed r(configured({kTruth[0]}), {Estimates(kTruth[0], covariance(kTruth[0], 0.002), seed)});
      for (int j = 0; j < 600; ++j) r.step(kTruth);
      const ModalParameters changed = with(kTruth[0], q, 1.0 + sign * 0.8 * th.relative_threshold);
      double largest = 0.0;
      for (int j = 0; j < 1200; ++j) {
        r.step({changed});
        largest = std::max(largest, std::abs(r.q(0, q).deviation_relative));
      }
      EXPECT_TRUE(r.log.empty()) << "quantity " << static_cast<int>(q) << ", seed " << seed;
      EXPECT_GT(largest, 0.75 * th.relative_threshold) << "the estimate did follow the step";
    }
}

TEST(FaultStatistics, ASlowDriftTheChiSquareMissesIsCaughtByTheCusum) {
  // zeta estimated with a 2 % std; it drifts +5 % (2.5 std) over a minute and
  // stays there. The user's threshold is 3 %. T2 (past 38 at the defaults) sees
  // 2.5 std; the CUSUM, drifting (2.5 - 0.5) / sqrt(2 tau) = 1 per second, reaches
  // its threshold (31) about 70 s after the drift began.
  FaultDetectorSettings st = configured({kTruth[0]});
  for (auto& th : st.thresholds) th.relative_threshold = 0.03;
  Feed r(st, {Estimates(kTruth[0], covariance(kTruth[0], 0.02), 23)});
  for (int j = 0; j < 600; ++j) r.step(kTruth);
  ASSERT_TRUE(r.log.empty());
  const double t0 = r.t(), h = r.detector.thresholds(0).chi_square;
  int chi_square_past = 0;
  double t_flag = NAN;
  for (int j = 0; j < 3000 && std::isnan(t_flag); ++j) {
    const double now = r.t();
    r.step({with(kTruth[0], Quantity::zeta, 1.0 + 0.05 * std::min(1.0, (now - t0) / 60.0))});
    if (r.detector.status()[0].chi_square > h) ++chi_square_past;
    if (r.q(0, Quantity::zeta).flagged) t_flag = now;
  }
  std::printf("  drift: flagged %.1f s after it began; T2 past h in %d updates\n", t_flag - t0, chi_square_past);
  ASSERT_FALSE(std::isnan(t_flag));
  EXPECT_EQ(chi_square_past, 0);
  ASSERT_EQ(r.log.size(), 1u);
  EXPECT_EQ(r.log[0].quantity, Quantity::zeta);
  EXPECT_LT(r.log[0].chi_square, h);
  EXPECT_GE(r.log[0].cusum, 1.0);
  EXPECT_LT(t_flag - t0, 60.0 + 60.0);
}

// ------------------------------------------------------------------ baselines

TEST(FaultStatistics, ASettlingEstimateDoesNotBecomeTheBaselineUntilSettled) {
  // Learned baseline. The gain estimate starts 13 % high and converges with a
  // 20 s time constant; its reported std starts at 10 % and falls to 0.1 % with a
  // 10 s time constant (uncertain until it is below 2.5 %, at 14 s).
  FaultDetectorSettings st = configured({kTruth[0]});
  st.baselines[0] = std::nullopt;
  Feed r(st, {Estimates(kTruth[0], covariance(kTruth[0], 0.001), 31)});
  bool seen_uncertain = false, seen_drifting = false;
  double t_ready = NAN;
  for (int j = 0; j < 6000; ++j) {
    const double now = r.t();
    const double offset = 0.13 * std::exp(-now / 20.0);
    const double rel_std = std::max(0.001, 0.1 * std::exp(-now / 10.0));
    r.cov[0] = covariance(kTruth[0], rel_std);
    r.est[0].mean(2) = kTruth[0].gain * (1.0 + offset);  // the settling, set directly
    r.step(kTruth);
    const ModeStatus& m = r.detector.status()[0];
    if (std::isnan(t_ready)) {
      if (m.state != BaselineState::learning) {
        t_ready = now;
        continue;
      }
      EXPECT_FALSE(m.baseline_ready);
      seen_uncertain = seen_uncertain || m.learn_hold == LearnHold::uncertain;
      seen_drifting = seen_drifting || m.learn_hold == LearnHold::drifting;
    }
  }
  const ModeStatus& m = r.detector.status()[0];
  const double bias = m.baseline.value.gain / kTruth[0].gain - 1.0;
  std::printf("  settled at %.1f s after %d restarts: gain baseline %+.2f %% off the truth (13 %% at the start)\n",
              t_ready, m.learn_restarts, 100.0 * bias);
  ASSERT_FALSE(std::isnan(t_ready));
  EXPECT_EQ(m.state, BaselineState::ready);
  EXPECT_TRUE(seen_uncertain);
  EXPECT_TRUE(seen_drifting);
  EXPECT_GE(m.learn_restarts, 1);
  EXPECT_GT(t_ready, 14.0 + FaultDetectorSettings{}.learn_window);
  EXPECT_LT(std::abs(bias), 0.25 * FaultThresholds{}.relative_threshold);
  EXPECT_TRUE(r.log.empty()) << "the healthy mode is never flagged";
}

TEST(FaultStatistics, TheBaselinesUncertaintyWidensTheTest) {
  // wn 8 % off a configured baseline (past the 5 % threshold), estimated to 0.1 %.
  // Exact baseline: flagged. Baseline known to 5 %: 1.6 std of d, not flagged.
  const ModalParameters off = with(kTruth[0], Quantity::wn, 1.08);
  FaultDetectorSettings exact = configured({kTruth[0]});
  FaultDetectorSettings loose = exact;
  loose.baseline_std = {{0.05 * kTruth[0].wn, 0.05 * kTruth[0].zeta, 0.05 * kTruth[0].gain}};
  Feed a(exact, {Estimates(kTruth[0], covariance(kTruth[0], 0.001), 41)});
  Feed b(loose, {Estimates(kTruth[0], covariance(kTruth[0], 0.001), 41)});
  for (int j = 0; j < 1200; ++j) {
    a.step({off});
    b.step({off});
  }
  EXPECT_TRUE(a.q(0, Quantity::wn).flagged);
  EXPECT_FALSE(b.detector.any_flag());
  EXPECT_TRUE(b.log.empty());
  EXPECT_NEAR(b.detector.status()[0].baseline.covariance_matrix()(0, 0), std::pow(0.05 * kTruth[0].wn, 2), 1e-12);
  EXPECT_NEAR(b.q(0, Quantity::wn).deviation_sigma, 0.08 / std::hypot(0.05, 0.001), 0.05);
  EXPECT_LT(b.detector.status()[0].chi_square, 4.0);
  EXPECT_EQ(b.q(0, Quantity::wn).cusum, 0.0) << "a deviation inside 3 std of the baseline is no drift";
}

}  // namespace
}  // namespace modalwatch
