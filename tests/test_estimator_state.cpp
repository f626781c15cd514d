// The recursive estimator's state as a value: state() and restore() resume
// estimation as after a gap, restore() rejects what does not fit, and the
// warm-up fit runs as a job on another thread with the same result.
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <variant>
#include <vector>

#include <gtest/gtest.h>

#include "estimator_support.hpp"

#include "modalwatch/estimator.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/simulator.hpp"

namespace modalwatch {
namespace {

using namespace test_support;

// An EstimatorState written out value by value, to be altered and read back
// unchecked: the states restore() must reject.
class StateTape final : public StateWriter, public StateReader {
 public:
  explicit StateTape(const EstimatorState& state) { state.write(*this); }
  // The nth value written under the name `what`.
  template <class T>
  T& at(std::string_view what, int nth = 0) {
    for (auto& [name, value] : values_)
      if (name == what && nth-- == 0) return std::get<T>(value);
    throw std::logic_error("no value named " + std::string(what));
  }
  EstimatorState read() {
    next_ = 0;
    return EstimatorState::read(*this);
  }

  void flag(bool v, const char* what) override { values_.emplace_back(what, v); }
  void count(std::size_t v, const char* what) override { values_.emplace_back(what, std::uint64_t{v}); }
  void name(const std::string& v, const char* what) override { values_.emplace_back(what, v); }
  void integer(std::int32_t v, const char* what) override { values_.emplace_back(what, v); }
  void counter(std::uint64_t v, const char* what) override { values_.emplace_back(what, v); }
  void real(double v, const char* what) override { values_.emplace_back(what, v); }
  void reals(const Eigen::VectorXd& v, const char* what) override { values_.emplace_back(what, v); }
  void matrix(const Eigen::MatrixXd& v, const char* what) override { values_.emplace_back(what, v); }

  bool flag(const char*) override { return next<bool>(); }
  std::size_t count(const char*) override { return next<std::uint64_t>(); }
  std::string name(const char*) override { return next<std::string>(); }
  std::int32_t integer(const char*, std::int32_t, std::int32_t) override { return next<std::int32_t>(); }
  std::uint64_t counter(const char*) override { return next<std::uint64_t>(); }
  double real(const char*) override { return next<double>(); }
  Eigen::VectorXd reals(Eigen::Index, const char*) override { return next<Eigen::VectorXd>(); }
  Eigen::MatrixXd matrix(Eigen::Index, const char*) override { return next<Eigen::MatrixXd>(); }
  [[noreturn]] void fail(const std::string& what) override { throw std::invalid_argument(what); }

 private:
  using Value = std::variant<bool, std::int32_t, std::uint64_t, double, std::string, Eigen::VectorXd, Eigen::MatrixXd>;
  template <class T>
  T next() {
    return std::get<T>(values_.at(next_++).second);
  }
  std::vector<std::pair<std::string, Value>> values_;
  std::size_t next_ = 0;
};

// The seed's record, interrupted half way: state(), a fresh estimator with the
// same settings, restore(), the rest, as a daemon restart does it (the restarted
// daemon's next sample comes after a time gap). Everything the estimator carries
// is in the state, so the resumed run must equal an uninterrupted run that sees
// the same time gap, to rounding (theta goes through physical units and back:
// 1e-15 relative; 1e-9 allows what that grows to over 10000 updates). The gap's
// own effect (prefilters and controller restart from rest, a transient that the
// updates partly absorb) is measured against the run without a gap and printed.
TEST(RecursiveEstimator, StateAndRestoreResumeWithoutWarmupAsAfterAGap) {
  const Config c = paper_config();
  const auto sim = simulate(*c.plant, *c.experiment);
  const Record& r = sim.record;
  const EstimatorSettings st = c.estimator;  // the shipped forgetting and warm-up
  const Eigen::Index half = r.size() / 2;
  const double restart_time = 2.0;  // s, how long the daemon was down
  auto sample = [&](Eigen::Index k, bool gap) {
    return Sample{r.t(k) + (gap && k >= half ? restart_time : 0.0), r.u(k), r.y(k), r.r(k)};
  };

  RecursiveEstimator smooth(c.model, st);  // no interruption at all
  RecursiveEstimator gapped(c.model, st);  // the same time gap, no restart
  RecursiveEstimator first(c.model, st);
  for (Eigen::Index k = 0; k < half; ++k) {
    smooth.step(sample(k, false));
    gapped.step(sample(k, true));
    first.step(sample(k, true));
  }
  const EstimatorState saved = first.state();
  ASSERT_TRUE(saved.warmed_up());
  EXPECT_EQ(saved.last_sample_time(), r.t(half - 1));

  RecursiveEstimator resumed(c.model, st);
  ASSERT_TRUE(resumed.status().warming_up);
  resumed.restore(saved);
  // No warm-up: the saved estimate is there at once and updates go on.
  EXPECT_FALSE(resumed.status().warming_up);
  EXPECT_EQ(resumed.status().samples, first.status().samples);
  EXPECT_EQ(resumed.status().updates, first.status().updates);
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(resumed.mode(i).value.wn / first.mode(i).value.wn, 1.0, 1e-14);
    EXPECT_NEAR(resumed.mode(i).std.wn / first.mode(i).std.wn, 1.0, 1e-12);
  }
  const std::uint64_t updates_at_restore = resumed.status().updates;
  EXPECT_TRUE(resumed.step(sample(half, true)) & kGap);
  gapped.step(sample(half, true));
  smooth.step(sample(half, false));
  // No warm-up: the filters run and, once the free response of the model's
  // slowest mode has decayed to a tenth and their output has caught up with the
  // data, theta updates. Here the decay decides: mode 2's estimate at the
  // restart decays at 0.0625 /s, 2.3 / 0.0625 = 37 s.
  Eigen::Index first_update = -1;
  for (Eigen::Index k = half + 1; k < half + 1000; ++k) {
    EXPECT_FALSE(resumed.step(sample(k, true)) & kWarmingUp);
    if (first_update < 0 && resumed.status().updates > updates_at_restore) first_update = k - half;
    gapped.step(sample(k, true));
    smooth.step(sample(k, false));
  }
  std::printf("theta updates resume %lld samples after the restart\n", static_cast<long long>(first_update));
  ASSERT_GT(first_update, 0) << "no update within 1000 samples (50 s) of the restart";

  double max_gap_effect[3] = {0, 0, 0}, end_gap_effect[3] = {0, 0, 0}, max_gap_relative[3] = {0, 0, 0};
  for (Eigen::Index k = half + 1000; k < r.size(); ++k) {
    smooth.step(sample(k, false));
    gapped.step(sample(k, true));
    resumed.step(sample(k, true));
    for (int i = 0; i < 3; ++i) {
      const ModeEstimate a = smooth.mode(i), g = gapped.mode(i);
      max_gap_effect[i] = std::max(max_gap_effect[i], std::abs(g.value.wn - a.value.wn) / a.std.wn);
      max_gap_relative[i] = std::max(max_gap_relative[i], std::abs(g.value.wn / a.value.wn - 1.0));
      if (k == r.size() - 1) end_gap_effect[i] = std::abs(g.value.wn - a.value.wn) / a.std.wn;
    }
  }
  for (int i = 0; i < 3; ++i)
    std::printf("mode %d: a %.0f s gap at %.0f s moves wn by up to %.3g sigma, %.2g %% (%.3g sigma at the end)\n",
                i + 1, restart_time, r.t(half), max_gap_effect[i], 100.0 * max_gap_relative[i], end_gap_effect[i]);
  const EstimatorStatus &a = gapped.status(), &b = resumed.status();
  EXPECT_EQ(b.samples, a.samples);
  EXPECT_EQ(b.updates, a.updates);
  EXPECT_EQ(b.gaps, a.gaps);
  EXPECT_EQ(b.outliers, a.outliers);
  EXPECT_EQ(b.resets, a.resets);
  EXPECT_EQ(b.low_excitation_samples, a.low_excitation_samples);
  for (int i = 0; i < 3; ++i) {
    const ModeEstimate g = gapped.mode(i), e = resumed.mode(i);
    EXPECT_NEAR(e.value.wn / g.value.wn, 1.0, 1e-9) << "mode " << i + 1;
    EXPECT_NEAR(e.value.zeta / g.value.zeta, 1.0, 1e-9) << "mode " << i + 1;
    EXPECT_NEAR(e.value.gain / g.value.gain, 1.0, 1e-9) << "mode " << i + 1;
    EXPECT_NEAR(e.std.wn / g.std.wn, 1.0, 1e-9) << "mode " << i + 1;
  }
  EXPECT_NEAR(resumed.residual_rms() / gapped.residual_rms(), 1.0, 1e-9);
}

TEST(RecursiveEstimator, RestoreRejectsAStateOfAnotherStructureOrWithNonFiniteNumbers) {
  const Config c = paper_config();
  ExperimentSpec e = *c.experiment;
  e.duration = 100.0;
  const auto sim = simulate(*c.plant, e);
  const EstimatorSettings st = settings_for(c, {0.999, 0.999, 0.999}, 1000);
  RecursiveEstimator est(c.model, st);
  run(est, sim.record);
  const EstimatorState good = est.state();
  RecursiveEstimator other(c.model, st);
  EXPECT_NO_THROW(other.restore(good));

  // States of another structure: from estimators on other models.
  AdditiveModel fewer = c.model;
  fewer.submodels.pop_back();
  EstimatorSettings fewer_settings = st;
  fewer_settings.forgetting.pop_back();
  EXPECT_THROW(other.restore(RecursiveEstimator(fewer, fewer_settings).state()), std::invalid_argument);
  AdditiveModel rigid = c.model;
  rigid.submodels[1] = make_rigid_body("mode2", 1.0);
  EXPECT_THROW(other.restore(RecursiveEstimator(rigid, st).state()), std::invalid_argument);
  // Altered values, through the state's serialisation.
  StateTape tape(good);
  tape.at<Eigen::MatrixXd>("P", 2) = Eigen::MatrixXd::Identity(4, 4);
  EXPECT_THROW(other.restore(tape.read()), std::invalid_argument);
  tape = StateTape(good);
  tape.at<Eigen::MatrixXd>("P", 0)(1, 1) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(other.restore(tape.read()), std::invalid_argument);
  tape = StateTape(good);
  tape.at<Eigen::VectorXd>("coefficients a", 0)(0) = std::numeric_limits<double>::infinity();
  EXPECT_THROW(other.restore(tape.read()), std::invalid_argument);
  tape = StateTape(good);
  tape.at<double>("noise variance") = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(other.restore(tape.read()), std::invalid_argument);
  tape = StateTape(good);
  tape.at<std::int32_t>("last reset reason") = 99;  // made up
  EXPECT_THROW(other.restore(tape.read()), std::invalid_argument);
  EXPECT_EQ(StateTape(good).read(), good);
  // A failed restore leaves the estimator as it was.
  for (int i = 0; i < 3; ++i) EXPECT_EQ(other.mode(i).value.wn, est.mode(i).value.wn);
  // A state written during warm-up carries no estimate: the warm-up starts again.
  RecursiveEstimator young(c.model, st);
  for (int k = 0; k < 10; ++k) young.step({sim.record.t(k), sim.record.u(k), sim.record.y(k), sim.record.r(k)});
  const EstimatorState early = young.state();
  EXPECT_FALSE(early.warmed_up());
  RecursiveEstimator again(c.model, st);
  again.restore(early);
  EXPECT_TRUE(again.status().warming_up);
  EXPECT_EQ(again.status().samples, 10u);
}

TEST(RecursiveEstimator, AfterRestoreTheFirstSampleIsAGapEvenOnARestartedClock) {
  const Config c = paper_config();
  ExperimentSpec e = *c.experiment;
  e.duration = 200.0;
  e.excitation = prbs(2.0);
  const auto sim = simulate(time_invariant(*c.plant, 0.01), e);
  const Record& r = sim.record;
  const EstimatorSettings st = settings_for(c, {0.999, 0.999, 0.999}, 1000);
  RecursiveEstimator est(c.model, st);
  const Eigen::Index half = r.size() / 2;
  for (Eigen::Index k = 0; k < half; ++k) est.step({r.t(k), r.u(k), r.y(k), r.r(k)});
  const EstimatorState saved = est.state();
  RecursiveEstimator resumed(c.model, st);
  resumed.restore(saved);
  // The controller's clock restarted: the second half arrives with t from 0.
  const double shift = r.t(half);
  EXPECT_TRUE(resumed.step({r.t(half) - shift, r.u(half), r.y(half), r.r(half)}) & kGap);
  EXPECT_EQ(resumed.status().gaps, saved.status().gaps + 1);
  // From then on the usual checks: a duplicate is rejected, the rest updates.
  EXPECT_TRUE(resumed.step({r.t(half) - shift, r.u(half), r.y(half), r.r(half)}) & kRejectedOutOfOrder);
  for (Eigen::Index k = half + 1; k < r.size(); ++k) resumed.step({r.t(k) - shift, r.u(k), r.y(k), r.r(k)});
  EXPECT_EQ(resumed.status().rejected_out_of_order, saved.status().rejected_out_of_order + 1);
  EXPECT_GT(resumed.status().updates, saved.status().updates + static_cast<std::uint64_t>(r.size() - half) / 2);
  for (int i = 0; i < 3; ++i)
    EXPECT_NEAR(resumed.mode(i).value.wn / modal_parameters(c.plant->modes[i].submodel).wn, 1.0, 0.03)
        << "mode " << i + 1;
}

// The daemon runs the warm-up fit on another thread (defer_warmup_fit) while
// samples keep arriving; `modalwatch track` runs it inside step(). Both must
// give the same estimates, bit for bit, on every sample after the warm-up.
TEST(RecursiveEstimator, WarmupFitOnAnotherThreadGivesTheSynchronousEstimatesBitForBit) {
  const Config c = paper_config();
  const auto sim = simulate(*c.plant, *c.experiment);
  const Record& r = sim.record;
  // The warm-up fit on (config/paper-sim.yaml gives theta(t0), P(t0) instead).
  const EstimatorSettings sync_settings = with_warmup_fit(c.estimator);
  EstimatorSettings split_settings = sync_settings;
  split_settings.defer_warmup_fit = true;
  ASSERT_GT(sync_settings.warmup_samples, 0);
  const int K = static_cast<int>(c.model.submodels.size());
  const Eigen::Index n = std::min<Eigen::Index>(r.size(), 3 * sync_settings.warmup_samples);
  auto sample = [&](Eigen::Index k) { return Sample{r.t(k), r.u(k), r.y(k), r.r(k)}; };
  // Per sample: wn, zeta, gain and their std of every mode, and the residual RMS.
  auto row = [K](const RecursiveEstimator& e) {
    std::vector<double> v;
    for (int i = 0; i < K; ++i) {
      const ModeEstimate m = e.mode(i);
      v.insert(v.end(), {m.value.wn, m.value.zeta, m.value.gain, m.std.wn, m.std.zeta, m.std.gain});
    }
    v.push_back(e.residual_rms());
    return v;
  };

  RecursiveEstimator sync(c.model, sync_settings);
  std::vector<std::vector<double>> expected;
  for (Eigen::Index k = 0; k < n; ++k) {
    sync.step(sample(k));
    expected.push_back(row(sync));
  }
  ASSERT_FALSE(sync.status().warming_up);
  ASSERT_TRUE(sync.status().warmup_fit_used);

  RecursiveEstimator split(c.model, split_settings);
  std::vector<std::vector<double>> got;
  Eigen::Index k = 0;
  for (; k < n; ++k) {
    const unsigned flags = split.step(sample(k));
    got.push_back(row(split));
    if (flags & kWarmupFitPending) break;
  }
  ASSERT_EQ(k + 1, sync_settings.warmup_samples);
  ASSERT_TRUE(split.warmup_fit_pending());
  ASSERT_TRUE(split.status().warming_up);
  const EstimatorStatus before = split.status();
  // While pending, step() takes nothing.
  EXPECT_EQ(split.step(sample(k + 1)), unsigned{kWarmupFitPending});
  EXPECT_EQ(split.status().samples, before.samples);

  WarmupFit job = split.take_warmup_fit();
  EXPECT_THROW(split.take_warmup_fit(), std::logic_error);
  EXPECT_EQ(job.samples(), sync_settings.warmup_samples);
  EXPECT_FALSE(job.done());
  std::thread fitter([&job] { job.run(); });
  fitter.join();
  EXPECT_TRUE(job.done());
  split.apply_warmup_fit(std::move(job));
  EXPECT_FALSE(split.warmup_fit_pending());
  EXPECT_FALSE(split.status().warming_up);
  EXPECT_TRUE(split.status().warmup_fit_used);
  // The samples that arrived meanwhile, then the rest. The row of the sample
  // that completed the window is the one after the fit in the synchronous run.
  got.back() = row(split);
  for (++k; k < n; ++k) {
    EXPECT_EQ(split.step(sample(k)) & kWarmupFitPending, 0u);
    got.push_back(row(split));
  }
  ASSERT_EQ(got.size(), expected.size());
  for (std::size_t j = 0; j < got.size(); ++j) ASSERT_EQ(got[j], expected[j]) << "sample " << j;
  EXPECT_EQ(split.status().samples, sync.status().samples);
  EXPECT_EQ(split.status().updates, sync.status().updates);
  for (int i = 0; i < K; ++i) EXPECT_EQ(split.submodel(i).theta(), sync.submodel(i).theta());
}

// A job is applied once, to its own estimator, after it has run; restore()
// drops a pending fit.
TEST(RecursiveEstimator, WarmupFitJobMisuseIsRejected) {
  const Config c = paper_config();
  const auto sim = simulate(*c.plant, *c.experiment);
  const Record& r = sim.record;
  EstimatorSettings st = settings_for(c, {}, 200);
  st.defer_warmup_fit = true;
  RecursiveEstimator est(c.model, st);
  EXPECT_THROW(est.take_warmup_fit(), std::logic_error);  // nothing pending
  const EstimatorState fresh = est.state();
  for (Eigen::Index k = 0; k < 200; ++k) est.step({r.t(k), r.u(k), r.y(k), r.r(k)});
  ASSERT_TRUE(est.warmup_fit_pending());
  WarmupFit job = est.take_warmup_fit();
  EXPECT_THROW(est.apply_warmup_fit(std::move(job)), std::logic_error);  // not run
  job.run();
  est.restore(fresh);  // drops the pending fit: the job is stale
  EXPECT_FALSE(est.warmup_fit_pending());
  EXPECT_THROW(est.apply_warmup_fit(std::move(job)), std::logic_error);
  // The warm-up starts again, with a window of its own.
  unsigned flags = 0;
  for (Eigen::Index k = 200; k < 400 && !(flags & kWarmupFitPending); ++k)
    flags = est.step({r.t(k), r.u(k), r.y(k), r.r(k)});
  ASSERT_TRUE(est.warmup_fit_pending());
  WarmupFit again = est.take_warmup_fit();
  again.run();
  est.apply_warmup_fit(std::move(again));
  EXPECT_FALSE(est.status().warming_up);
}

}  // namespace
}  // namespace modalwatch
