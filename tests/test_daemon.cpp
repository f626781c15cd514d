// The daemon end to end, over real LCM and real threads, on a simulated
// flexible beam whose flexible mode loses 15 % stiffness at t = 30..32 s
// (config/flexible-beam-drift.yaml, simulated and tracked once per run with
// the real CLI).
//
// - DaemonInProcess runs the Daemon class in process on one shared memq://
//   instance (publisher, daemon and collector), faster than real time: the
//   test paces its publishing by the daemon's counters, and the daemon runs
//   on sample time.
// The binary as a child process: test_daemon_process.cpp; operators'
// situations (restarts, reloads, losses): test_daemon_operations.cpp.
#include <fcntl.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <numbers>
#include <random>
#include <sstream>

#include "daemon_support.hpp"
#include "estimator_support.hpp"

#include "daemon/loop_probe.hpp"
#include "modalwatch/daemon/daemon.hpp"
#include "modalwatch/io/checkpoint.hpp"
#include "modalwatch/simulator.hpp"

using namespace modalwatch;
using namespace modalwatch::test_support;
using Fault = modalwatch::fault_status_t;

namespace {

class DaemonInProcess : public ScratchDir {
 public:
  static void TearDownTestSuite() { remove_drift_data(); }
};

}  // namespace

// The flexible mode is flagged within 20 s of the drift start,
// the suspension mode never; the estimates are those of `modalwatch track`.
TEST_F(DaemonInProcess, FlagsTheDriftingModeOnlyAndMatchesTrack) {
  const DriftData& data = drift_track();
  ASSERT_EQ(data.record.size(), samples_at(60.0));
  Received rx;
  const DaemonCounters counters = run_in_process(load_config(kDriftConfig), data.record, rx);
  EXPECT_EQ(counters.samples_received, 245760u);
  EXPECT_EQ(counters.samples_processed, 245760u);
  EXPECT_EQ(counters.samples_dropped + counters.decode_errors + counters.samples_nonfinite + counters.gaps +
                counters.resets,
            0u);

  // Flags: the first raise of each quantity of each mode.
  std::array<double, 6> first_raise;
  first_raise.fill(-1.0);
  for (const auto& s : rx.status) {
    ASSERT_EQ(s.n_modes, 2);
    for (int e = 0; e < 6; ++e)
      if (entry(s, e).state == "raised" && first_raise[e] < 0.0)
        first_raise[e] = static_cast<double>(entry(s, e).since - kUtime0) * 1e-6;
  }
  for (int q = 0; q < 3; ++q)
    EXPECT_LT(first_raise[3 * kSuspension + q], 0.0) << "suspension quantity " << q << " flagged";
  const double flex_wn = first_raise[3 * kFlex + 0];
  EXPECT_GT(flex_wn, kDriftStart) << "flex wn flagged before the drift";
  EXPECT_LE(flex_wn, kDriftStart + 20.0) << "flex wn not flagged within 20 s of the drift start";
  for (int q = 0; q < 3; ++q)
    if (first_raise[3 * kFlex + q] >= 0.0) {
      EXPECT_GT(first_raise[3 * kFlex + q], kDriftStart);
    }
  // The last status: flex wn still flagged, about -7.8 % (sqrt(0.85) - 1).
  ASSERT_FALSE(rx.status.empty());
  const auto& last = rx.status.back();
  EXPECT_EQ(last.modes[kFlex].wn.state, "raised");
  EXPECT_EQ(last.modes[kFlex].state, "raised");
  EXPECT_LT(last.modes[kFlex].wn.deviation_sigma, 0.0);  // low
  EXPECT_NEAR(last.modes[kFlex].wn.deviation_percent, 100.0 * (std::sqrt(0.85) - 1.0), 1.5);
  // Flag times also as sample time since the first sample.
  EXPECT_NEAR(last.modes[kFlex].wn.since_t, static_cast<double>(last.modes[kFlex].wn.since - kUtime0) * 1e-6, 1e-6);

  // Estimates: one per 0.1 s of sample time, each equal to track's row of the
  // sample it was published after. On the wire, utime has 1 us resolution and
  // the 4096 Hz period is 244.140625 us, so the daemon's t = (utime - utime0)
  // 1e-6 differs from the CSV's by up to 0.5 us (and the warm-up fit sees those
  // times). Track is therefore run on the record with exactly the daemon's
  // times (same batching, same rounding): then the two must agree to rounding.
  ASSERT_GE(rx.estimates.size(), 590u);
  const std::string us_csv = path("record_us.csv"), us_est = path("est_us.csv"), us_flags = path("flags_us.csv");
  write_wire_times_csv(data.record, us_csv);
  const Outcome tr_us = run_cli("track --no-progress --config " + kDriftConfig + " --data " + us_csv + " --out " +
                                us_est + " --faults " + us_flags);
  ASSERT_EQ(tr_us.code, 0) << tr_us.output;

  // Flags: `track --faults` on the same samples changes exactly the daemon's
  // flags (time to the microsecond, mode, quantity, event).
  const std::vector<std::string> daemon_changes =
      daemon_flag_changes(rx.status, std::llround(data.record.t(0) * 1e6));
  EXPECT_FALSE(daemon_changes.empty());
  EXPECT_EQ(track_flag_changes(us_flags), daemon_changes) << "track --faults and the daemon flag differently";
  const Table tr = read_table(us_est);
  const int c_wn[2] = {tr.column("suspension_wn"), tr.column("flex_wn")};
  const int c_zeta[2] = {tr.column("suspension_zeta"), tr.column("flex_zeta")};
  const int c_gain[2] = {tr.column("suspension_gain"), tr.column("flex_gain")};
  double worst = 0.0;
  int compared = 0;
  for (const auto& m : rx.estimates) {
    const double t = static_cast<double>(m.utime - kUtime0) * 1e-6;
    const Eigen::Index k = samples_at(t);
    ASSERT_LT(k, tr.data.rows());
    ASSERT_NEAR(tr.data(k, 0), t - static_cast<double>(std::llround(data.record.t(0) * 1e6)) * 1e-6, 1e-9);
    for (int i = 0; i < 2; ++i) {
      const auto rel = [](double a, double b) { return std::abs(a - b) / std::max(std::abs(b), 1e-300); };
      worst = std::max({worst, rel(m.modes[i].wn, tr.data(k, c_wn[i])), rel(m.modes[i].zeta, tr.data(k, c_zeta[i])),
                        rel(m.modes[i].gain, tr.data(k, c_gain[i]))});
    }
    ++compared;
  }
  EXPECT_GE(compared, 590);
  EXPECT_LT(worst, 1e-12) << "daemon estimates differ from modalwatch track";
  // Against track on the CSV's own times: the 0.5 us rounding costs less than 1e-5.
  double worst_csv = 0.0;
  for (const auto& m : rx.estimates) {
    const Eigen::Index k = samples_at(static_cast<double>(m.utime - kUtime0) * 1e-6);
    for (int i = 0; i < 2; ++i)
      worst_csv =
          std::max(worst_csv, std::abs(m.modes[i].wn - data.track.data(k, c_wn[i])) / data.track.data(k, c_wn[i]));
  }
  EXPECT_LT(worst_csv, 1e-5);
  // And they are right: flex at the end near 82.98 Hz, suspension at 6 Hz.
  const auto& fin = rx.estimates.back();
  EXPECT_NEAR(fin.modes[kFlex].hz, 90.0 * std::sqrt(0.85), 0.5);
  EXPECT_NEAR(fin.modes[kSuspension].hz, 6.0, 0.1);
}

// A checkpoint pauses the estimation loop wherever it has got to in the
// record; the estimates and the fault detector's updates stay on the
// sample-time grid, so the flags are still track's to the microsecond.
TEST_F(DaemonInProcess, CheckpointPausesDoNotMoveTheFlags) {
  const DriftData& data = drift_track();
  Config c = load_config(kDriftConfig);
  c.daemon.checkpoint_path = path("paused.ckpt");
  c.daemon.checkpoint_period = 0.05;  // s of wall time: many pauses, at samples no one chose
  Received rx;
  const DaemonCounters counters = run_in_process(c, data.record, rx);
  EXPECT_EQ(counters.samples_processed, 245760u);
  EXPECT_GE(counters.checkpoints_written, 5u) << "too few pauses to test anything";
  const std::string us_csv = path("record_us.csv"), us_flags = path("flags_us.csv");
  write_wire_times_csv(data.record, us_csv);
  const Outcome tr = run_cli("track --no-progress --config " + kDriftConfig + " --data " + us_csv + " --out " +
                             path("est_us.csv") + " --faults " + us_flags);
  ASSERT_EQ(tr.code, 0) << tr.output;
  const std::vector<std::string> daemon_changes =
      daemon_flag_changes(rx.status, std::llround(data.record.t(0) * 1e6));
  EXPECT_FALSE(daemon_changes.empty());
  EXPECT_EQ(track_flag_changes(us_flags), daemon_changes) << "a pause moved the daemon's flags";
  // Every estimate on the grid of 0.1 s from the first sample.
  for (const auto& m : rx.estimates) {
    const std::int64_t since_first = m.utime - kUtime0 - std::llround(data.record.t(0) * 1e6);
    ASSERT_LT(since_first % 100000, 245) << "an estimate off the publish grid at " << since_first << " us";
  }
}

// The drift config's beam at 50 dB with one memory for both modes (0.49 s), a
// 2 s warm-up and the flexible mode's wn stepping -8 % at t = 20 s: the step
// trips the divergence reset, and the restored state does not settle, so the
// window after it is refitted. The daemon runs that refit on its fitter thread,
// holding the input meanwhile, with estimates and flags exactly those of
// `modalwatch track`, which runs it inline.
TEST_F(DaemonInProcess, ARefitAfterAModeStepRunsOnTheFitterThreadAndMatchesTrack) {
  std::string yaml;
  {
    std::ifstream in(kDriftConfig);
    std::stringstream text;
    text << in.rdbuf();
    yaml = text.str();
  }
  const auto replace = [&](const std::string& from, const std::string& to) {
    const std::size_t at = yaml.find(from);
    ASSERT_NE(at, std::string::npos) << from;
    yaml.replace(at, from.size(), to);
  };
  replace("forgetting: 0.9999", "forgetting: 0.9995");
  replace("forgetting: 0.999\n", "forgetting: 0.9995\n");
  replace("snr_db: 30", "snr_db: 50");
  replace("frequency_hz: [[30, 90.0], [32, 82.9759]]", "frequency_hz: [[20, 90.0], [20.0003, 82.8]]");
  replace("gain: [[30, 2.5e-7], [32, 2.94118e-7]]", "gain: [[20, 2.5e-7], [20.0003, 2.5e-7]]");
  replace("duration: 60", "duration: 30");
  replace("warmup: 5 ", "warmup: 2 ");
  const std::string cfg = write("refit.yaml", yaml), rec_csv = path("refit_record.csv");
  const Outcome sim = run_cli("simulate --config " + cfg + " --out " + rec_csv);
  ASSERT_EQ(sim.code, 0) << sim.output;
  const Record rec = read_record(rec_csv);
  Received rx;
  const DaemonCounters counters = run_in_process(load_config(cfg), rec, rx);
  EXPECT_EQ(counters.samples_processed, static_cast<std::uint64_t>(rec.size()));
  EXPECT_EQ(counters.resets, 1u);
  EXPECT_EQ(counters.samples_dropped + counters.held_dropped, 0u);

  const std::string us_csv = path("refit_us.csv"), us_est = path("refit_est.csv"), us_flags = path("refit_flags.csv");
  write_wire_times_csv(rec, us_csv);
  const Outcome tr = run_cli("track --no-progress --config " + cfg + " --data " + us_csv + " --out " + us_est +
                             " --faults " + us_flags);
  ASSERT_EQ(tr.code, 0) << tr.output;
  EXPECT_NE(tr.output.find("refit"), std::string::npos) << tr.output;
  EXPECT_EQ(track_flag_changes(us_flags), daemon_flag_changes(rx.status, std::llround(rec.t(0) * 1e6)));
  const Table est = read_table(us_est);
  const int c_wn = est.column("flex_wn");
  double worst = 0.0, flex_hz_after = NAN;
  for (const auto& m : rx.estimates) {
    const double t = static_cast<double>(m.utime - kUtime0) * 1e-6;
    const Eigen::Index k = samples_at(t);
    ASSERT_LT(k, est.data.rows());
    worst = std::max(worst, std::abs(m.modes[kFlex].wn - est.data(k, c_wn)) / est.data(k, c_wn));
    if (std::isnan(flex_hz_after) && t >= 22.5) flex_hz_after = m.modes[kFlex].hz;
  }
  EXPECT_LT(worst, 1e-12) << "daemon estimates differ from modalwatch track";
  // 2.5 s after the step (the transient 1.22 s, the window 0.49 s, the fit).
  EXPECT_NEAR(flex_hz_after, 82.8, 0.8);
}

// Two measured inputs, open loop, end to end over LCM (two_input_plant(): a
// 200 Hz structure whose 5 Hz mode both shakers drive, with residues of
// opposite sign, and whose 12 Hz mode only the second does; 30 dB output
// noise). The record goes out as sample_batch2_t packets; the
// daemon's estimates are exactly `modalwatch track`'s on the same samples (the
// same CSV columns the model names), and each submodel's wn ends within 4 of
// its reported standard deviations and 0.1 % of the truth. Packets of the single-input types, which cannot
// say what the second input was, are counted decode errors.
TEST_F(DaemonInProcess, ATwoInputModelMatchesTrackAndFollowsEachModeOnItsOwnInput) {
  const TwoInputPlant two = two_input_plant(path("two_inputs.yaml"));
  const Config& c = two.config;
  const std::string& cfg = two.config_path;
  const Record& rec = two.record;
  const auto& modes = two.modes;
  ASSERT_EQ(c.model.n_inputs(), 2);
  ASSERT_EQ(rec.inputs(), 2);

  Received rx;
  DaemonCounters counters;
  {
    lcm_t* lcm = lcm_create("memq://");
    ASSERT_NE(lcm, nullptr);
    rx.subscribe(lcm, c.lcm);
    {
      Daemon d(c, lcm);
      d.start();
      std::uint64_t published = 0;
      publish_paced(lcm, c, d, rec, 0, rec.size(), published);
      EXPECT_TRUE(wait_for([&] { return all_handled(d) && d.counters().samples_received == published; }, 60.0));
      // The single-input types on both channels: the second input is unknown.
      Record one = rec;
      one.further_u.clear();
      const std::vector<std::uint8_t> batch = encode_batch(one, 0, 64, kUtime0 + 100'000'000, rec.size());
      const std::vector<std::uint8_t> sample = encode_sample({kUtime0 + 200'000'000, rec.size() + 100, 1.0, 2.0, 0.0});
      lcm_publish(lcm, c.lcm.batches_channel.c_str(), batch.data(), static_cast<unsigned>(batch.size()));
      lcm_publish(lcm, c.lcm.samples_channel.c_str(), sample.data(), static_cast<unsigned>(sample.size()));
      EXPECT_TRUE(wait_for([&] { return d.counters().decode_errors == 2; }, 10.0));
      d.stop();
      counters = d.counters();
    }
    dispatch_rest(lcm);
    lcm_destroy(lcm);
  }
  EXPECT_EQ(counters.samples_received, static_cast<std::uint64_t>(rec.size()));
  EXPECT_EQ(counters.samples_processed, static_cast<std::uint64_t>(rec.size()));
  EXPECT_EQ(counters.decode_errors, 2u);
  EXPECT_EQ(counters.samples_dropped + counters.samples_nonfinite + counters.gaps + counters.resets, 0u);

  const std::string us_csv = path("two_inputs_us.csv"), us_est = path("two_inputs_est.csv");
  write_wire_times_csv(rec, us_csv, {"u1", "u2"});
  const Outcome tr = run_cli("track --no-progress --config " + cfg + " --data " + us_csv + " --out " + us_est);
  ASSERT_EQ(tr.code, 0) << tr.output;
  EXPECT_NE(tr.output.find("warm-up fit: used"), std::string::npos) << tr.output;
  const Table est = read_table(us_est);
  ASSERT_GE(rx.estimates.size(), 590u);
  int compared = 0;
  for (const auto& m : rx.estimates) {
    const Eigen::Index k = std::llround(static_cast<double>(m.utime - kUtime0) * 1e-6 / c.sample_time);
    ASSERT_LT(k, est.data.rows());
    ASSERT_EQ(m.n_modes, 3);
    for (std::size_t i = 0; i < modes.size(); ++i) {
      const std::string name = modes[i].name;
      ASSERT_EQ(m.modes[i].wn, est.data(k, est.column(name + "_wn"))) << name << " at sample " << k;
      ASSERT_EQ(m.modes[i].zeta, est.data(k, est.column(name + "_zeta"))) << name << " at sample " << k;
      ASSERT_EQ(m.modes[i].gain, est.data(k, est.column(name + "_gain"))) << name << " at sample " << k;
    }
    ++compared;
  }
  EXPECT_GE(compared, 590);
  // The last estimate: each wn within 4 of the standard deviations the
  // estimator reports with it (the 30 dB noise through that submodel's own
  // input over its 5 s memory) and within 0.1 % of the truth (the start was 5 % off).
  const auto& last = rx.estimates.back();
  for (std::size_t i = 0; i < modes.size(); ++i) {
    const auto& m = last.modes[i];
    const double truth = modes[i].truth.wn;
    std::printf("  %s: wn %.6g (truth %.6g, %+.4f %%, %.2f std), gain %.4g (truth %.4g)\n", modes[i].name.c_str(),
                m.wn, truth, 100.0 * (m.wn / truth - 1.0), (m.wn - truth) / m.wn_std, m.gain, modes[i].truth.gain);
    EXPECT_LT(std::abs(m.wn - truth), 4.0 * m.wn_std) << modes[i].name;
    EXPECT_NEAR(m.wn / truth, 1.0, 0.001) << modes[i].name;
  }
}

// The samples of r whose step() says `flag`, for a RecursiveEstimator run as
// the daemon runs it.
namespace {
std::uint64_t steps_flagged(const Config& c, const Record& r, StepFlags flag) {
  RecursiveEstimator est(c.model, c.estimator);
  std::uint64_t n = 0;
  for (Eigen::Index k = 0; k < r.size(); ++k)
    if (est.step(Sample{r.t(k), r.u(k), r.y(k), r.r(k)}) & flag) ++n;
  return n;
}
}  // namespace

// The paper's loop with mode 3's wn stepping -3 % at 400 s, below the
// divergence reset: the daemon counts the change test's covariance boosts
// (modalwatch_change_boosts_total), as many as the estimator's step() reports
// on the same samples, and no reset.
TEST_F(DaemonInProcess, CountsTheChangeTestsCovarianceBoostsAsTheEstimatorMakesThem) {
  const test_support::PaperModeThreeStep loop = test_support::paper_mode_three_step();
  const Record& r = loop.record;
  const std::uint64_t boosts = steps_flagged(loop.config, r, kChangeBoost);
  ASSERT_GT(boosts, 0u);
  Received rx;
  const DaemonCounters counters = run_in_process(loop.config, r, rx);
  EXPECT_EQ(counters.samples_processed, static_cast<std::uint64_t>(r.size()));
  EXPECT_EQ(counters.change_boosts, boosts);
  EXPECT_EQ(counters.resets, 0u);
}

// The weak mode beside a gain step: the daemon counts the modes returned to
// their estimate after a sign change of their gain
// (modalwatch_mode_restores_total), as many as step() reports.
TEST_F(DaemonInProcess, CountsTheModesReturnedAfterASignChangeAsTheEstimatorReturnsThem) {
  const test_support::SimulatedRecord loop = test_support::weak_mode_beside_a_gain_step();
  const Record& r = loop.record;
  const std::uint64_t restores = steps_flagged(loop.config, r, kModeRestored);
  ASSERT_GT(restores, 0u);
  Received rx;
  const DaemonCounters counters = run_in_process(loop.config, r, rx);
  EXPECT_EQ(counters.samples_processed, static_cast<std::uint64_t>(r.size()));
  EXPECT_EQ(counters.mode_restores, restores);
}

// The warm-up fit runs on the fitter thread, not the estimation loop: a fit
// longer than WatchdogSec (here 1 s; the probe's hook holds the fitter for 3 s
// before the real fit) keeps the WATCHDOG=1 pings coming, and the input that
// arrives meanwhile is held and then estimated, none of it dropped. (WatchdogSec
// is not shorter so that the check holds under TSan on a loaded machine too.)
TEST_F(DaemonInProcess, WarmupFitLongerThanTheWatchdogKeepsPingingAndDropsNothing) {
  using Clock = std::chrono::steady_clock;
  // systemd's stand-in, as in DaemonProcess.NotifiesSystemd...: an abstract datagram socket.
  const int sock = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  ASSERT_GE(sock, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  const std::string name = "modalwatch-fit-notify-" + std::to_string(::getpid());
  std::memcpy(addr.sun_path + 1, name.data(), name.size());
  const auto len = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + 1 + name.size());
  ASSERT_EQ(::bind(sock, reinterpret_cast<sockaddr*>(&addr), len), 0);
  timeval tv{0, 50'000};
  ::setsockopt(sock, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  std::mutex mutex;
  std::vector<Clock::time_point> pings;
  std::atomic<bool> done{false};
  std::thread reader([&] {
    char buf[256];
    while (!done) {
      const ssize_t n = ::recv(sock, buf, sizeof buf, 0);
      if (n > 0 && std::string(buf, static_cast<std::size_t>(n)).find("WATCHDOG=1") != std::string::npos) {
        std::lock_guard<std::mutex> lock(mutex);
        pings.push_back(Clock::now());
      }
    }
  });
  ::setenv("NOTIFY_SOCKET", ("@" + name).c_str(), 1);
  ::setenv("WATCHDOG_USEC", "1000000", 1);
  ::unsetenv("WATCHDOG_PID");

  struct SlowFit : LoopProbe {
    void warmed_up() override { warmed = Clock::now(); }
    void exiting() override {}
    void warmup_fit_running() override {
      fit_start = Clock::now();
      std::this_thread::sleep_for(std::chrono::milliseconds(3000));
      fits.fetch_add(1);
    }
    std::atomic<int> fits{0};
    Clock::time_point fit_start, warmed;  // read after the threads are joined
  } probe;

  const Eigen::Index n = samples_at(20.0);
  Config c = load_config(kDriftConfig);
  lcm_t* lcm = lcm_create("memq://");
  ASSERT_NE(lcm, nullptr);
  Received rx;
  rx.subscribe(lcm, c.lcm);
  DaemonCounters k;
  {
    Daemon d(c, lcm);
    attach_loop_probe(d, probe);
    d.start();
    std::uint64_t published = 0;
    // Up to 4 s of input ahead of the daemon: about 3 s of it arrives during the fit.
    publish_paced(lcm, c, d, 0, n, published, 0, 0, 16384);
    ASSERT_TRUE(wait_for([&] { return all_handled(d) && d.counters().samples_received == std::uint64_t(n); }, 30.0));
    d.stop();
    k = d.counters();
  }
  done = true;
  reader.join();
  ::close(sock);
  ::unsetenv("NOTIFY_SOCKET");
  ::unsetenv("WATCHDOG_USEC");
  dispatch_rest(lcm);
  lcm_destroy(lcm);

  EXPECT_EQ(probe.fits.load(), 1);
  EXPECT_EQ(k.samples_processed, std::uint64_t(n));
  EXPECT_EQ(k.samples_dropped, 0u);
  EXPECT_EQ(k.held_dropped, 0u);
  EXPECT_GT(k.samples_held, 4096u) << "no input arrived during the fit: the test does not test the backlog";
  EXPECT_EQ(k.snapshots_dropped, 0u);
  // The pings from the one before the fit's start until the loop had worked off
  // the held input (warmed_up): one per half WatchdogSec (0.5 s), never a gap of
  // a whole WatchdogSec, which systemd punishes.
  const auto fit_end = probe.fit_start + std::chrono::milliseconds(3000);
  ASSERT_GT(probe.warmed, fit_end);
  std::vector<double> span;  // s since the fit's start
  for (std::size_t i = 0; i < pings.size(); ++i) {
    const bool last_before = pings[i] < probe.fit_start && i + 1 < pings.size() && pings[i + 1] >= probe.fit_start;
    if (last_before || (pings[i] >= probe.fit_start && pings[i] <= probe.warmed))
      span.push_back(std::chrono::duration<double>(pings[i] - probe.fit_start).count());
  }
  ASSERT_GE(span.size(), 6u) << "WATCHDOG=1 pings around a fit of more than 3 s";
  EXPECT_LE(span.front(), 0.0);
  span.push_back(std::chrono::duration<double>(probe.warmed - probe.fit_start).count());
  double worst_gap = 0.0;
  for (std::size_t i = 1; i < span.size(); ++i) worst_gap = std::max(worst_gap, span[i] - span[i - 1]);
  EXPECT_LT(worst_gap, 1.0) << "a WatchdogSec without WATCHDOG=1 during the warm-up fit";
  // One estimate per 0.1 s of sample time in (0, 20) s, the held input included:
  // 199, each 0.1 s (to the sample) after the one before.
  ASSERT_EQ(rx.estimates.size(), 199u);
  for (std::size_t i = 1; i < rx.estimates.size(); ++i)
    EXPECT_NEAR(static_cast<double>(rx.estimates[i].utime - rx.estimates[i - 1].utime), 100'000.0, 250.0) << i;
  EXPECT_NEAR(rx.estimates.back().modes[kFlex].hz, 90.0, 0.5);
  EXPECT_NEAR(rx.estimates.back().modes[kSuspension].hz, 6.0, 0.1);
}

// Garbage, NaN, duplicates, reordering, silence and a burst.
TEST_F(DaemonInProcess, SurvivesBadInputAndCountsIt) {
  const DriftData& data = drift_data();
  Config c = load_config(kDriftConfig);
  c.daemon.stale_time = 0.3;
  c.daemon.sample_ring = 4096;  // small, so that the burst can overflow it
  lcm_t* lcm = lcm_create("memq://");
  ASSERT_NE(lcm, nullptr);
  Received rx;
  rx.subscribe(lcm, c.lcm);
  const Record& rec = data.record;
  const auto sample = [&](Eigen::Index k, std::int64_t utime_shift = 0) {
    StampedSample s;
    s.utime = kUtime0 + utime_shift + std::llround(rec.t(k) * 1e6);
    s.seq = k;
    s.u = rec.u(k);
    s.y = rec.y(k);
    s.r = rec.r(k);
    return s;
  };
  const auto send = [&](const std::string& channel, const std::vector<std::uint8_t>& bytes) {
    lcm_publish(lcm, channel.c_str(), bytes.data(), static_cast<unsigned>(bytes.size()));
  };

  Daemon d(c, lcm);
  d.start();
  Eigen::Index k = samples_at(10.0);
  std::uint64_t published = 0;
  publish_paced(lcm, c, d, 0, k, published);
  ASSERT_TRUE(wait_for([&] { return all_handled(d) && d.counters().samples_received == std::uint64_t(k); }, 20.0));
  ASSERT_FALSE(d.warming_up());

  // Garbage: truncated, a sample on the batch channel (wrong fingerprint), random bytes.
  const std::uint64_t received_before = d.counters().samples_received;
  std::vector<std::uint8_t> truncated = encode_sample(sample(k));
  truncated.resize(20);
  send(c.lcm.samples_channel, truncated);
  send(c.lcm.batches_channel, encode_sample(sample(k)));
  std::mt19937 rng(7);
  for (int i = 0; i < 50; ++i) {
    std::vector<std::uint8_t> junk(1 + rng() % 300);
    for (auto& b : junk) b = static_cast<std::uint8_t>(rng());
    send(i % 2 ? c.lcm.samples_channel : c.lcm.batches_channel, junk);
  }
  // Non-finite samples (each consumes its seq).
  for (int i = 0; i < 5; ++i, ++k) {
    StampedSample s = sample(k);
    (i % 2 ? s.u : s.y) = i == 4 ? std::numeric_limits<double>::infinity() : std::nan("");
    send(c.lcm.samples_channel, encode_sample(s));
  }
  // Duplicates: one sample, then the same packet three more times.
  for (int i = 0; i < 4; ++i) send(c.lcm.samples_channel, encode_sample(sample(k)));
  ++k;
  // Reordering: k+1 before k; k is then out of order, and its empty time slot
  // (2 T between k-1 and k+1) is a gap for the estimator (gap_factor 1.5).
  send(c.lcm.samples_channel, encode_sample(sample(k + 1)));
  send(c.lcm.samples_channel, encode_sample(sample(k)));
  k += 2;
  // Wait for every packet, not only the garbage: under TSan the subscriber may
  // still be decoding the valid ones (5 NaN + 4 duplicate + 2 reordered samples).
  ASSERT_TRUE(wait_for(
      [&] {
        const DaemonCounters n = d.counters();
        return n.decode_errors == 52 && n.samples_received == received_before + 11 && all_handled(d);
      },
      10.0));
  {
    const DaemonCounters n = d.counters();
    EXPECT_EQ(n.decode_errors, 52u);
    EXPECT_EQ(n.samples_nonfinite, 5u);
    EXPECT_EQ(n.samples_duplicate, 3u);
    EXPECT_EQ(n.samples_out_of_order, 1u);
    EXPECT_EQ(n.gaps, 1u);  // the reordered sample's slot; NaN samples keep theirs
  }
  // Silence: nothing for 1 s of wall time, then the stream resumes 10 s later in sample time.
  std::this_thread::sleep_for(std::chrono::milliseconds(1000));
  const std::int64_t shift = 10'000'000;
  const Eigen::Index resume = k;
  k = samples_at(14.0);
  published += 5 + 4 + 2;  // the single samples above
  publish_paced(lcm, c, d, resume, k, published, shift);
  ASSERT_TRUE(wait_for([&] { return all_handled(d) && d.counters().samples_received == published; }, 20.0));
  EXPECT_EQ(d.counters().samples_dropped, 0u);
  EXPECT_EQ(d.counters().gaps, 2u);
  // A burst: 8 s of samples at once, about 100x the rate and beyond.
  const Eigen::Index burst_end = samples_at(22.0);
  const std::int64_t burst_utime = kUtime0 + shift + std::llround(rec.t(k) * 1e6);
  publish_range(lcm, c.lcm.batches_channel, rec, k, burst_end, 256, shift);
  published += static_cast<std::uint64_t>(burst_end - k);
  // Then the normal stream again.
  publish_paced(lcm, c, d, burst_end, samples_at(29.5), published, shift);  // 7.5 s to recover, before the drift
  ASSERT_TRUE(wait_for([&] { return all_handled(d) && d.counters().samples_received == published; }, 20.0));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  d.stop();
  dispatch_rest(lcm);
  lcm_destroy(lcm);

  const DaemonCounters n = d.counters();
  EXPECT_EQ(n.samples_received, n.samples_processed + n.samples_dropped + n.samples_nonfinite + n.samples_duplicate +
                                    n.samples_out_of_order);
  EXPECT_EQ(n.decode_errors, 52u);
  EXPECT_EQ(n.samples_nonfinite, 5u);
  EXPECT_EQ(n.samples_duplicate, 3u);
  int health = 0;
  for (const auto& s : rx.status) health |= s.health;
  EXPECT_TRUE(health & Fault::HEALTH_DECODE_ERRORS);
  EXPECT_TRUE(health & Fault::HEALTH_STALE_INPUT);
  EXPECT_TRUE(health & Fault::HEALTH_INPUT_GAP);
  EXPECT_EQ((health & Fault::HEALTH_RING_OVERFLOW) != 0, n.samples_dropped > 0);
  // Every drop in the burst left a time gap behind it (at most one per overflow episode).
  if (n.samples_dropped > 0) {
    EXPECT_GE(n.gaps, 3u);
  }
  ASSERT_FALSE(rx.status.empty());
  const auto& last_status = rx.status.back();
  EXPECT_EQ(last_status.decode_errors, 52);
  EXPECT_EQ(last_status.samples_nonfinite, 5);
  EXPECT_EQ(last_status.samples_duplicate, 3);
  // Estimation went on: the last estimates are fresh and right (no drift before 30 s).
  ASSERT_FALSE(rx.estimates.empty());
  const auto& fin = rx.estimates.back();
  EXPECT_GT(static_cast<double>(fin.utime - kUtime0 - shift) * 1e-6, 29.0);
  EXPECT_NEAR(fin.modes[kFlex].hz, 90.0, 0.9);
  EXPECT_NEAR(fin.modes[kSuspension].hz, 6.0, 0.2);
  // No fault flag from garbage, NaN, duplicates, reordering or silence. (After
  // the burst, whose drops cost thousands of samples, prefilter resets and
  // estimator resets, a transient may pass a threshold: not asserted.)
  int checked = 0;
  for (const auto& s : rx.status) {
    if (s.utime >= burst_utime) continue;
    ++checked;
    for (int e = 0; e < 3 * s.n_modes; ++e) EXPECT_NE(entry(s, e).state, "raised") << "false alarm";
  }
  EXPECT_GT(checked, 100);
}

// ============================================================================
// modalwatchd as a child process over udpm on loopback.

// A checkpoint that cannot be written (here: its directory is removed after
// start-up; a full disk fails the same way, with ENOSPC) is counted and logged,
// the previous one stays, and estimation goes on.
TEST_F(DaemonInProcess, CheckpointFailureIsLoggedAndEstimationContinues) {
  drift_data();
  Config c = load_config(kDriftConfig);
  std::filesystem::create_directories(path("missing-dir"));
  c.daemon.checkpoint_path = path("missing-dir/state.ckpt");
  c.daemon.checkpoint_period = 0.1;
  lcm_t* lcm = lcm_create("memq://");
  ASSERT_NE(lcm, nullptr);
  Received rx;
  rx.subscribe(lcm, c.lcm);
  {
    Daemon d(c, lcm);
    std::filesystem::remove_all(path("missing-dir"));
    d.start();
    std::uint64_t published = 0;
    publish_paced(lcm, c, d, 0, samples_at(8.0), published);
    ASSERT_TRUE(wait_for([&] { return d.counters().checkpoint_failures >= 2; }, 10.0));
    publish_paced(lcm, c, d, samples_at(8.0), samples_at(12.0), published);
    ASSERT_TRUE(wait_for([&] { return all_handled(d) && d.counters().samples_received == published; }, 20.0));
    d.stop();
    EXPECT_FALSE(d.write_checkpoint());
    const DaemonCounters k = d.counters();
    EXPECT_EQ(k.checkpoints_written, 0u);
    EXPECT_GE(k.checkpoint_failures, 3u);
    EXPECT_EQ(k.samples_processed, published);
  }
  dispatch_rest(lcm);
  lcm_destroy(lcm);
  EXPECT_FALSE(std::filesystem::exists(path("missing-dir")));
  ASSERT_FALSE(rx.estimates.empty());
  EXPECT_GT(static_cast<double>(rx.estimates.back().utime - kUtime0) * 1e-6, 11.8);
  EXPECT_NEAR(rx.estimates.back().modes[kFlex].hz, 90.0, 0.5);
}
