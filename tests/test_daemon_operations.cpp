// The daemon as an operator meets it, in process on one memq:// instance (real
// LCM, real threads): a sender that restarts, samples lost or reordered in
// transport, a reload, the states before flags can rise, the pace of the
// fault status, overruns, checkpoint and input-state logging. Part of the
// test_daemon binary (it shares the drift record and its helpers).
#include <spdlog/sinks/base_sink.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "daemon_support.hpp"

#include "modalwatch/daemon/daemon.hpp"
#include "modalwatch/error.hpp"

using namespace modalwatch;
using namespace modalwatch::test_support;
using Fault = modalwatch::fault_status_t;

namespace {

// The daemon's log lines while it lives (spdlog's default logger, swapped).
class LogCapture {
 public:
  LogCapture() : previous_(spdlog::default_logger()), sink_(std::make_shared<Sink>()) {
    auto logger = std::make_shared<spdlog::logger>("capture", sink_);
    logger->set_pattern("%l %v");
    logger->set_level(spdlog::level::info);
    spdlog::set_default_logger(logger);
  }
  ~LogCapture() { spdlog::set_default_logger(previous_); }
  LogCapture(const LogCapture&) = delete;
  LogCapture& operator=(const LogCapture&) = delete;

  std::string text() { return sink_->text(); }
  // Lines that contain `what`.
  int count(const std::string& what) {
    std::istringstream lines(text());
    int n = 0;
    for (std::string line; std::getline(lines, line);)
      if (line.find(what) != std::string::npos) ++n;
    return n;
  }

 private:
  // Written by the daemon's threads, read by the test's: under the sink's mutex.
  class Sink : public spdlog::sinks::base_sink<std::mutex> {
   public:
    std::string text() {
      std::lock_guard<std::mutex> lock(mutex_);
      return text_;
    }

   protected:
    void sink_it_(const spdlog::details::log_msg& msg) override {
      spdlog::memory_buf_t line;
      formatter_->format(msg, line);
      text_.append(line.data(), line.size());
    }
    void flush_() override {}

   private:
    std::string text_;
  };

  std::shared_ptr<spdlog::logger> previous_;
  std::shared_ptr<Sink> sink_;
};

// A checkpoint written after 17 s of the drift record (warm-up 5 s, baselines
// learned over the next 10 s), and the fault status of that run; made once.
struct LearnedRun {
  std::string dir, checkpoint;
  std::vector<Fault> status;
  std::int64_t last_seq = 0;
};

const LearnedRun& learned_run() {
  static LearnedRun run = [] {
    LearnedRun r;
    // Not in drift_data().dir, which DaemonInProcess's suite removes when it ends.
    r.dir = (std::filesystem::temp_directory_path() / ("modalwatch_learned_" + std::to_string(::getpid()))).string();
    std::filesystem::create_directories(r.dir);
    r.checkpoint = r.dir + "/learned.ckpt";
    Config c = load_config(kDriftConfig);
    c.daemon.checkpoint_path = r.checkpoint;
    lcm_t* lcm = lcm_create("memq://");
    Received rx;
    rx.subscribe(lcm, c.lcm);
    {
      Daemon d(c, lcm);
      d.start();
      std::uint64_t published = 0;
      publish_paced(lcm, c, d, 0, samples_at(17.0), published);
      EXPECT_TRUE(wait_for([&] { return all_handled(d) && d.counters().samples_received == published; }, 30.0));
      d.stop();
      EXPECT_TRUE(d.write_checkpoint());
      r.last_seq = samples_at(17.0) - 1;
    }
    dispatch_rest(lcm);
    lcm_destroy(lcm);
    r.status = rx.status;
    return r;
  }();
  return run;
}

// Added to a record index: the seq of a sender that goes on after the checkpoint.
std::int64_t seq_going_on() { return learned_run().last_seq + 1 - samples_at(17.0); }

// The drift config resuming from the learned checkpoint.
Config resumed_config(const std::string& checkpoint_copy) {
  std::filesystem::copy_file(learned_run().checkpoint, checkpoint_copy,
                             std::filesystem::copy_options::overwrite_existing);
  Config c = load_config(kDriftConfig);
  c.daemon.checkpoint_path = checkpoint_copy;
  return c;
}

// A daemon on its own memq:// instance, resumed from the learned checkpoint
// (no warm-up), its messages collected in rx.
struct Resumed {
  explicit Resumed(const std::string& checkpoint_copy) : c(resumed_config(checkpoint_copy)) {}
  ~Resumed() {
    d.reset();
    lcm_destroy(lcm);
  }
  Daemon& start() {
    rx.subscribe(lcm, c.lcm);
    d.emplace(c, lcm);
    d->start();
    return *d;
  }
  // Record time [from, to) s, seq going on from the checkpoint's (or, for a
  // restarted sender, from 0), and waits until the daemon has handled it all.
  bool feed(double from, double to, bool restarted = false) {
    const std::int64_t seq_shift = restarted ? 0 : seq_going_on();
    publish_paced(lcm, c, *d, samples_at(from), samples_at(to), published, 0, seq_shift);
    return wait_for([&] { return all_handled(*d) && d->counters().samples_received == published; }, 20.0);
  }
  void stop() {
    d->stop();
    dispatch_rest(lcm);  // memq queued the daemon's messages
  }

  Config c;
  lcm_t* lcm = lcm_create("memq://");
  Received rx;
  std::optional<Daemon> d;
  std::uint64_t published = 0;
};

class DaemonInProcessOperations : public ScratchDir {
 public:
  static void TearDownTestSuite() { std::filesystem::remove_all(learned_run().dir); }
};

}  // namespace

// Before flags can rise the fault status says why: "warming_up" during the
// estimator's warm-up (5 s), then "learning" until every baseline is learned
// (10 s more), then "watching"; each quantity reads "learning" until its mode
// has a baseline.
TEST_F(DaemonInProcessOperations, FaultStatusSaysWarmingUpAndLearningUntilItCanFlag) {
  const LearnedRun& run = learned_run();
  ASSERT_GT(run.status.size(), 150u);
  int warming = 0, learning = 0, watching = 0;
  std::string previous = "warming_up";
  for (const Fault& s : run.status) {
    EXPECT_EQ(s.version, Fault::VERSION);
    const double t = static_cast<double>(s.utime - kUtime0) * 1e-6;
    ASSERT_EQ(s.n_modes, 2);
    if (s.state == "no_input") {  // before the first sample
      EXPECT_EQ(s.utime, 0);
      EXPECT_EQ(warming + learning + watching, 0);
      continue;
    }
    if (s.state == "warming_up") {
      ++warming;
      EXPECT_LE(t, 5.0 + 0.2);
    } else if (s.state == "learning") {
      ++learning;
      EXPECT_GE(t, 5.0 - 0.2);
      EXPECT_TRUE(!s.modes[0].baseline_ready || !s.modes[1].baseline_ready);
    } else {
      EXPECT_EQ(s.state, "watching");
      ++watching;
      EXPECT_GE(t, 15.0 - 0.2);
      EXPECT_TRUE(s.modes[0].baseline_ready && s.modes[1].baseline_ready);
    }
    // Never back to an earlier state.
    EXPECT_FALSE(previous == "watching" && s.state != "watching") << t;
    EXPECT_FALSE(previous == "learning" && s.state == "warming_up") << t;
    previous = s.state;
    for (const auto& m : s.modes) {
      for (int q = 0; q < 3; ++q) {
        const auto& qs = quantity(m, q);
        if (!m.baseline_ready) {
          EXPECT_EQ(qs.state, "learning") << m.name << " at t = " << t;
        }
        EXPECT_NE(qs.state, "raised");
      }
    }
  }
  EXPECT_GE(warming, 40);  // 5 s at 0.1 s
  EXPECT_GE(learning, 90);
  EXPECT_GE(watching, 10);
}

// A controller that restarts sends seq and utime from 0 again. After a resume
// from a checkpoint (seq and utime far ahead) the daemon sees the restart
// within kRestartConfirm (0.1 s of samples, counted out of order), counts and
// logs it, resets the prefilters (one gap) and goes on with the restored
// parameters and baselines; a second restart is handled the same way.
TEST_F(DaemonInProcessOperations, SenderRestartAfterAResumeIsDetectedAndEstimationGoesOn) {
  Resumed r(path("state.ckpt"));
  LogCapture log;
  Daemon& d = r.start();
  ASSERT_TRUE(d.restored_from_checkpoint());
  const std::uint64_t& published = r.published;
  ASSERT_TRUE(r.feed(0.0, 6.0, true));  // seq 0.., utime kUtime0..: both far behind the checkpoint
  DaemonCounters k = d.counters();
  EXPECT_EQ(k.sender_restarts, 1u);
  // The run is confirmed by the sample 0.1 s after its first: the 410 before it are dropped.
  const std::uint64_t confirm = static_cast<std::uint64_t>(std::ceil(0.1 * kFs));
  EXPECT_EQ(k.samples_out_of_order, confirm);
  EXPECT_EQ(k.samples_processed, published - confirm);
  EXPECT_EQ(k.gaps, 1u);
  EXPECT_EQ(k.samples_lost, 0u);
  // Again, from 0.
  ASSERT_TRUE(r.feed(0.0, 6.0, true));
  k = d.counters();
  EXPECT_EQ(k.sender_restarts, 2u);
  EXPECT_EQ(k.samples_processed, published - 2 * confirm);
  EXPECT_EQ(k.gaps, 2u);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  r.stop();
  const Received& rx = r.rx;
  EXPECT_FALSE(d.warming_up());
  EXPECT_EQ(log.count("sender restart: seq and utime started again"), 2) << log.text();

  // Estimates went on, on the sender's clock, from the restored parameters.
  ASSERT_FALSE(rx.estimates.empty());
  const auto& last = rx.estimates.back();
  EXPECT_NEAR(static_cast<double>(last.utime - kUtime0) * 1e-6, 6.0, 0.11);
  EXPECT_NEAR(last.modes[kFlex].hz, 90.0, 0.5);
  EXPECT_NEAR(last.modes[kSuspension].hz, 6.0, 0.2);
  ASSERT_FALSE(rx.status.empty());
  int restart_bits = 0;
  for (const Fault& s : rx.status) {
    if (s.health & Fault::HEALTH_SENDER_RESTART) ++restart_bits;
    EXPECT_TRUE(s.state == "watching" || s.state == "no_input") << s.state;  // the restored baselines stay
    for (int e = 0; e < 6; ++e) EXPECT_NE(entry(s, e).state, "raised") << "false alarm";
  }
  EXPECT_EQ(restart_bits, 2);
  EXPECT_EQ(rx.status.back().sender_restarts, 2);
}

// A reload whose file also changes what needs a restart (a forgetting factor,
// the LCM URL) keeps the restored baselines; a baseline the file now sets
// replaces the kept one, with a warning.
TEST_F(DaemonInProcessOperations, ReloadKeepsLearnedAndRestoredBaselines) {
  Resumed r(path("state.ckpt"));
  const Config& c = r.c;
  LogCapture log;
  Daemon& d = r.start();
  ASSERT_TRUE(r.feed(17.0, 18.0));

  Config next = c;
  next.estimator.forgetting[kFlex] = 0.998;
  next.lcm.url = "udpm://239.255.76.67:7667?ttl=0";
  next.faults.thresholds[0].hold_time = 1.5;
  const std::string summary = d.reload(next);
  EXPECT_NE(summary.find("NOT applied"), std::string::npos) << summary;
  ASSERT_TRUE(r.feed(18.0, 19.0));
  const std::size_t after_first = r.rx.count_status();
  // Now the running model again, with a configured baseline for flex (95 Hz): it replaces the restored one.
  Config third = c;
  third.faults.baselines.resize(2);
  third.faults.baselines[kFlex] = ModalParameters{2.0 * std::numbers::pi * 95.0, 0.02, 1.0};
  d.reload(third);
  ASSERT_TRUE(r.feed(19.0, 19.5));
  r.stop();
  const Received& rx = r.rx;

  ASSERT_GT(after_first, 10u);
  for (std::size_t i = 0; i < rx.status.size(); ++i) {
    const Fault& s = rx.status[i];
    EXPECT_TRUE(s.state == "watching" || s.state == "no_input") << "status " << i << ": baselines lost at a reload";
    EXPECT_TRUE(s.modes[kSuspension].baseline_ready && s.modes[kFlex].baseline_ready);
  }
  const std::string text = log.text();
  // The checkpoint carries how a baseline came about: restored, it is still the learned one.
  EXPECT_NE(text.find("reload: mode 'flex': the learned baseline"), std::string::npos) << text;
  EXPECT_EQ(log.count("reload: mode 'suspension'"), 0) << text;
  // The flex baseline is the configured one after the second reload.
  EXPECT_NEAR(rx.estimates.back().modes[kFlex].baseline_wn, 2.0 * std::numbers::pi * 95.0, 1e-9);
  EXPECT_NEAR(rx.estimates.back().modes[kSuspension].baseline_wn / (2.0 * std::numbers::pi), 6.0, 0.2);
}

// Lost, reordered and duplicated packets: samples lost in transport are
// counted from the sequence numbers (late ones are not lost), apart from ring
// drops, every sample is accounted for, and the gap warnings they cause come
// as one line per 5 s with a count, not one per gap.
TEST_F(DaemonInProcessOperations, CountsSamplesLostInTransportAndRateLimitsGapWarnings) {
  Resumed r(path("state.ckpt"));
  const Config& c = r.c;
  lcm_t* lcm = r.lcm;
  LogCapture log;
  Daemon& d = r.start();
  const Record& rec = drift_data().record;
  const std::int64_t seq_shift = seq_going_on();
  std::uint64_t sent = 0, lost = 0, late = 0, duplicated = 0, unique = 0;
  constexpr int kBatch = 64;
  const auto send = [&](Eigen::Index k) {
    const std::vector<std::uint8_t> bytes = encode_batch(rec, k, kBatch, kUtime0, seq_shift);
    lcm_publish(lcm, c.lcm.batches_channel.c_str(), bytes.data(), static_cast<unsigned>(bytes.size()));
    sent += kBatch;
  };
  const auto t0 = std::chrono::steady_clock::now();
  int batch = 2;  // the first packets arrive: the subscriber counts losses from there
  for (Eigen::Index k = samples_at(17.0); k + 2 * kBatch <= samples_at(29.0); k += 2 * kBatch, batch += 2) {
    unique += 2 * kBatch;
    if (batch % 10 == 0) {
      lost += 2 * kBatch;  // two packets that never arrive
    } else if (batch % 10 == 4) {
      send(k + kBatch);  // swapped: the first one arrives late
      send(k);
      late += kBatch;
    } else if (batch % 10 == 6) {
      send(k);
      send(k);
      send(k + kBatch);
      duplicated += kBatch;
    } else {
      send(k);
      send(k + kBatch);
    }
    wait_for([&] { return d.counters().samples_received + 4096 > sent; }, 10.0);
  }
  ASSERT_TRUE(wait_for([&] { return all_handled(d) && d.counters().samples_received == sent; }, 20.0));
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::this_thread::sleep_for(std::chrono::milliseconds(100));  // the subscriber idles: losses are final
  r.stop();
  const DaemonCounters k = d.counters();
  EXPECT_EQ(k.samples_lost, lost);
  EXPECT_EQ(k.samples_dropped, 0u);
  // A repeated packet's last sample repeats the last accepted seq (duplicate),
  // the others are below it (out of order), as the samples of a late packet are.
  EXPECT_EQ(k.samples_duplicate, duplicated / kBatch);
  EXPECT_EQ(k.samples_out_of_order, late + duplicated - duplicated / kBatch);
  EXPECT_EQ(k.samples_received, k.samples_processed + k.samples_nonfinite + k.samples_dropped + k.samples_duplicate +
                                    k.samples_out_of_order);
  EXPECT_EQ(k.samples_received, sent);
  EXPECT_EQ(sent - duplicated + k.samples_lost, unique);  // every sample sent once arrived or is counted lost
  // One gap per lost pair and per late packet, ~150 in all: the first line at
  // once, then one per 5 s of wall time with a count.
  EXPECT_GE(k.gaps, 150u);
  const int gap_lines = log.count("input gap: prefilter states reset");
  EXPECT_GE(gap_lines, 1);
  EXPECT_LE(gap_lines, 2 + static_cast<int>(wall / 5.0)) << log.text();
  EXPECT_GE(log.count("samples lost in transport"), 1);
}

// One fault status per publish period of sample time while input flows (here
// 3 s at real time: 30), not a second one from the wall-clock timer that is
// meant for the silence; without input, one per publish period of wall time.
TEST_F(DaemonInProcessOperations, OneFaultStatusPerPublishPeriod) {
  Resumed r(path("state.ckpt"));  // no warm-up fit in the way
  r.start();
  const std::int64_t seq_shift = seq_going_on();
  const auto t0 = std::chrono::steady_clock::now();
  const Eigen::Index begin = samples_at(17.0);
  publish_range(
      r.lcm, r.c.lcm.batches_channel, drift_data().record, begin, samples_at(20.0), 32, 0, seq_shift,
      [&](Eigen::Index next) {
        std::this_thread::sleep_until(t0 + std::chrono::duration<double>(static_cast<double>(next - begin) / kFs));
      });
  std::this_thread::sleep_for(std::chrono::seconds(3));  // without input
  r.stop();
  const Received& rx = r.rx;
  // Without input the status repeats the newest sample's utime.
  const std::int64_t last_utime = kUtime0 + std::llround(drift_data().record.t(samples_at(20.0) - 1) * 1e6);
  std::size_t with_input = 0, without = 0;
  for (const Fault& s : rx.status) {
    if (s.state == "no_input") continue;  // before the first sample
    (s.utime < last_utime ? with_input : without) += 1;
  }
  EXPECT_GE(rx.estimates.size(), 29u);
  EXPECT_EQ(with_input, rx.estimates.size());  // flag changes would add theirs: none here
  EXPECT_GE(without, 25u);                     // about 3 s / 0.1 s after the input stops
  EXPECT_LE(without, 35u);
}

// Loop ticks that overrun set HEALTH_OVERRUN and the overruns counter. A
// 10 us tick overruns on any machine.
TEST_F(DaemonInProcessOperations, OverrunsAreInTheHealthBitsAndCounters) {
  Resumed r(path("state.ckpt"));
  r.c.daemon.loop_rate_hz = 100000.0;
  Daemon& d = r.start();
  ASSERT_TRUE(r.feed(17.0, 19.0));
  r.stop();
  const Received& rx = r.rx;
  const DaemonCounters k = d.counters();
  ASSERT_GT(k.overruns, 0u);
  int with_bit = 0;
  for (const Fault& s : rx.status)
    if (s.health & Fault::HEALTH_OVERRUN) {
      ++with_bit;
      EXPECT_NE(s.health_text.find("overrun"), std::string::npos);
    }
  EXPECT_GT(with_bit, 0);
  ASSERT_FALSE(rx.status.empty());
  EXPECT_GT(rx.status.back().overruns, 0);
  EXPECT_LE(static_cast<std::uint64_t>(rx.status.back().overruns), k.overruns);
}

// A checkpoint directory that does not exist fails at start-up (and a reload
// to one is rejected), naming the key, instead of failing at every write. The
// first periodic write is logged at info level, the rest at debug level.
TEST_F(DaemonInProcessOperations, CheckpointDirectoryIsCheckedAndTheFirstWriteLogged) {
  Config bad = load_config(kDriftConfig);
  bad.daemon.checkpoint_path = path("no-such-dir/state.ckpt");
  const std::string message = error_of([&] { Daemon d(bad, nullptr); });
  EXPECT_NE(message.find("daemon.checkpoint.path"), std::string::npos) << message;
  EXPECT_NE(message.find("no-such-dir"), std::string::npos) << message;

  Resumed r(path("state.ckpt"));
  r.c.daemon.checkpoint_period = 0.1;
  LogCapture log;
  Daemon& d = r.start();
  ASSERT_TRUE(r.feed(17.0, 18.0));
  ASSERT_TRUE(wait_for([&] { return d.counters().checkpoints_written >= 3; }, 10.0));
  EXPECT_NE(error_of([&] { d.reload(bad); }).find("daemon.checkpoint.path"), std::string::npos);
  EXPECT_EQ(d.config().daemon.checkpoint_path, r.c.daemon.checkpoint_path);
  r.stop();
  EXPECT_EQ(log.count("checkpoint written:"), 1) << log.text();
  EXPECT_NE(log.text().find("logged at debug level"), std::string::npos);
}

// "input resumed" needs a sample: at start without input the daemon says "no
// input yet", and a reload that lengthens stale_time does not end that.
TEST_F(DaemonInProcessOperations, InputResumedIsLoggedOnlyWhenASampleArrives) {
  Resumed r(path("state.ckpt"));
  r.c.daemon.stale_time = 0.2;
  LogCapture log;
  Daemon& d = r.start();
  ASSERT_TRUE(wait_for([&] { return log.count("no input yet") == 1; }, 30.0)) << log.text();
  Config longer = r.c;
  longer.daemon.stale_time = 100.0;
  d.reload(longer);
  std::this_thread::sleep_for(std::chrono::milliseconds(400));
  EXPECT_EQ(log.count("input resumed"), 0) << log.text();
  ASSERT_TRUE(r.feed(17.0, 17.5));
  ASSERT_TRUE(wait_for([&] { return log.count("input resumed") == 1; }, 30.0)) << log.text();
  r.stop();
}
