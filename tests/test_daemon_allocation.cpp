// No heap allocation on the daemon's estimation thread after
// start-up. The Daemon runs in process on memq:// over the drifting flexible
// beam (warm-up, baseline learning, a fault flag rising, the metrics endpoint on) and with bad input
// mixed in (NaN, duplicates, reordering, a gap); a LoopProbe starts counting on
// the estimation thread once the warm-up is over and stops when the loop exits.
//
// Counting as in test_allocation.cpp (tests/allocation_counter.cpp): per
// thread, so the subscriber and publisher threads, which may allocate, do not count.
#include <atomic>
#include <cstdlib>
#include <string>

#include "allocation_counter.hpp"
#include "daemon_support.hpp"

#include "daemon/loop_probe.hpp"
#include "modalwatch/daemon/daemon.hpp"

using namespace modalwatch;
using namespace modalwatch::test_support;

namespace {

class CountingProbe : public LoopProbe {
 public:
  void warmed_up() override {
    AllocationCounter::start();
    started = true;
  }
  // On the estimation thread; read by the test after the daemon's threads are joined.
  void exiting() override {
    const std::uint64_t n = AllocationCounter::stop().allocations;
    if (n > 0) trace = first_allocation_trace();
    allocations = n;
  }
  std::atomic<bool> started{false};
  std::atomic<std::uint64_t> allocations{~0ull};
  std::string trace;
};

}  // namespace

TEST(DaemonAllocation, NoneOnTheEstimationThreadAfterStartUp) {
  const DriftData& data = drift_data();
  const Record& rec = data.record;
  Config c = load_config(kDriftConfig);
  c.daemon.stale_time = 0.2;
  c.daemon.metrics_listen = "127.0.0.1:0";  // the metrics endpoint on: the loop counts its ticks for it
  lcm_t* lcm = lcm_create("memq://");
  ASSERT_NE(lcm, nullptr);
  Received rx;
  rx.subscribe(lcm, c.lcm);
  CountingProbe probe;
  {
    Daemon d(c, lcm);
    attach_loop_probe(d, probe);
    d.start();
    const auto handled = [&] {
      const DaemonCounters k = d.counters();
      return k.samples_processed + k.samples_dropped + k.samples_nonfinite + k.samples_duplicate +
             k.samples_out_of_order;
    };
    // memq queues without bound: pace by what was sent, not by what the daemon received.
    std::uint64_t published = 0;
    Eigen::Index done = 0;
    const auto pace = [&](Eigen::Index next) {
      published += static_cast<std::uint64_t>(next - done);
      done = next;
      wait_for([&] { return published < handled() + 8192; }, 10.0);
    };
    const Eigen::Index mid = 20 * 4096, end = rec.size();
    publish_range(lcm, c.lcm.batches_channel, rec, 0, mid, 64, 0, 0, pace);
    ASSERT_TRUE(wait_for([&] { return probe.started.load(); }, 20.0)) << "the warm-up never ended";
    // Bad input after the warm-up: NaN, a duplicate, a late (reordered) sample.
    for (int i = 0; i < 3; ++i) {
      StampedSample s{kUtime0 + std::llround(rec.t(mid + i) * 1e6), mid + i, rec.u(mid + i), std::nan(""),
                      rec.r(mid + i)};
      const auto bytes = encode_sample(s);
      lcm_publish(lcm, c.lcm.samples_channel.c_str(), bytes.data(), static_cast<unsigned>(bytes.size()));
      if (i == 1) lcm_publish(lcm, c.lcm.samples_channel.c_str(), bytes.data(), static_cast<unsigned>(bytes.size()));
    }
    {  // an old sample arriving late: out of order
      const Eigen::Index k = mid - 5;
      const auto bytes =
          encode_sample(StampedSample{kUtime0 + std::llround(rec.t(k) * 1e6), k, rec.u(k), rec.y(k), rec.r(k)});
      lcm_publish(lcm, c.lcm.samples_channel.c_str(), bytes.data(), static_cast<unsigned>(bytes.size()));
    }
    // Then silence (stale input), and the rest 2 s later in sample time (a gap), with the drift.
    std::this_thread::sleep_for(std::chrono::milliseconds(400));
    done = mid + 3;
    publish_range(lcm, c.lcm.batches_channel, rec, mid + 3, end, 64, 2'000'000, 0, pace);
    published += 5;  // the single samples
    ASSERT_TRUE(wait_for([&] { return d.counters().samples_received == published && handled() == published; }, 30.0));
    d.stop();
    const DaemonCounters k = d.counters();
    EXPECT_EQ(k.samples_nonfinite, 3u);
    EXPECT_EQ(k.samples_duplicate, 1u);
    EXPECT_EQ(k.samples_out_of_order, 1u);
    EXPECT_EQ(k.gaps, 1u);
    EXPECT_GT(k.flag_changes, 0u) << "the fault detector's flag path was not exercised";
    EXPECT_GT(k.samples_processed, std::uint64_t(end) - 10);
  }
  lcm_destroy(lcm);
  EXPECT_EQ(probe.allocations.load(), 0u) << "heap allocations on the estimation thread after start-up\n"
                                          << probe.trace;
}

// The same with a model of two measured inputs (two_input_plant(): open loop,
// sample_batch2_t packets, a NaN in the second input): the further inputs go
// from the decoder through the ring and the backlog into the estimator's
// Sample, all of fixed size.
TEST(DaemonAllocation, NoneOnTheEstimationThreadWithTwoInputs) {
  const std::string dir =
      std::filesystem::temp_directory_path() / ("modalwatch_daemon_allocation_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const TwoInputPlant two = two_input_plant(dir + "/two_inputs.yaml");
  Record rec = two.record;
  const Eigen::Index bad = 30 * 200;  // after the warm-up
  rec.further_u[0](bad) = std::nan("");
  lcm_t* lcm = lcm_create("memq://");
  ASSERT_NE(lcm, nullptr);
  Received rx;
  rx.subscribe(lcm, two.config.lcm);
  CountingProbe probe;
  {
    Daemon d(two.config, lcm);
    attach_loop_probe(d, probe);
    d.start();
    // The count starts on the tick after the warm-up's backlog is worked off:
    // wait for it before the rest (the NaN and most of the record) goes out.
    const Eigen::Index warm = 25 * 200;
    std::uint64_t published = 0;
    publish_paced(lcm, two.config, d, rec, 0, warm, published);
    ASSERT_TRUE(wait_for([&] { return probe.started.load(); }, 20.0)) << "the warm-up never ended";
    publish_paced(lcm, two.config, d, rec, warm, rec.size(), published);
    ASSERT_TRUE(wait_for([&] { return all_handled(d) && d.counters().samples_received == published; }, 30.0));
    d.stop();
    const DaemonCounters k = d.counters();
    EXPECT_EQ(k.samples_nonfinite, 1u);
    EXPECT_EQ(k.samples_processed, static_cast<std::uint64_t>(rec.size()) - 1);
    EXPECT_EQ(k.decode_errors, 0u);
  }
  lcm_destroy(lcm);
  std::filesystem::remove_all(dir);
  EXPECT_EQ(probe.allocations.load(), 0u) << "heap allocations on the estimation thread after start-up\n"
                                          << probe.trace;
}
