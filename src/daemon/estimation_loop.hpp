#pragma once
// The estimation loop: a thread on a fixed tick grid (daemon.loop_rate_hz,
// absolute-time sleep) that drains the input ring through the input policy into
// RecursiveEstimator::step, runs the fault detector once per publish period of
// sample time and pushes a Snapshot for the publisher. After start-up it
// neither allocates, locks nor makes a system call, apart from its sleep and,
// under systemd with WatchdogSec, sd_notify(WATCHDOG=1).
//
// Input policy:
// - Time. The estimator, the fault detector and the publish period run on
//   sample time, t = (utime - utime0) * 1e-6 with utime0 the first sample's,
//   so the daemon gives the estimates `modalwatch track` gives on the same
//   record and replay faster than real time is just faster. Stale input and
//   the idle fault status run on the wall clock (CLOCK_MONOTONIC).
// - Sequence numbers. A seq at or below the last accepted one is a duplicate
//   (equal) or out of order (below) and is dropped, unless the sender has
//   restarted (a new replay, a controller reboot): its seq went back and
//   either its utime is more than one gap past the last sample (taken at once),
//   or its utime went back too and the samples after it go on from there
//   (in seq and utime) for kRestartConfirm seconds of sample time and at least
//   kRestartConfirmSamples samples (those are dropped, counted out of order;
//   reordered packets never go on that long). A restart is counted and
//   logged; the loop then maps the sender's utime onto its own clock
//   (utime_offset_), so that sample time goes on past a gap: the prefilter
//   states reset as after any gap, the parameters, baselines and a restored
//   checkpoint stay.
// - NaN/Inf in u (any input), y or r: counted, and passed to the estimator,
//   which keeps the sample's time slot without updating.
// - Gaps. The estimator detects them itself (estimator.gap_factor, which
//   daemon.gap_time sets), so track and the daemon apply one rule.
// - The warm-up fit runs on the WarmupFitter. Meanwhile the loop keeps ticking
//   (watchdog, fault status from the status cached before the fit) and moves
//   the input into a backlog preallocated for daemon.warmup_backlog seconds
//   (overflow: counted as dropped). Once the fit is applied the loop works the
//   backlog off within half of each tick, then continues live. The estimates
//   equal those of `modalwatch track`, which runs the same fit inline.
//
// The thread is started and stopped by the control side; a stop is either a
// pause (checkpoint, reload: the state stays for the next start) or final.
#include <atomic>
#include <cstdint>
#include <optional>
#include <thread>
#include <vector>

#include "counters.hpp"
#include "doorbell.hpp"
#include "modalwatch/estimator.hpp"
#include "modalwatch/fault_detector.hpp"
#include "modalwatch/io/checkpoint.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/io/messages.hpp"
#include "snapshot.hpp"
#include "spsc_ring.hpp"
#include "warmup_fitter.hpp"

namespace modalwatch {
class LoopProbe;
}

namespace modalwatch::daemon_detail {

class EstimationLoop {
 public:
  // `config` is the daemon's; the control side rewrites it only while the loop
  // is stopped. Resumes from `checkpoint` when the estimator accepts it.
  EstimationLoop(const Config& config, const std::optional<Checkpoint>& checkpoint, SpscRing<StampedSample>& input,
                 SpscRing<Snapshot>& output, Doorbell& output_bell, Counters& counters, std::int64_t start_ns);
  ~EstimationLoop();
  EstimationLoop(const EstimationLoop&) = delete;
  EstimationLoop& operator=(const EstimationLoop&) = delete;

  void set_probe(LoopProbe* probe);
  void set_watchdog_usec(std::uint64_t usec) { watchdog_usec_ = usec; }

  // The fitter lives from start-up to the final stop; only while warming up.
  void start_fitter();
  void stop_fitter() { fitter_.stop(); }

  void start();
  // A pause drains the input ring and pushes a final snapshot. A final stop
  // also waits for a running warm-up fit (ticking as usual) and works the
  // backlog off in full.
  void stop(bool final_stop);

  // While stopped: the state to resume from (none during the warm-up), and a
  // new fault detector for the rewritten config that keeps learned and
  // restored baselines (unless the config now sets one) and logs at warning
  // level what it does not carry over (flags, learning in progress). When the
  // faults: section did not change, the detector stays as it is.
  std::optional<Checkpoint> capture(std::uint64_t fingerprint) const;
  void reconfigure_detector();

  bool restored() const { return restored_; }
  bool warming_up() const { return warming_up_.load(std::memory_order_relaxed); }
  const std::atomic<bool>& warming_up_flag() const { return warming_up_; }
  std::size_t backlog_capacity() const { return backlog_.size(); }

 private:
  enum StopRequest : int { keep_running = 0, pause_requested = 1, stop_requested = 2 };
  void run() noexcept;
  void drain(std::int64_t now) noexcept;
  void process(const StampedSample& s) noexcept;
  bool restart_confirmed(const StampedSample& s) noexcept;
  void note_restart(const StampedSample& s) noexcept;
  void enqueue_held(const StampedSample& s) noexcept;
  void work_off_backlog(std::int64_t deadline_ns) noexcept;
  void push_snapshot(Snapshot::Kind kind, std::int64_t now, bool update_detector) noexcept;
  void set_detector(const std::vector<std::optional<ModeBaseline>>& kept);

  // Wiring.
  const Config& config_;
  SpscRing<StampedSample>& input_;
  SpscRing<Snapshot>& output_;
  Doorbell& output_bell_;
  LoopCounters& counters_;
  const Counters& all_counters_;  // copied into each snapshot
  const std::int64_t start_ns_;
  LoopProbe* probe_ = nullptr;
  std::uint64_t watchdog_usec_ = 0;
  std::thread thread_;
  std::atomic<int> stop_{keep_running};

  // Set by start() from the config.
  std::int64_t tick_origin_ns_ = 0, tick_period_ns_ = 0;
  std::int64_t publish_period_us_ = 0, gap_us_ = 0;

  // The estimator and the fault detector, and the detector's inputs (sized at
  // construction, so that update() does not allocate).
  RecursiveEstimator estimator_;
  bool restored_ = false;
  std::optional<FaultDetector> detector_;
  std::vector<bool> baseline_configured_;  // per mode: the baseline is the config's
  FaultSettings detector_faults_;          // the config's faults: section the detector was made for
  DetectorInput detector_input_;
  std::vector<FlagChange> flag_changes_;
  TickHistogram tick_histogram_;  // durations of the loop's ticks, for the metrics endpoint

  // Input policy and timing.
  bool have_seq_ = false;
  std::int64_t last_seq_ = -1;
  // utime_ below is the sender's utime + utime_offset_ (changed by a restart).
  std::int64_t utime_offset_ = 0;
  bool restart_since_snapshot_ = false;
  // A run of samples behind the last accepted one: a restart when it goes on.
  int restart_run_ = 0;
  std::int64_t restart_run_seq_ = 0, restart_run_utime_ = 0, restart_run_first_utime_ = 0;
  bool have_time_ = false;      // utime0_ set (a sample since start)
  bool have_ref_time_ = false;  // last_utime_ is meaningful (a sample, or a restored checkpoint)
  std::int64_t utime0_ = 0, last_utime_ = 0;
  std::int64_t next_publish_utime_ = 0;
  Sample sample_;  // the estimator's input, filled in place (its further inputs: the model's)
  std::int64_t last_sample_ns_ = 0, last_snapshot_ns_ = 0, last_watchdog_ns_ = 0;

  // Events for the next snapshot.
  bool gap_since_snapshot_ = false, reset_since_snapshot_ = false;
  std::uint64_t dropped_at_snapshot_ = 0, decode_errors_at_snapshot_ = 0, overruns_at_snapshot_ = 0,
                lost_at_snapshot_ = 0;
  Snapshot next_snapshot_;  // built in place, copied into the ring
  std::atomic<bool> warming_up_{true};
  bool probe_fired_ = false;

  // The warm-up fit. While it runs, the loop reports status_before_fit_ and
  // holds the input in backlog_, a FIFO preallocated at construction.
  WarmupFitter fitter_;
  bool fit_in_flight_ = false;
  EstimatorStatus status_before_fit_;
  std::vector<StampedSample> backlog_;
  std::size_t backlog_head_ = 0, backlog_size_ = 0;
};

}  // namespace modalwatch::daemon_detail
