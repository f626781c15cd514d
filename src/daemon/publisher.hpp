#pragma once
// The output side: a thread that sleeps on the doorbell the estimation loop
// rings after each snapshot, turns snapshots into estimates_t and
// fault_status_t messages and log lines, and sends heartbeat_t on the wall
// clock. It alone maps the estimator's and the fault detector's state to the
// fault_status_t flag and health bits. It may allocate and block: nothing on
// the latency path waits for it (a full snapshot ring drops snapshots).
#include <array>
#include <atomic>
#include <cstdint>
#include <optional>
#include <thread>
#include <vector>

#include <lcm/lcm.h>

#include "counters.hpp"
#include "doorbell.hpp"
#include "metrics.hpp"
#include "modalwatch/io/config.hpp"
#include "snapshot.hpp"
#include "spsc_ring.hpp"

namespace modalwatch::daemon_detail {

// The daemon's state as the heartbeat reports it.
enum class RunState : int { starting, running, reloading, stopping };

class Publisher {
 public:
  struct Wiring {
    lcm_t* lcm;
    SpscRing<Snapshot>& input;
    Doorbell& input_bell;
    Counters& counters;
    const std::atomic<int>& run_state;    // RunState
    const std::atomic<bool>& warming_up;  // the estimator's, for the heartbeat
    std::int64_t start_ns;                // for the heartbeat's uptime
  };
  // `config` is the daemon's; the control side rewrites it only while this
  // thread is stopped. `restored`: the estimator resumed from a checkpoint.
  Publisher(const Config& config, const Wiring& wiring, bool restored);
  ~Publisher() { stop(); }
  Publisher(const Publisher&) = delete;
  Publisher& operator=(const Publisher&) = delete;

  void start();
  void stop();  // publishes what is left in the ring, then joins

 private:
  void run();
  void handle(const Snapshot& s);
  void publish_estimates(const Snapshot& s);
  void publish_fault_status(const Snapshot& s);
  void publish_heartbeat(std::int64_t now);
  void export_metrics(const Snapshot& s);
  bool send(const std::string& channel, const auto& message);
  void log_snapshot(const Snapshot& s);
  void log_rates(std::int64_t now);
  void log_repeated(const DaemonCounters& c, std::int64_t now);

  // An event that may repeat many times a second (gaps, losses): the first
  // goes out at once, the rest as one line per kWarningPeriod with a count.
  struct RepeatedWarning {
    std::uint64_t logged = 0;  // the counter's value the last line covered
    std::int64_t last_ns = 0, next_ns = 0;
  };
  template <class Line>
  void warn_repeated(RepeatedWarning& w, std::uint64_t total, std::int64_t now, Line&& line);

  const Config& config_;
  Wiring wiring_;
  PublisherCounters& counters_;
  const bool restored_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::vector<std::uint8_t> encoded_;
  std::optional<MetricsEndpoint> metrics_;  // daemon.metrics.listen; fed from the snapshots
  MetricsSnapshot metrics_snapshot_;
  std::int64_t next_heartbeat_ns_ = 0, next_rate_log_ns_ = 0;
  // What was logged already: each event is logged once, when it happens.
  DaemonCounters rate_base_;
  std::int64_t rate_base_ns_ = 0;
  bool logged_warmup_over_ = false, logged_stale_ = false;
  std::uint64_t received_when_stale_ = 0;
  RepeatedWarning gaps_, resets_, boosts_, restores_, lost_, dropped_;
  const char* last_reset_reason_ = "";
  std::uint64_t logged_held_dropped_ = 0;
  std::array<bool, kMaxModes> logged_baseline_{};
};

}  // namespace modalwatch::daemon_detail
