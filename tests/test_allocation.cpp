// Proof that RecursiveEstimator::step() (and the read-outs a daemon calls per
// sample: mode(), mode_covariance(), residual_rms(), status()) does not touch the
// heap once the warm-up is over, nor FaultDetector::update() after construction.
//
// The counting (every operator new/delete and, outside sanitizer builds, malloc
// & co., per thread) is tests/allocation_counter.cpp, linked into this binary.
#include <array>
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "allocation_counter.hpp"
#include "modalwatch/estimator.hpp"
#include "modalwatch/fault_detector.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/simulator.hpp"
#include "simulation_support.hpp"
#include "support.hpp"

namespace modalwatch {
namespace {

using test_support::AllocationCounter;
using test_support::first_allocation_trace;

struct Data {
  Config config;
  Record open, closed;
};

const Data& data() {
  static const Data d = [] {
    Data out;
    out.config = load_config(test_support::source_file("config/paper-sim.yaml"));
    ExperimentSpec e = *out.config.experiment;
    e.duration = 330.0;  // 6600 samples: warm-up, lead-in, 5000 counted steps
    e.closed_loop = true;
    out.closed = simulate(*out.config.plant, e).record;
    e.closed_loop = false;  // the same signal as plant input
    out.open = simulate(*out.config.plant, e).record;
    return out;
  }();
  return d;
}

struct Case {
  bool closed_loop;
  int warmup_samples;
  int refinements;
  int block_iterations;
  int update_divisor;
};

std::string case_name(const ::testing::TestParamInfo<Case>& info) {
  const Case& c = info.param;
  return std::string(c.closed_loop ? "Closed" : "Open") + "_Warmup" + std::to_string(c.warmup_samples) + "_Ms" +
         std::to_string(c.refinements) + "_Ml" + std::to_string(c.block_iterations) + "_Div" +
         std::to_string(c.update_divisor);
}

class NoAllocation : public ::testing::TestWithParam<Case> {};

TEST_P(NoAllocation, InStepAndReadOutsAfterWarmup) {
  const Case c = GetParam();
  const Data& d = data();
  EstimatorSettings s = d.config.estimator;
  s.closed_loop = c.closed_loop;
  s.warmup_samples = c.warmup_samples;
  s.refinements = c.refinements;
  s.block_iterations = c.block_iterations;
  s.update_divisor = c.update_divisor;
  RecursiveEstimator est(d.config.model, s);
  const Record& r = c.closed_loop ? d.closed : d.open;
  const auto sample = [&](Eigen::Index k) { return Sample{r.t(k), r.u(k), r.y(k), c.closed_loop ? r.r(k) : 0.0}; };

  // Warm-up (and its offline fit) plus a lead-in, uncounted.
  constexpr Eigen::Index kLeadIn = 100, kCounted = 5000;
  const Eigen::Index begin = c.warmup_samples + kLeadIn;
  ASSERT_LE(begin + kCounted, r.size());
  for (Eigen::Index k = 0; k < begin; ++k) est.step(sample(k));
  ASSERT_FALSE(est.status().warming_up);
  const std::uint64_t updates_before = est.status().updates;

  unsigned flags = 0;
  double sink = 0.0;
  std::uint64_t resets = 0;
  AllocationCounter::start();
  for (Eigen::Index k = begin; k < begin + kCounted; ++k) {
    flags |= est.step(sample(k));
    for (int i = 0; i < est.submodels(); ++i) {
      const ModeEstimate m = est.mode(i);
      sink += m.value.wn + m.value.zeta + m.value.gain + m.std.wn + m.std.zeta + m.std.gain;
      sink += est.mode_covariance(i).trace();
    }
    sink += est.residual_rms();
    resets += est.status().resets;
  }
  const test_support::AllocationCounts counts = AllocationCounter::stop();

  EXPECT_EQ(counts.allocations, 0u) << first_allocation_trace();
  EXPECT_EQ(counts.deallocations, 0u);
  // The counted region really ran the update path.
  EXPECT_GT(est.status().updates, updates_before) << "flags seen: " << flags;
  EXPECT_FALSE(flags & kWarmingUp);
  EXPECT_TRUE(sink == sink) << "NaN in the read-outs";
  (void)resets;
  // mode_covariance() is modal_covariance() of the submodel's theta covariance,
  // and its diagonal gives mode()'s standard deviations.
  for (int i = 0; i < est.submodels(); ++i) {
    const Eigen::Matrix3d mc = est.mode_covariance(i);
    const Eigen::Matrix3d expected = modal_covariance(est.submodel(i), est.covariance(i));
    EXPECT_LE((mc - expected).norm(), 1e-12 * expected.norm()) << "submodel " << i;
    const ModeEstimate m = est.mode(i);
    EXPECT_NEAR(std::sqrt(mc(0, 0)), m.std.wn, 1e-12 * m.std.wn + 1e-300);
    EXPECT_NEAR(std::sqrt(mc(1, 1)), m.std.zeta, 1e-12 * m.std.zeta + 1e-300);
    EXPECT_NEAR(std::sqrt(mc(2, 2)), m.std.gain, 1e-12 * m.std.gain + 1e-300);
  }
}

std::vector<Case> all_cases() {
  std::vector<Case> cases;
  for (bool closed : {false, true})
    for (int warmup : {1000, 0})
      for (int ms : {0, 2})
        for (int ml : {1, 2})
          for (int div : {1, 5}) cases.push_back({closed, warmup, ms, ml, div});
  return cases;
}

INSTANTIATE_TEST_SUITE_P(Estimator, NoAllocation, ::testing::ValuesIn(all_cases()), case_name);

// Two measured inputs (open loop): the paper's modes with mode2 driven by a
// second input, white noise beside the paper's signal on the first. The
// further inputs travel in the Sample's fixed array, and the warm-up window
// (fitted here, so that the window's ring keeps them per sample too) holds
// them in buffers sized at construction.
struct TwoInputs {
  AdditiveModel model;
  Record record;
};

const TwoInputs& two_inputs() {
  static const TwoInputs d = [] {
    const Config& c = data().config;
    TwoInputs out;
    out.model = c.model;
    out.model.inputs = {"u1", "u2"};
    out.model.submodels[1].input = 1;
    PlantSpec plant = *c.plant;
    plant.modes[1].submodel.input = 1;
    ExperimentSpec e = *c.experiment;
    e.duration = 330.0;
    e.closed_loop = false;
    const auto n = static_cast<Eigen::Index>(std::llround(e.duration / e.sample_time));
    e.further_input_samples = {modalwatch::test_support::white_noise(n, 11)};
    out.record = simulate(plant, e).record;
    return out;
  }();
  return d;
}

class NoAllocationTwoInputs : public ::testing::TestWithParam<Case> {};

TEST_P(NoAllocationTwoInputs, InStepAndReadOutsAfterWarmup) {
  const Case c = GetParam();
  const TwoInputs& d = two_inputs();
  EstimatorSettings s = data().config.estimator;
  s.closed_loop = false;
  s.warmup_samples = c.warmup_samples;
  s.fit_on_warmup = true;
  s.refinements = c.refinements;
  s.block_iterations = c.block_iterations;
  s.update_divisor = c.update_divisor;
  RecursiveEstimator est(d.model, s);
  const Record& r = d.record;
  ASSERT_EQ(r.inputs(), 2);
  Sample sample;
  sample.further_inputs = 1;
  const auto step = [&](Eigen::Index k) {
    sample.t = r.t(k);
    sample.u = r.u(k);
    sample.y = r.y(k);
    sample.further_u[0] = r.input(1)(k);
    return est.step(sample);
  };
  constexpr Eigen::Index kLeadIn = 100, kCounted = 5000;
  const Eigen::Index begin = c.warmup_samples + kLeadIn;
  ASSERT_LE(begin + kCounted, r.size());
  for (Eigen::Index k = 0; k < begin; ++k) step(k);
  ASSERT_FALSE(est.status().warming_up);
  const std::uint64_t updates_before = est.status().updates;

  unsigned flags = 0;
  double sink = 0.0;
  AllocationCounter::start();
  for (Eigen::Index k = begin; k < begin + kCounted; ++k) {
    flags |= step(k);
    for (int i = 0; i < est.submodels(); ++i) {
      const ModeEstimate m = est.mode(i);
      sink += m.value.wn + m.std.wn + est.mode_covariance(i).trace();
    }
    sink += est.residual_rms();
  }
  const test_support::AllocationCounts counts = AllocationCounter::stop();
  EXPECT_EQ(counts.allocations, 0u) << first_allocation_trace();
  EXPECT_EQ(counts.deallocations, 0u);
  EXPECT_GT(est.status().updates, updates_before) << "flags seen: " << flags;
  EXPECT_EQ(est.status().rejected_nonfinite, 0u) << "the second input did not arrive";
  EXPECT_TRUE(sink == sink) << "NaN in the read-outs";
}

std::vector<Case> two_input_cases() {
  std::vector<Case> cases;
  for (int warmup : {1000, 0})
    for (int ms : {0, 2})
      for (int ml : {1, 2}) cases.push_back({false, warmup, ms, ml, 1});
  return cases;
}

INSTANTIATE_TEST_SUITE_P(Estimator, NoAllocationTwoInputs, ::testing::ValuesIn(two_input_cases()), case_name);

// FaultDetector::update(), both overloads and with a joint covariance,
// through learning (a restart and a settled window), configured baselines, flags rising and falling on every
// quantity of every mode: no allocation once constructed (`changes` reserved).
TEST(FaultDetectorAllocation, UpdateAllocatesNothing) {
  const std::vector<ModalParameters> truth = {{60.0, 0.05, 2.0}, {150.0, 0.03, 0.5}, {400.0, 0.02, 0.1}};
  FaultDetectorSettings s;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    s.mode_names.push_back("m" + std::to_string(i));
    s.baselines.emplace_back(i == 0 ? std::nullopt : std::optional<ModalParameters>(truth[i]));
  }
  s.baseline_std.assign(truth.size(), ModalParameters{});
  s.learn_window = 5.0;
  for (auto& th : s.thresholds) th.hold_time = th.clear_time = 0.5;
  FaultDetector detector(s);
  std::vector<ModalParameters> value = truth, std_dev(truth.size());
  std::vector<Eigen::Matrix3d> cov(truth.size());
  Eigen::MatrixXd joint = Eigen::MatrixXd::Zero(9, 9);  // the gains correlated across modes
  std::vector<FlagChange> changes;
  changes.reserve(kQuantities * truth.size());
  int raised = 0, fallen = 0;

  AllocationCounter::start();
  for (int k = 0; k < 2000; ++k) {
    const double t = 0.1 * k;
    // 0-2 s: the first mode still settling (a restart); then steady; every 20 s
    // a 10 s spell 30 % off on every quantity of every mode.
    const double f = t < 2.0 ? 1.0 + 0.1 * (2.0 - t) : ((k / 100) % 2 == 1 && t > 20.0 ? 0.7 : 1.0);
    for (std::size_t i = 0; i < truth.size(); ++i) {
      value[i] = {truth[i].wn * f, truth[i].zeta * f, truth[i].gain * f};
      std_dev[i] = {1e-3 * truth[i].wn, 1e-3 * truth[i].zeta, 1e-3 * truth[i].gain};
      cov[i] = Eigen::Vector3d(std_dev[i].wn, std_dev[i].zeta, std_dev[i].gain).cwiseAbs2().asDiagonal();
    }
    for (std::size_t i = 0; i < truth.size(); ++i) {
      const auto at = static_cast<Eigen::Index>(3 * i);
      joint.block<3, 3>(at, at) = cov[i];
      for (std::size_t j = 0; j < truth.size(); ++j)
        if (j != i) joint(at + 2, static_cast<Eigen::Index>(3 * j + 2)) = 0.5e-6 * truth[i].gain * truth[j].gain;
    }
    changes.clear();
    if (k % 3 == 0)
      detector.update(t, value, cov, k % 97 != 0, changes);
    else if (k % 3 == 1)
      detector.update(t, value, std_dev, true, changes);
    else
      detector.update(t, value, cov, true, changes, 0.0, nullptr, &joint);
    for (const FlagChange& c : changes) (c.raised ? raised : fallen) += 1;
  }
  const test_support::AllocationCounts counts = AllocationCounter::stop();
  EXPECT_EQ(counts.allocations, 0u) << first_allocation_trace();
  EXPECT_EQ(counts.deallocations, 0u);
  EXPECT_EQ(detector.status()[0].state, BaselineState::ready);
  EXPECT_GE(detector.status()[0].learn_restarts, 1);
  EXPECT_GE(raised, 9 * 5) << "every quantity of every mode rose in each spell";
  EXPECT_GE(fallen, 9 * 4);
}

// The counter itself works: an allocation inside the counted region is seen
// (through operator new and, outside sanitizer builds, through malloc).
TEST(AllocationCounter, SeesOperatorNewAndMalloc) {
  AllocationCounter::start();
  auto* p = new std::array<double, 16>();
  asm volatile("" : : "g"(p) : "memory");  // the pointer escapes: new/delete cannot be elided
  const test_support::AllocationCounts after_new = AllocationCounter::stop();
  delete p;
  EXPECT_EQ(after_new.allocations, 1u);
#if MODALWATCH_INTERPOSE_MALLOC
  AllocationCounter::start();
  Eigen::VectorXd v(64);  // Eigen allocates with malloc, not operator new
  v.setZero();
  const test_support::AllocationCounts after_eigen = AllocationCounter::stop();
  EXPECT_GE(after_eigen.allocations, 1u);
  EXPECT_NE(first_allocation_trace().find("first allocation"), std::string::npos);
#endif
}

}  // namespace
}  // namespace modalwatch
