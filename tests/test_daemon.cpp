// The daemon end to end, over real LCM and real threads, on a simulated
// flexible beam whose flexible mode loses 15 % stiffness at t = 30..32 s
// (config/flexible-beam-drift.yaml, simulated and tracked once per run with
// the real CLI).
//
// - DaemonInProcess runs the Daemon class in process on one shared memq://
//   instance (publisher, daemon and collector), faster than real time: the
//   test paces its publishing by the daemon's counters, and the daemon runs
//   on sample time.
// - DaemonProcess runs the modalwatchd binary as a child process over udpm on
//   loopback (ttl=0, a port of its own) and signals it.
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
#include <cstddef>
#include <cstring>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <numbers>
#include <random>
#include <sstream>

#include "daemon_support.hpp"

#include "modalwatch/io/checkpoint.hpp"
#include "daemon/loop_probe.hpp"
#include "modalwatch/daemon/daemon.hpp"

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
  Config c = load_config(kDriftConfig);
  lcm_t* lcm = lcm_create("memq://");
  ASSERT_NE(lcm, nullptr);
  Received rx;
  rx.subscribe(lcm, c.lcm);
  {
    Daemon d(c, lcm);
    d.start();
    std::uint64_t published = 0;
    publish_paced(lcm, c, d, 0, data.record.size(), published);
    ASSERT_TRUE(wait_for([&] { return all_handled(d) && d.counters().samples_received == 245760u; }, 30.0));
    d.stop();
    const DaemonCounters k = d.counters();
    EXPECT_EQ(k.samples_processed, 245760u);
    EXPECT_EQ(k.samples_dropped + k.decode_errors + k.samples_nonfinite + k.gaps + k.resets, 0u);
  }
  dispatch_rest(lcm);
  lcm_destroy(lcm);

  // Flags: the first raise of each quantity of each mode.
  std::array<double, 6> first_raise;
  first_raise.fill(-1.0);
  for (const auto& s : rx.status) {
    ASSERT_EQ(s.n_modes, 2);
    for (int e = 0; e < 6; ++e)
      if (entry(s, e).state == "raised" && first_raise[e] < 0.0)
        first_raise[e] = static_cast<double>(entry(s, e).since - kUtime0) * 1e-6;
  }
  for (int q = 0; q < 3; ++q) EXPECT_LT(first_raise[3 * kSuspension + q], 0.0) << "suspension quantity " << q << " flagged";
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
  const std::string us_csv = path("record_us.csv"), us_est = path("est_us.csv");
  {
    const Record& rec = data.record;
    FILE* f = std::fopen(us_csv.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fprintf(f, "t,u,y,r\n");
    const std::int64_t first = std::llround(rec.t(0) * 1e6);
    for (Eigen::Index k = 0; k < rec.size(); ++k) {
      const Eigen::Index b = k / 64 * 64;  // publish_paced's batches
      const std::int64_t utime = std::llround(rec.t(b) * 1e6) + std::llround(static_cast<double>(k - b) * rec.sample_time() * 1e6);
      std::fprintf(f, "%.17g,%.17g,%.17g,%.17g\n", static_cast<double>(utime - first) * 1e-6, rec.u(k), rec.y(k), rec.r(k));
    }
    std::fclose(f);
  }
  const std::string us_flags = path("flags_us.csv");
  const Outcome tr_us = run_cli("track --no-progress --config " + kDriftConfig + " --data " + us_csv + " --out " +
                                us_est + " --faults " + us_flags);
  ASSERT_EQ(tr_us.code, 0) << tr_us.output;

  // Flags: `track --faults` on the same samples changes exactly the daemon's
  // flags (time to the microsecond, mode, quantity, event). The daemon's
  // changes are read off its fault status: a flag's RAISED bit turning on (at
  // `since`) or off (at the message's utime).
  {
    const std::int64_t first = std::llround(data.record.t(0) * 1e6);
    const char* kQuantity[3] = {"wn", "zeta", "gain"};
    std::vector<std::string> daemon_changes, track_changes;
    std::array<bool, 6> up{};
    for (const auto& s : rx.status) {
      for (int e = 0; e < 6; ++e) {
        const modalwatch::mode_status_t& m = s.modes[static_cast<std::size_t>(e / 3)];
        const modalwatch::quantity_status_t& q = e % 3 == 0 ? m.wn : e % 3 == 1 ? m.zeta : m.gain;
        const bool now = q.state == "raised";
        if (now == up[e]) continue;
        up[e] = now;
        const std::int64_t at = (now ? q.since : s.utime) - kUtime0 - first;
        daemon_changes.push_back(std::to_string(at) + "," + m.name + "," + kQuantity[e % 3] + "," +
                                 (now ? "raised" : "cleared"));
      }
    }
    std::ifstream in(us_flags);
    std::string line;
    std::getline(in, line);
    ASSERT_EQ(line, "t,mode,quantity,event,value,baseline,relative,sigma");
    while (std::getline(in, line)) {
      std::stringstream row(line);
      std::string t, mode, quantity, event;
      std::getline(row, t, ',');
      std::getline(row, mode, ',');
      std::getline(row, quantity, ',');
      std::getline(row, event, ',');
      track_changes.push_back(std::to_string(std::llround(std::stod(t) * 1e6)) + "," + mode + "," + quantity + "," +
                              event);
    }
    EXPECT_FALSE(daemon_changes.empty());
    EXPECT_EQ(track_changes, daemon_changes) << "track --faults and the daemon flag differently";
  }
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
      worst_csv = std::max(worst_csv, std::abs(m.modes[i].wn - data.track.data(k, c_wn[i])) / data.track.data(k, c_wn[i]));
  }
  EXPECT_LT(worst_csv, 1e-5);
  // And they are right: flex at the end near 82.98 Hz, suspension at 6 Hz.
  const auto& fin = rx.estimates.back();
  EXPECT_NEAR(fin.modes[kFlex].hz, 90.0 * std::sqrt(0.85), 0.5);
  EXPECT_NEAR(fin.modes[kSuspension].hz, 6.0, 0.1);
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
  ASSERT_TRUE(wait_for([&] {
    const DaemonCounters n = d.counters();
    return n.decode_errors == 52 && n.samples_received == received_before + 11 && all_handled(d);
  }, 10.0));
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
  EXPECT_EQ(n.samples_received,
            n.samples_processed + n.samples_dropped + n.samples_nonfinite + n.samples_duplicate + n.samples_out_of_order);
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

namespace {

class DaemonProcess : public ScratchDir {
 protected:
  void SetUp() override {
    ScratchDir::SetUp();
    drift_data();
    port_ = 7700 + static_cast<int>(::getpid() % 250);
    url_ = "udpm://239.255.76.67:" + std::to_string(port_) + "?ttl=0";
    lcm_ = lcm_create(url_.c_str());
    ASSERT_NE(lcm_, nullptr) << "udpm on loopback unavailable (scripts/setup.sh adds the multicast route)";
    lcm_settings_.url = url_;
    rx_.subscribe(lcm_, lcm_settings_);
    handler_ = std::thread([this] {
      while (!stop_handler_) lcm_handle_timeout(lcm_, 20);
    });
  }
  void TearDown() override {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
    stop_handler_ = true;
    if (handler_.joinable()) handler_.join();
    if (lcm_) lcm_destroy(lcm_);
    ScratchDir::TearDown();
  }

  // The drift config with this test's LCM URL and daemon/faults sections.
  std::string write_config(const std::string& name, const std::string& daemon_extra, const std::string& faults) {
    std::ifstream in(kDriftConfig);
    std::stringstream text;
    text << in.rdbuf();
    std::string yaml = text.str();
    yaml = yaml.substr(0, yaml.find("# The daemon:"));
    yaml += "lcm:\n  url: \"" + url_ + "\"\n";
    yaml += "daemon:\n  loop_rate_hz: 2000\n  publish_period: 0.1\n  heartbeat_period: 0.2\n  checkpoint:\n    path: " +
            path("state.ckpt") + "\n    period: 0.5\n" + daemon_extra;
    yaml += faults;
    return write(name, yaml);
  }

  void start(const std::string& config) {
    log_ = path("daemon" + std::to_string(++starts_) + ".log");
    pid_ = ::fork();
    ASSERT_GE(pid_, 0);
    if (pid_ == 0) {
      for (const auto& [k, v] : env_) ::setenv(k.c_str(), v.c_str(), 1);
      const int fd = ::open(log_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      ::dup2(fd, 1);
      ::dup2(fd, 2);
      ::execl(MODALWATCHD, MODALWATCHD, "--config", config.c_str(), static_cast<char*>(nullptr));
      ::_exit(127);
    }
    const std::size_t before = rx_.count_heartbeats();
    ASSERT_TRUE(wait_for([&] { return rx_.count_heartbeats() > before; }, 10.0)) << log();
  }

  // Exit code, or -1 on timeout / signal.
  int stop(int sig, double timeout_s = 10.0) {
    ::kill(pid_, sig);
    int status = 0;
    const bool done = wait_for([&] { return ::waitpid(pid_, &status, WNOHANG) == pid_; }, timeout_s);
    pid_ = -1;
    if (!done) return -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }

  std::string log() const {
    std::ifstream in(log_);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  }

  // Samples [begin, end) at `speed` times real time; returns the wall time each batch went out.
  void publish(Eigen::Index begin, Eigen::Index end, double speed, std::int64_t seq_shift = 0) {
    const auto t0 = std::chrono::steady_clock::now();
    publish_range(lcm_, lcm_settings_.batches_channel, drift_data().record, begin, end, 128, 0, seq_shift,
                  [&](Eigen::Index next) {
                    sent_.push_back({next - 1 + seq_shift, std::chrono::steady_clock::now()});
                    std::this_thread::sleep_until(
                        t0 + std::chrono::duration<double>(static_cast<double>(next - begin) / kFs / speed));
                  });
  }

  // Runs modalwatchd to completion and checks its exit code and message.
  // `wrapper` is a command line prefix (limits, privileges) for the daemon.
  void start_expect_exit(const std::string& config, int code, const std::string& message,
                         const std::string& wrapper = "") {
    const std::string cmd = wrapper + std::string(MODALWATCHD) + " --config " + config + " 2>&1";
    FILE* pipe = popen(cmd.c_str(), "r");
    ASSERT_NE(pipe, nullptr);
    std::string out;
    char buf[4096];
    while (std::fgets(buf, sizeof buf, pipe)) out += buf;
    const int status = pclose(pipe);
    EXPECT_EQ(WIFEXITED(status) ? WEXITSTATUS(status) : -1, code) << out;
    EXPECT_NE(out.find(message), std::string::npos) << out;
  }

  struct Sent {
    std::int64_t last_seq;
    std::chrono::steady_clock::time_point when;
  };

  int port_ = 0;
  std::string url_, log_;
  lcm_t* lcm_ = nullptr;
  LcmSettings lcm_settings_;
  Received rx_;
  std::thread handler_;
  std::atomic<bool> stop_handler_{false};
  pid_t pid_ = -1;
  int starts_ = 0;
  std::vector<std::pair<std::string, std::string>> env_;  // for the child
  std::vector<Sent> sent_;
};

}  // namespace

TEST_F(DaemonProcess, SigtermCheckpointsAndRestartResumesWithoutWarmup) {
  const std::string cfg = write_config("c.yaml", "", "");
  start(cfg);
  const Eigen::Index n1 = samples_at(12.0);
  publish(0, n1, 20.0);
  ASSERT_TRUE(wait_for([&] { return rx_.count_estimates() >= 115; }, 10.0)) << log();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  modalwatch::estimates_t before;
  {
    std::lock_guard<std::mutex> lock(rx_.mutex);
    before = rx_.estimates.back();
  }
  EXPECT_EQ(stop(SIGTERM), 0) << log();
  const std::string log1 = log();
  EXPECT_NE(log1.find("checkpoint written"), std::string::npos) << log1;
  const modalwatch::Checkpoint ck = modalwatch::read_checkpoint(path("state.ckpt"));
  EXPECT_EQ(ck.last_seq, n1 - 1) << "the final checkpoint includes every sample sent";
  ASSERT_EQ(ck.estimator.model().submodels.size(), 2u);
  // The checkpoint holds the estimate after the last sample, the last message the
  // one at the last 0.1 s boundary before it: close, not equal.
  EXPECT_NEAR(modal_parameters(ck.estimator.model().submodels[kFlex]).wn, before.modes[kFlex].wn, 2e-3 * before.modes[kFlex].wn);

  // Restart: resumes from the checkpoint, no warm-up: the first estimates are the
  // checkpointed ones carried on, not the configured initial guess.
  const std::size_t seen = rx_.count_estimates();
  start(cfg);
  publish(n1, n1 + samples_at(2.0), 20.0);
  ASSERT_TRUE(wait_for([&] { return rx_.count_estimates() >= seen + 15; }, 10.0)) << log();
  const std::string log2 = log();
  EXPECT_NE(log2.find("restored checkpoint"), std::string::npos) << log2;
  EXPECT_NE(log2.find("resumed from checkpoint"), std::string::npos) << log2;
  {
    std::lock_guard<std::mutex> lock(rx_.mutex);
    const auto& first = rx_.estimates[seen];
    EXPECT_LT(static_cast<double>(first.utime - kUtime0) * 1e-6, 12.2);
    // A warm-up would publish the configured model with zero std for 5 s (20480 samples).
    EXPECT_LT(first.samples_processed, 1000);
    EXPECT_GT(first.modes[kFlex].wn_std, 0.0) << "still warming up after the restore";
    // restore() restarts the prefilters as after a gap: the first estimate moves by up to ~0.6 %.
    EXPECT_NEAR(first.modes[kFlex].wn, before.modes[kFlex].wn, 0.01 * before.modes[kFlex].wn);
    EXPECT_NEAR(first.modes[kSuspension].wn, before.modes[kSuspension].wn, 0.02 * before.modes[kSuspension].wn);
    // No suppression for warm-up in the first fault status after the restart.
    bool suppressed_after = false;
    for (std::size_t i = 0; i < rx_.status.size(); ++i)
      if (rx_.status[i].utime > first.utime &&
          (rx_.status[i].state == "warming_up" || rx_.status[i].modes[0].wn.state == "suppressed"))
        suppressed_after = true;
    EXPECT_FALSE(suppressed_after);
  }
  EXPECT_EQ(stop(SIGINT), 0) << log();
}

TEST_F(DaemonProcess, SigkillLosesAtMostOneCheckpointPeriod) {
  const std::string cfg = write_config("c.yaml", "", "");
  start(cfg);
  // 25 s of samples at 10x: 2.5 s of wall time, checkpoints every 0.5 s; kill at 2.2 s.
  std::thread sender([&] { publish(0, samples_at(25.0), 10.0); });
  std::this_thread::sleep_for(std::chrono::milliseconds(2200));
  const auto killed_at = std::chrono::steady_clock::now();
  const std::string log1 = log();
  EXPECT_EQ(stop(SIGKILL), -1);
  sender.join();
  ASSERT_TRUE(std::filesystem::exists(path("state.ckpt"))) << log1;
  const modalwatch::Checkpoint ck = modalwatch::read_checkpoint(path("state.ckpt"));
  // When was the checkpoint's newest sample sent?
  std::chrono::steady_clock::time_point sent_at{};
  for (const Sent& s : sent_)
    if (s.last_seq >= ck.last_seq) {
      sent_at = s.when;
      break;
    }
  ASSERT_NE(sent_at.time_since_epoch().count(), 0);
  const double lost = std::chrono::duration<double>(killed_at - sent_at).count();
  EXPECT_LE(lost, 0.5 + 0.15) << "more than one checkpoint period (0.5 s) lost";
  EXPECT_GT(ck.last_seq, samples_at(5.0)) << "no checkpoint after the warm-up";

  const std::size_t seen = rx_.count_estimates();
  start(cfg);
  publish(samples_at(25.0), samples_at(26.0), 10.0);
  ASSERT_TRUE(wait_for([&] { return rx_.count_estimates() >= seen + 5; }, 10.0)) << log();
  EXPECT_NE(log().find("restored checkpoint"), std::string::npos) << log();
  EXPECT_EQ(stop(SIGTERM), 0) << log();
}

TEST_F(DaemonProcess, SighupAppliesAValidConfigAndKeepsTheRunningOneOnAnInvalid) {
  const std::string cfg = write_config("c.yaml", "", "");
  start(cfg);
  publish(0, samples_at(8.0), 20.0);
  ASSERT_TRUE(wait_for([&] { return rx_.count_estimates() >= 70; }, 10.0)) << log();
  // Valid: estimates every 0.5 s of sample time instead of 0.1 s.
  write_config("c.yaml", "", "");
  {
    std::string text;
    std::ifstream in(cfg);
    std::stringstream s;
    s << in.rdbuf();
    text = s.str();
    text.replace(text.find("publish_period: 0.1"), std::string("publish_period: 0.1").size(), "publish_period: 0.5");
    std::ofstream(cfg) << text;
  }
  ::kill(pid_, SIGHUP);
  ASSERT_TRUE(wait_for([&] { return log().find("reloaded") != std::string::npos; }, 5.0)) << log();
  std::size_t mark = rx_.count_estimates();
  publish(samples_at(8.0), samples_at(12.0), 20.0);
  ASSERT_TRUE(wait_for([&] { return rx_.count_estimates() >= mark + 7; }, 10.0)) << log();
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  {
    std::lock_guard<std::mutex> lock(rx_.mutex);
    const std::size_t n = rx_.estimates.size() - mark;
    EXPECT_GE(n, 7u);
    EXPECT_LE(n, 9u);  // 4 s at 0.5 s (0.1 s would give 40)
  }
  // Invalid: the running config stays, and says why.
  {
    std::ofstream(cfg, std::ios::app) << "  bogus_key: 1\n";
  }
  ::kill(pid_, SIGHUP);
  ASSERT_TRUE(wait_for([&] { return log().find("reload rejected") != std::string::npos; }, 5.0)) << log();
  EXPECT_NE(log().find("bogus_key"), std::string::npos) << log();
  mark = rx_.count_estimates();
  publish(samples_at(12.0), samples_at(14.0), 20.0);
  ASSERT_TRUE(wait_for([&] { return rx_.count_estimates() >= mark + 3; }, 10.0)) << log();
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_LE(rx_.count_estimates() - mark, 5u) << "the rejected file changed the publish period";
  EXPECT_EQ(stop(SIGTERM), 0) << log();
}

TEST_F(DaemonProcess, BadConfigOrLcmUrlExitsWithAMessage) {
  const std::string bad = write("bad.yaml", "sample_rate_hz: 10\nmodel: {submodels: []}\n");
  start_expect_exit(bad, 2, "must list at least one submodel");
  std::string text;
  {
    std::ifstream in(write_config("c.yaml", "", ""));
    std::stringstream s;
    s << in.rdbuf();
    text = s.str();
  }
  text.replace(text.find(url_), url_.size(), "nosuchprovider://x");
  start_expect_exit(write("url.yaml", text), 2, "cannot open LCM provider");
}

// ASan and TSan make mlockall a no-op that succeeds (their shadow memory is
// terabytes): under them nothing is locked and a refusal cannot be provoked.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif

// daemon.realtime_priority where the process may not have it: start-up stops
// with exit code 2 and says which key and which limit, rather than running
// without the real-time scheduling the config asked for. The refusals are
// provoked with util-linux's prlimit and, as root, setpriv, which drops
// CAP_IPC_LOCK / CAP_SYS_NICE from the bounding set (exec then drops them from
// the process): a locked-memory limit below the process size fails mlockall;
// with mlockall allowed, RLIMIT_RTPRIO = 0 fails SCHED_FIFO.
TEST_F(DaemonProcess, RealtimePriorityThatIsNotPermittedExitsNamingTheKey) {
  const std::string config = write_config("rt.yaml", "  realtime_priority: 50\n", "");
  const bool root = ::geteuid() == 0;
  if (!kSanitized)
    start_expect_exit(config, 2, "key 'daemon.realtime_priority': mlockall failed",
                      std::string("prlimit --memlock=65536:65536 --rtprio=0:0 ") +
                          (root ? "setpriv --bounding-set=-sys_nice,-ipc_lock " : ""));
  rlimit memlock{};
  ::getrlimit(RLIMIT_MEMLOCK, &memlock);
  if (!root && memlock.rlim_cur != RLIM_INFINITY && !kSanitized) return;  // mlockall refused first: checked above
  start_expect_exit(config, 2, "key 'daemon.realtime_priority': SCHED_FIFO at priority 50 not permitted",
                    std::string("prlimit --rtprio=0:0 ") + (root ? "setpriv --bounding-set=-sys_nice " : ""));
}

namespace {
struct ThreadSched {
  std::string name;
  int policy = -1;
  int priority = -1;
};
// Every thread of `pid` with its scheduling policy and real-time priority
// (fields 41 and 40 of /proc/<pid>/task/<tid>/stat, counted after the comm).
std::vector<ThreadSched> thread_scheduling(pid_t pid) {
  std::vector<ThreadSched> out;
  for (const auto& task : std::filesystem::directory_iterator("/proc/" + std::to_string(pid) + "/task")) {
    std::ifstream comm(task.path() / "comm"), stat(task.path() / "stat");
    ThreadSched t;
    std::getline(comm, t.name);
    std::string line;
    std::getline(stat, line);
    std::istringstream rest(line.substr(line.rfind(')') + 2));
    std::vector<std::string> f{std::istream_iterator<std::string>(rest), std::istream_iterator<std::string>()};
    if (f.size() < 39) continue;  // the thread exited while being read
    t.priority = std::stoi(f[37]);
    t.policy = std::stoi(f[38]);
    out.push_back(t);
  }
  return out;
}
}  // namespace

// daemon.realtime_priority where it is permitted: the latency path (subscriber,
// estimation loop, publisher, and LCM's receive thread that the subscription
// starts) runs SCHED_FIFO at that priority, the rest (main, checkpointer,
// warm-up fitter) at normal priority, and memory is locked.
TEST_F(DaemonProcess, RealtimePriorityPutsTheLatencyPathOnSchedFifo) {
  // The same checks as the daemon's own, made here on this thread.
  sched_param fifo{};
  fifo.sched_priority = 20;
  rlimit memlock{};
  ::getrlimit(RLIMIT_MEMLOCK, &memlock);
  if (pthread_setschedparam(pthread_self(), SCHED_FIFO, &fifo) != 0 ||
      (::geteuid() != 0 && memlock.rlim_cur != RLIM_INFINITY))
    GTEST_SKIP() << "SCHED_FIFO 20 or mlockall not permitted for this user (root, or LimitRTPRIO/LimitMEMLOCK)";
  sched_param normal{};
  pthread_setschedparam(pthread_self(), SCHED_OTHER, &normal);

  start(write_config("rt.yaml", "  realtime_priority: 20\n", ""));
  publish(0, samples_at(2.0), 4.0);
  // Threads the daemon does not name keep the process name: main and LCM's receiver.
  std::map<std::string, std::vector<int>> policies;  // thread name -> policy of each
  for (const auto& t : thread_scheduling(pid_)) {
    policies[t.name].push_back(t.policy);
    if (t.policy == SCHED_FIFO) {
      EXPECT_EQ(t.priority, 20) << t.name;
    }
  }
  for (const char* rt : {"mw-subscribe", "mw-estimate", "mw-publish"})
    EXPECT_EQ(policies[rt], std::vector<int>{SCHED_FIFO}) << rt;
  EXPECT_EQ(policies["mw-checkpoint"], std::vector<int>{SCHED_OTHER});
  if (policies.count("mw-fit")) {
    EXPECT_EQ(policies["mw-fit"], std::vector<int>{SCHED_OTHER});
  }
  std::vector<int> unnamed = policies["modalwatchd"];
  std::sort(unnamed.begin(), unnamed.end());
  EXPECT_EQ(unnamed, (std::vector<int>{SCHED_OTHER, SCHED_FIFO})) << "main, LCM's receive thread";
  std::ifstream status("/proc/" + std::to_string(pid_) + "/status");
  std::string line;
  long locked_kib = 0;
  while (std::getline(status, line))
    if (line.rfind("VmLck:", 0) == 0) locked_kib = std::stol(line.substr(6));
  if (!kSanitized) {
    EXPECT_GT(locked_kib, 1024) << "mlockall";
  }
  EXPECT_EQ(stop(SIGTERM), 0) << log();
}

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

// `modalwatch watch` prints the daemon's messages as they arrive, one line each.
TEST_F(DaemonProcess, WatchPrintsEstimatesAndFlags) {
  const std::string cfg = write_config("c.yaml", "", "");
  start(cfg);
  std::string out;
  std::thread watcher([&] {
    const std::string cmd = std::string(MODALWATCH_CLI) + " watch --config " + cfg + " --count 20 --timeout 20 2>&1";
    FILE* pipe = popen(cmd.c_str(), "r");
    char buf[4096];
    while (pipe && std::fgets(buf, sizeof buf, pipe)) out += buf;
    if (pipe) pclose(pipe);
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // watch subscribes
  publish(0, samples_at(8.0), 20.0);
  watcher.join();
  EXPECT_EQ(stop(SIGTERM), 0) << log();
  // 20 estimates lines (0.1 s apart) and the fault status lines between them.
  std::istringstream lines(out);
  std::string line;
  int estimates = 0, faults = 0;
  while (std::getline(lines, line)) {
    if (line.rfind("estimates t =", 0) == 0) {
      ++estimates;
      EXPECT_NE(line.find("| suspension: f ="), std::string::npos) << line;
      EXPECT_NE(line.find("| flex: f ="), std::string::npos) << line;
    }
    if (line.rfind("faults    t =", 0) == 0) {
      ++faults;
      EXPECT_NE(line.find("| flags: none"), std::string::npos) << line;  // no drift before 30 s
      EXPECT_NE(line.find("| health: "), std::string::npos) << line;
      // 8 s: the 5 s warm-up and the first 3 s of the 10 s learn window. Flags cannot rise yet, and watch says so.
      EXPECT_TRUE(line.find("cannot flag yet") != std::string::npos || line.find("no input yet") != std::string::npos)
          << line;
    }
  }
  EXPECT_EQ(estimates, 20) << out;
  EXPECT_GE(faults, 15) << out;
}

// systemd's protocol, with a stand-in for systemd: an abstract unix datagram
// socket in NOTIFY_SOCKET, WatchdogSec=0.2 s in WATCHDOG_USEC.
TEST_F(DaemonProcess, NotifiesSystemdReadyWatchdogReloadingStopping) {
  const int sock = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  ASSERT_GE(sock, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  const std::string name = "modalwatch-notify-" + std::to_string(::getpid());
  std::memcpy(addr.sun_path + 1, name.data(), name.size());  // abstract: leading NUL
  const auto len = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + 1 + name.size());
  ASSERT_EQ(::bind(sock, reinterpret_cast<sockaddr*>(&addr), len), 0);
  timeval tv{0, 100'000};
  ::setsockopt(sock, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  std::mutex mutex;
  std::vector<std::pair<std::string, std::chrono::steady_clock::time_point>> got;
  std::atomic<bool> done{false};
  std::thread reader([&] {
    char buf[512];
    while (!done) {
      const ssize_t n = ::recv(sock, buf, sizeof buf, 0);
      if (n <= 0) continue;
      std::lock_guard<std::mutex> lock(mutex);
      got.emplace_back(std::string(buf, static_cast<std::size_t>(n)), std::chrono::steady_clock::now());
    }
  });
  const auto count = [&](const std::string& what) {
    std::lock_guard<std::mutex> lock(mutex);
    return std::count_if(got.begin(), got.end(), [&](const auto& m) { return m.first.find(what) != std::string::npos; });
  };
  env_ = {{"NOTIFY_SOCKET", "@" + name}, {"WATCHDOG_USEC", "200000"}};
  const std::string cfg = write_config("c.yaml", "", "");
  start(cfg);
  EXPECT_TRUE(wait_for([&] { return count("READY=1") == 1; }, 5.0)) << log();
  publish(0, samples_at(8.0), 20.0);  // 0.4 s
  std::this_thread::sleep_for(std::chrono::milliseconds(600));
  // WATCHDOG=1 every half WatchdogSec from the estimation loop: about 10 in 1 s.
  EXPECT_GE(count("WATCHDOG=1"), 7) << log();
  EXPECT_NE(log().find("systemd watchdog 200 ms"), std::string::npos) << log();
  ::kill(pid_, SIGHUP);
  EXPECT_TRUE(wait_for([&] { return count("READY=1") == 2; }, 5.0)) << log();
  EXPECT_EQ(count("RELOADING=1"), 1);
  EXPECT_EQ(stop(SIGTERM), 0) << log();
  EXPECT_TRUE(wait_for([&] { return count("STOPPING=1") == 1; }, 2.0));
  done = true;
  reader.join();
  ::close(sock);
  // Order: READY, then RELOADING before the second READY, STOPPING last.
  std::vector<std::string> lifecycle;
  for (const auto& [m, t] : got)
    if (m.find("WATCHDOG") == std::string::npos) lifecycle.push_back(m.substr(0, m.find('\n')));
  ASSERT_EQ(lifecycle.size(), 4u);
  EXPECT_EQ(lifecycle[0], "READY=1");
  EXPECT_EQ(lifecycle[1], "RELOADING=1");
  EXPECT_EQ(lifecycle[2], "READY=1");
  EXPECT_EQ(lifecycle[3], "STOPPING=1");
}
