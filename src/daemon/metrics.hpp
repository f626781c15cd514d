#pragma once
// modalwatchd's Prometheus endpoint (daemon.metrics.listen): the publisher
// thread turns each snapshot into a MetricsSnapshot and hands it to
// MetricsEndpoint::update(); Prometheus scrapes GET /metrics on an HTTP server
// of prometheus-cpp's own (civetweb threads). Nothing here runs on the
// estimation loop: the loop only counts its tick durations into a
// TickHistogram, a fixed-size value it copies into its snapshot.
//
// Every series carries the label axis (the config's `axis:`); per-mode series
// add mode (the submodel's name), per-quantity series add quantity (wn, zeta,
// gain). Names follow Prometheus's conventions: base units in the name, _total
// for counters, enums as numbers documented in the help text.
#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "modalwatch/daemon/daemon.hpp"
#include "modalwatch/fault_detector.hpp"
#include "modalwatch/model.hpp"

namespace modalwatch {

struct MetricsSettings {
  std::string listen;  // "127.0.0.1:9464" (host:port, port 0: any free one); empty: no endpoint
};

// Upper bounds (le) of the loop tick duration histogram, in ns: the loop ticks
// every 0.5..1 ms, so the buckets resolve the work inside a tick and the
// overruns past it. A tick longer than the last bound counts in +Inf.
inline constexpr std::array<std::int64_t, 13> kTickBucketBoundsNs = {
    5'000,     10'000,    25'000,    50'000,     100'000,    250'000,    500'000,
    1'000'000, 2'500'000, 5'000'000, 10'000'000, 25'000'000, 100'000'000};

// Tick durations since start, counted by the estimation loop: record() is a
// bounded search and two additions, with no allocation, lock or system call.
// buckets[i] counts the ticks with kTickBucketBoundsNs[i-1] < duration <=
// kTickBucketBoundsNs[i] (not cumulative over buckets; the endpoint sums them
// into Prometheus's le buckets), the last one those above every bound.
struct TickHistogram {
  std::array<std::uint64_t, kTickBucketBoundsNs.size() + 1> buckets{};
  std::uint64_t sum_ns = 0;

  void record(std::int64_t duration_ns) noexcept {
    std::size_t i = 0;
    while (i < kTickBucketBoundsNs.size() && duration_ns > kTickBucketBoundsNs[i]) ++i;
    ++buckets[i];
    sum_ns += static_cast<std::uint64_t>(duration_ns > 0 ? duration_ns : 0);
  }
  std::uint64_t count() const noexcept {
    std::uint64_t n = 0;
    for (const std::uint64_t b : buckets) n += b;
    return n;
  }
};

struct ModeMetrics {
  ModalParameters value, std_dev;  // the estimate, wn in rad/s (the endpoint derives the Hz series)
  // The fault detector's view: baseline (learned or configured), and per
  // quantity the deviations and the flag, exported as 0 none, 1 pending, 2 raised.
  ModeStatus status;
};

// What one update() exports: a plain, trivially copyable value, modes in config
// order (the first n_modes entries are used). Counters are totals since the
// daemon started; the endpoint advances its Prometheus counters by the
// difference to the previous snapshot.
struct MetricsSnapshot {
  int n_modes = 0;
  std::array<ModeMetrics, Daemon::kMaxModes> modes{};
  bool warming_up = true;       // the estimator's warm-up window (state 0)
  bool low_excitation = false;  // flags suppressed for lack of excitation
  bool misfit = false;          // flags suppressed while the model does not fit (EstimatorStatus::misfit)
  bool stale = false;           // no input for longer than daemon.stale_time
  DaemonCounters counters;
  TickHistogram tick;
};

// The endpoint: registry, metric families and HTTP server, built once. Call
// update() from one thread (the publisher); scrapes are served concurrently
// from the server's threads, each metric read atomically.
class MetricsEndpoint {
 public:
  // Binds settings.listen. Throws InputError naming `daemon.metrics.listen`
  // for an address that is empty, malformed or cannot be bound (in use, not a
  // local address). mode_names: the submodels' names, in config order.
  MetricsEndpoint(const MetricsSettings& settings, std::string axis, std::vector<std::string> mode_names);
  ~MetricsEndpoint();
  MetricsEndpoint(const MetricsEndpoint&) = delete;
  MetricsEndpoint& operator=(const MetricsEndpoint&) = delete;

  // Sets the gauges and advances the counters and the histogram. A total below
  // the previous one (the source restarted) is taken as the new base, without
  // an increment: Prometheus counters only go up.
  void update(const MetricsSnapshot& snapshot);

  // The bound TCP port (the actual one when settings.listen asked for port 0).
  int port() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace modalwatch
