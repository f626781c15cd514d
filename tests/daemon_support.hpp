#pragma once
// Helpers for the daemon's end-to-end tests: a simulated drifting record (made
// once per test binary with the real `modalwatch simulate` and `track`), LCM
// publishing of that record, and collection of the daemon's messages.
#include <lcm/lcm.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include <modalwatch/estimates_t.hpp>
#include <modalwatch/fault_status_t.hpp>
#include <modalwatch/heartbeat_t.hpp>

#include "support.hpp"

#include "modalwatch/daemon/daemon.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/io/csv.hpp"
#include "modalwatch/io/messages.hpp"
#include "modalwatch/io/records.hpp"

namespace modalwatch::test_support {

// config/flexible-beam-drift.yaml: 4096 Hz, modes "suspension" and "flex"; flex
// loses 15 % stiffness over t in [30, 32] s.
inline const std::string kDriftConfig = std::string(MODALWATCH_SOURCE_DIR) + "/config/flexible-beam-drift.yaml";
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

  void subscribe(lcm_t* lcm, const LcmSettings& s) {
    lcm_subscribe(lcm, s.estimates_channel.c_str(), &on<modalwatch::estimates_t, &Received::estimates>, this);
    lcm_subscribe(lcm, s.fault_status_channel.c_str(), &on<modalwatch::fault_status_t, &Received::status>, this);
    lcm_subscribe(lcm, s.heartbeat_channel.c_str(), &on<modalwatch::heartbeat_t, &Received::heartbeats>, this);
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
  }
  std::size_t count_estimates() {
    std::lock_guard<std::mutex> lock(mutex);
    return estimates.size();
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
inline void publish_paced(lcm_t* lcm, const Config& c, Daemon& d, Eigen::Index begin, Eigen::Index end,
                          std::uint64_t& published, std::int64_t utime_shift = 0, std::int64_t seq_shift = 0,
                          std::uint64_t backlog = 2048) {
  const Record& rec = drift_data().record;
  Eigen::Index done = begin;
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
        10.0);
  });
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

}  // namespace modalwatch::test_support
