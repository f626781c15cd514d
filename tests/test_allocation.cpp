// Proof that RecursiveEstimator::step() (and the read-outs a daemon calls per
// sample: mode(), residual_rms(), status()) does not touch the heap once the
// warm-up is over.
//
// The counting (every operator new/delete and, outside sanitizer builds, malloc
// & co., per thread) is tests/allocation_counter.cpp, linked into this binary.
#include <array>
#include <cstdio>
#include <string>

#include <gtest/gtest.h>

#include "allocation_counter.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/estimator.hpp"
#include "modalwatch/simulator.hpp"

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
    out.config = load_config(std::string(MODALWATCH_SOURCE_DIR) + "/config/paper-sim.yaml");
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
