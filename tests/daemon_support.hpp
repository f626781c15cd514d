#pragma once
// Helpers for the daemon's end-to-end tests: a simulated drifting record (made
// once per test binary with the real `modalwatch simulate` and `track`), LCM
// publishing of that record, and collection of the daemon's messages.
#include <lcm/lcm.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <type_traits>
#include <vector>

#include <gtest/gtest.h>

#include <modalwatch/estimates_t.hpp>
#include <modalwatch/fault_status_t.hpp>
#include <modalwatch/heartbeat_t.hpp>

#include "simulation_support.hpp"
#include "support.hpp"

#include "modalwatch/daemon/daemon.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/io/csv.hpp"
#include "modalwatch/io/messages.hpp"
#include "modalwatch/io/records.hpp"
#include "modalwatch/simulator.hpp"

namespace modalwatch::test_support {

// config/flexible-beam-drift.yaml: 4096 Hz, modes "suspension" and "flex"; flex
// loses 15 % stiffness over t in [30, 32] s.
inline const std::string kDriftConfig = test_support::source_file("config/flexible-beam-drift.yaml");
constexpr double kDriftStart = 30.0;         // s
constexpr std::int64_t kUtime0 = 1'000'000;  // us, utime of sample 0 on the wire

// The drift record and (track_csv, when asked for) `modalwatch track`'s
// estimates of it, made once per process.
struct DriftData {
  std::string dir, record_csv, track_csv;
  Record record;
  Table track;  // empty until drift_track()
};

inline const DriftData& drift_data() {
  static DriftData d = [] {
    DriftData x;
    x.dir =
        (std::filesystem::temp_directory_path() / ("modalwatch_daemon_data_" + std::to_string(::getpid()))).string();
    std::filesystem::create_directories(x.dir);
    x.record_csv = x.dir + "/record.csv";
    x.track_csv = x.dir + "/est.csv";
    const Outcome sim = run_cli("simulate --config " + kDriftConfig + " --out " + x.record_csv);
    EXPECT_EQ(sim.code, 0) << sim.output;
    x.record = read_record(x.record_csv);
    return x;
  }();
  return d;
}

inline const DriftData& drift_track() {
  auto& d = const_cast<DriftData&>(drift_data());
  if (d.track.columns.empty()) {
    const Outcome tr =
        run_cli("track --no-progress --config " + kDriftConfig + " --data " + d.record_csv + " --out " + d.track_csv);
    EXPECT_EQ(tr.code, 0) << tr.output;
    d.track = read_table(d.track_csv);
  }
  return d;
}

inline void remove_drift_data() {
  std::filesystem::remove_all(std::filesystem::temp_directory_path() /
                              ("modalwatch_daemon_data_" + std::to_string(::getpid())));
}

// Batches [begin, end) of the record in packets of `batch` samples;
// utime = kUtime0 + utime_shift + t * 1e6, seq = index + seq_shift.
inline void publish_range(lcm_t* lcm, const std::string& channel, const Record& rec, Eigen::Index begin,
                          Eigen::Index end, int batch, std::int64_t utime_shift = 0, std::int64_t seq_shift = 0,
                          const std::function<void(Eigen::Index)>& after_each = {}) {
  for (Eigen::Index k = begin; k < end; k += batch) {
    const Eigen::Index n = std::min<Eigen::Index>(batch, end - k);
    const std::vector<std::uint8_t> bytes = encode_batch(rec, k, n, kUtime0 + utime_shift, seq_shift);
    lcm_publish(lcm, channel.c_str(), bytes.data(), static_cast<unsigned>(bytes.size()));
    if (after_each) after_each(k + n);
  }
}

// The daemon's output messages, decoded.
struct Received {
  std::mutex mutex;
  std::vector<modalwatch::estimates_t> estimates;
  std::vector<modalwatch::fault_status_t> status;
  std::vector<modalwatch::heartbeat_t> heartbeats;
  // When each estimates message arrived here: the daemon's progress in wall time.
  std::vector<std::chrono::steady_clock::time_point> estimate_arrivals;

  void subscribe(lcm_t* lcm, const LcmSettings& s) {
    // LCM keeps 30 messages per subscription by default and drops the rest
    // silently: a test thread stalled by a loaded machine would lose some.
    for (lcm_subscription_t* sub :
         {lcm_subscribe(lcm, s.estimates_channel.c_str(), &on<modalwatch::estimates_t, &Received::estimates>, this),
          lcm_subscribe(lcm, s.fault_status_channel.c_str(), &on<modalwatch::fault_status_t, &Received::status>, this),
          lcm_subscribe(lcm, s.heartbeat_channel.c_str(), &on<modalwatch::heartbeat_t, &Received::heartbeats>, this)})
      if (sub) lcm_subscription_set_queue_capacity(sub, 100000);
  }
  template <class T, std::vector<T> Received::*list>
  static void on(const lcm_recv_buf_t* rbuf, const char*, void* user) {
    auto* self = static_cast<Received*>(user);
    T msg;
    if (msg.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) < 0) {
      ADD_FAILURE() << "undecodable daemon message";
      return;
    }
    std::lock_guard<std::mutex> lock(self->mutex);
    (self->*list).push_back(std::move(msg));
    if constexpr (std::is_same_v<T, modalwatch::estimates_t>) self->estimate_arrivals.push_back(std::chrono::steady_clock::now());
  }
  std::size_t count_estimates() {
    std::lock_guard<std::mutex> lock(mutex);
    return estimates.size();
  }
  std::int64_t last_estimate_utime() {
    std::lock_guard<std::mutex> lock(mutex);
    return estimates.empty() ? 0 : estimates.back().utime;
  }
  std::size_t count_status() {
    std::lock_guard<std::mutex> lock(mutex);
    return status.size();
  }
  std::size_t count_heartbeats() {
    std::lock_guard<std::mutex> lock(mutex);
    return heartbeats.size();
  }
};

// Quantity q (0 wn, 1 zeta, 2 gain) of a mode's fault status.
inline const modalwatch::quantity_status_t& quantity(const modalwatch::mode_status_t& m, int q) {
  return q == 0 ? m.wn : q == 1 ? m.zeta : m.gain;
}

// Entry e = 3 mode + quantity of a fault status.
inline const modalwatch::quantity_status_t& entry(const modalwatch::fault_status_t& s, int e) {
  return quantity(s.modes[static_cast<std::size_t>(e / 3)], e % 3);
}

// Waits until pred() or the timeout; returns pred().
inline bool wait_for(const std::function<bool()>& pred, double timeout_s) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (!pred()) {
    if (std::chrono::steady_clock::now() > end) return pred();
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

constexpr int kSuspension = 0, kFlex = 1;
constexpr double kFs = 4096.0;

inline Eigen::Index samples_at(double t) { return static_cast<Eigen::Index>(std::llround(t * kFs)); }

// Publishes [begin, end) and keeps at most `backlog` samples ahead of the
// daemon; `published` counts the samples sent so far (memq queues without bound,
// so the daemon's received counter lags what was sent).
inline void publish_paced(lcm_t* lcm, const Config& c, Daemon& d, const Record& rec, Eigen::Index begin,
                          Eigen::Index end, std::uint64_t& published, std::int64_t utime_shift = 0,
                          std::int64_t seq_shift = 0, std::uint64_t backlog = 2048) {
  Eigen::Index done = begin;
  // Input that arrives during the warm-up fit is held up to daemon.warmup_backlog:
  // never more ahead than that less one batch, or a low sample rate's small
  // backlog overflows.
  const double held_at_most = std::floor(c.daemon.warmup_backlog / c.sample_time);
  backlog = std::min<std::uint64_t>(backlog, static_cast<std::uint64_t>(std::max(64.0, held_at_most - 64.0)));
  publish_range(lcm, c.lcm.batches_channel, rec, begin, end, 64, utime_shift, seq_shift, [&](Eigen::Index next) {
    published += static_cast<std::uint64_t>(next - done);
    done = next;
    wait_for(
        [&] {
          const DaemonCounters k = d.counters();
          const std::uint64_t handled = k.samples_processed + k.samples_dropped + k.samples_nonfinite +
                                        k.samples_duplicate + k.samples_out_of_order;
          return published < handled + backlog;
        },
        // The daemon holds input while a warm-up fit or a refit runs on its
        // fitter thread: under a sanitizer such a fit takes tens of seconds,
        // and sending on after a shorter wait overflows the backlog.
        120.0);
  });
}

// The same for the drift record.
inline void publish_paced(lcm_t* lcm, const Config& c, Daemon& d, Eigen::Index begin, Eigen::Index end,
                          std::uint64_t& published, std::int64_t utime_shift = 0, std::int64_t seq_shift = 0,
                          std::uint64_t backlog = 2048) {
  publish_paced(lcm, c, d, drift_data().record, begin, end, published, utime_shift, seq_shift, backlog);
}

inline bool all_handled(Daemon& d);
inline void dispatch_rest(lcm_t* lcm);

// The Daemon in process on its own memq:// instance over the whole record,
// paced by its counters, until it has handled every sample (within
// `timeout_s`); returns its counters after stop(). `rx` collects what it
// published.
inline DaemonCounters run_in_process(const Config& c, const Record& rec, Received& rx, double timeout_s = 30.0) {
  lcm_t* lcm = lcm_create("memq://");
  EXPECT_NE(lcm, nullptr);
  if (!lcm) return {};
  rx.subscribe(lcm, c.lcm);
  DaemonCounters k;
  {
    Daemon d(c, lcm);
    d.start();
    std::uint64_t published = 0;
    publish_paced(lcm, c, d, rec, 0, rec.size(), published);
    EXPECT_TRUE(wait_for([&] { return all_handled(d) && d.counters().samples_received == published; }, timeout_s));
    d.stop();
    k = d.counters();
  }
  dispatch_rest(lcm);
  lcm_destroy(lcm);
  return k;
}

inline bool all_handled(Daemon& d) {
  const DaemonCounters k = d.counters();
  return k.samples_received ==
         k.samples_processed + k.samples_dropped + k.samples_nonfinite + k.samples_duplicate + k.samples_out_of_order;
}

inline void dispatch_rest(lcm_t* lcm) {
  while (lcm_handle_timeout(lcm, 50) > 0) {
  }
}

// `rec` as a CSV with the sample times the daemon sees after publish_paced:
// utime has 1 us resolution and a batch of 64 carries its first sample's utime
// with the period added per sample, so the daemon's t differs from the record's
// by up to 0.5 us (and so would its estimates and flags, slightly). `track` on
// this CSV sees exactly the daemon's times. t starts at 0. With several
// inputs, `inputs` names their columns (the model's inputs).
inline void write_wire_times_csv(const Record& rec, const std::string& path,
                                 const std::vector<std::string>& inputs = {"u"}) {
  FILE* f = std::fopen(path.c_str(), "w");
  ASSERT_NE(f, nullptr) << path;
  ASSERT_EQ(static_cast<int>(inputs.size()), rec.inputs());
  std::fprintf(f, "t");
  for (const std::string& name : inputs) std::fprintf(f, ",%s", name.c_str());
  std::fprintf(f, rec.has_reference() ? ",y,r\n" : ",y\n");
  const std::int64_t first = std::llround(rec.t(0) * 1e6);
  for (Eigen::Index k = 0; k < rec.size(); ++k) {
    const Eigen::Index b = k / 64 * 64;  // publish_paced's batches
    const std::int64_t utime =
        std::llround(rec.t(b) * 1e6) + std::llround(static_cast<double>(k - b) * rec.sample_time() * 1e6);
    const double t = static_cast<double>(utime - first) * 1e-6;
    std::fprintf(f, "%.17g", t);
    for (int j = 0; j < rec.inputs(); ++j) std::fprintf(f, ",%.17g", rec.input(j)(k));
    if (rec.has_reference())
      std::fprintf(f, ",%.17g,%.17g\n", rec.y(k), rec.r(k));
    else
      std::fprintf(f, ",%.17g\n", rec.y(k));
  }
  std::fclose(f);
}

// A two-input open-loop structure at 200 Hz: a 5 Hz mode both shakers drive
// (residues of opposite sign) and a 12 Hz mode only the second does; u1 a
// PRBS, u2 independent white noise, 30 dB output noise, 60 s. Its config
// (written to `config_path`) starts every mode 5 % off, with a 5 s memory
// (lambda 0.999), a 10 s warm-up fitted from both inputs and an estimate
// every 0.1 s.
struct TwoInputPlant {
  struct Mode {
    std::string name;
    int input;
    ModalParameters truth;
  };
  std::vector<Mode> modes;
  std::string config_path;
  Config config;
  Record record;
};

inline TwoInputPlant two_input_plant(const std::string& config_path) {
  TwoInputPlant out;
  const double two_pi = 2.0 * 3.14159265358979323846;
  out.modes = {{"pitch_u1", 0, {two_pi * 5.0, 0.04, 1.0}},
               {"pitch_u2", 1, {two_pi * 5.0, 0.04, -0.4}},
               {"roll_u2", 1, {two_pi * 12.0, 0.02, 0.5}}};
  std::ostringstream yaml;
  yaml.precision(17);
  yaml << "sample_rate_hz: 200\nmodel:\n  inputs: [u1, u2]\n  submodels:\n";
  for (const auto& m : out.modes)
    yaml << "    - name: " << m.name << "\n      input: u" << m.input + 1 << "\n      wn: " << 1.05 * m.truth.wn
         << "\n      zeta: " << 0.95 * m.truth.zeta << "\n      gain: " << 1.05 * m.truth.gain
         << "\n      forgetting: 0.999\n";
  yaml << "estimator:\n  warmup: 10\ndaemon:\n  publish_period: 0.1\n";
  {
    std::ofstream f(config_path);
    f << yaml.str();
  }
  out.config_path = config_path;
  out.config = load_config(config_path);

  PlantSpec plant;
  for (const auto& m : out.modes) {
    PlantMode pm;
    pm.modal = m.truth;
    pm.submodel = make_mode(m.name, m.truth);
    pm.submodel.input = m.input;
    plant.modes.push_back(pm);
  }
  plant.snr_db = 30.0;
  ExperimentSpec e;
  e.sample_time = out.config.sample_time;
  e.duration = 60.0;
  e.seed = 4;
  e.excitation.kind = SignalSpec::Kind::prbs;
  e.excitation.register_bits = 12;
  e.excitation.clock_period = 1;
  e.excitation.amplitude = 1.0;
  const auto n = static_cast<Eigen::Index>(std::llround(e.duration / e.sample_time));
  e.further_input_samples = {modalwatch::test_support::white_noise(n, 44)};
  out.record = simulate(plant, e).record;
  return out;
}

// The daemon's flag changes read off its fault status messages, as
// "us since the first sample,mode,quantity,event": a flag's RAISED state turning
// on (at its `since`) or off (at the message's utime). `first_us` is the
// record's first t in us (the wire's utime is kUtime0 + t).
inline std::vector<std::string> daemon_flag_changes(const std::vector<modalwatch::fault_status_t>& status,
                                                    std::int64_t first_us) {
  const char* kQuantity[3] = {"wn", "zeta", "gain"};
  std::vector<std::string> changes;
  std::vector<bool> up;
  for (const auto& s : status) {
    up.resize(static_cast<std::size_t>(3 * s.n_modes), false);
    for (int e = 0; e < 3 * s.n_modes; ++e) {
      const modalwatch::mode_status_t& m = s.modes[static_cast<std::size_t>(e / 3)];
      const bool now = quantity(m, e % 3).state == "raised";
      if (now == up[static_cast<std::size_t>(e)]) continue;
      up[static_cast<std::size_t>(e)] = now;
      const std::int64_t at = (now ? quantity(m, e % 3).since : s.utime) - kUtime0 - first_us;
      changes.push_back(std::to_string(at) + "," + m.name + "," + kQuantity[e % 3] + "," +
                        (now ? "raised" : "cleared"));
    }
  }
  return changes;
}

// `track --faults`'s flag changes (its CSV) in the same form.
inline std::vector<std::string> track_flag_changes(const std::string& flags_csv) {
  std::vector<std::string> changes;
  std::ifstream in(flags_csv);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "t,mode,quantity,event,value,baseline,relative,sigma") << flags_csv;
  while (std::getline(in, line)) {
    std::stringstream row(line);
    std::string t, mode, quantity_name, event;
    std::getline(row, t, ',');
    std::getline(row, mode, ',');
    std::getline(row, quantity_name, ',');
    std::getline(row, event, ',');
    changes.push_back(std::to_string(std::llround(std::stod(t) * 1e6)) + "," + mode + "," + quantity_name + "," +
                      event);
  }
  return changes;
}

}  // namespace modalwatch::test_support
