#pragma once
// modalwatchd's engine: three threads joined by two lock-free single-producer
// single-consumer rings, so that the thread on the latency path never waits.
//
//   LCM subscriber ──StampedSample──► ring ──► estimation loop ──Snapshot──► ring ──► publisher
//   (lcm_handle, decode;                      (fixed tick, input policy,              (estimates_t,
//    a full ring drops)                        RecursiveEstimator::step,               fault_status_t,
//                                              FaultDetector per publish period)       heartbeat_t, logs)
//
// The estimation loop neither locks, allocates nor makes a system call after
// start-up, apart from its absolute-time sleep (clock_nanosleep on
// CLOCK_MONOTONIC) and, under systemd with WatchdogSec, sd_notify(WATCHDOG=1).
// Everything it reports goes through a fixed-size snapshot; the publisher,
// woken by a doorbell the loop rings after each snapshot, turns it into
// messages and log lines.
//
// Two helper threads keep slow work off the loop. The checkpointer writes the
// periodic checkpoint: it pauses the loop (the input ring buffers meanwhile),
// copies the state, restarts the loop and writes the file; reload() pauses the
// loop the same way. The fitter runs the estimator's warm-up fit (seconds,
// allocating) while the loop keeps its tick, the watchdog and the fault status,
// and holds the input in a backlog (daemon.warmup_backlog) that it works off
// afterwards.
//
// The estimator, the fault detector and the publish period run on sample time
// (the samples' utime), so the daemon's estimates equal those of `modalwatch
// track` on the same record; stale input, the heartbeat and checkpoints run on
// the wall clock.
//
// Usage (modalwatchd's main does this; tests drive the same class in process):
//   Daemon d(config);             // opens LCM (or uses the caller's lcm_t), restores a checkpoint
//   d.start();
//   ... d.reload(new_config) on SIGHUP ...
//   d.stop();                     // drains both rings, joins the threads
//   d.write_checkpoint();         // final state (no-op without daemon.checkpoint)
#include <cstdint>
#include <memory>
#include <string>

#include "modalwatch/io/config.hpp"

extern "C" {
typedef struct _lcm_t lcm_t;
}

namespace modalwatch {

// Counters since start (each monotonic). Safe to read from any thread.
struct DaemonCounters {
  std::uint64_t samples_received = 0;      // samples decoded from valid packets
  std::uint64_t samples_dropped = 0;       // input ring full, or the warm-up backlog (held_dropped)
  std::uint64_t samples_lost = 0;          // sequence numbers that never arrived (lost in transport)
  std::uint64_t decode_errors = 0;         // packets rejected by the decoder
  std::uint64_t samples_nonfinite = 0;     // NaN/Inf in u, y or r
  std::uint64_t samples_duplicate = 0;     // seq equal to the last accepted one
  std::uint64_t samples_out_of_order = 0;  // seq below the last accepted one (or a restart being confirmed)
  std::uint64_t sender_restarts = 0;       // the sender started its seq and utime again
  std::uint64_t samples_processed = 0;     // passed to the estimator
  std::uint64_t gaps = 0;                  // utime gaps that reset the prefilter states
  std::uint64_t resets = 0;                // estimator returns to its last good state
  std::uint64_t change_boosts = 0;         // covariance boosts after a change of the output error
  std::uint64_t mode_restores = 0;         // updates that returned a mode to its last good estimate (its gain changed sign)
  std::uint64_t overruns = 0;              // loop ticks that ended after the next was due
  std::uint64_t samples_held = 0;          // held in the backlog while the warm-up fit ran
  std::uint64_t held_dropped = 0;          // backlog full (daemon.warmup_backlog), also in samples_dropped
  std::uint64_t snapshots = 0;             // snapshots handed to the publisher
  std::uint64_t snapshots_dropped = 0;     // snapshot ring full (publisher behind)
  std::uint64_t estimates_published = 0;
  std::uint64_t fault_status_published = 0;
  std::uint64_t heartbeats_published = 0;
  std::uint64_t flag_changes = 0;
  std::uint64_t checkpoints_written = 0;
  std::uint64_t checkpoint_failures = 0;
};

class Daemon {
 public:
  // Opens config.lcm.url, or uses `lcm` (not owned; it must outlive the Daemon
  // and nobody else may call lcm_handle on it) so an in-process test can share
  // one memq:// instance. Restores daemon.checkpoint when it exists and matches
  // the config. Throws InputError for an LCM URL that cannot be opened, a
  // model the daemon cannot carry (more than kMaxModes submodels) or a
  // checkpoint path whose directory does not exist.
  explicit Daemon(const Config& config, lcm_t* lcm = nullptr);
  ~Daemon();  // stop()s
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  static constexpr int kMaxModes = 16;

  void start();
  // Stops taking input, lets the estimation loop drain the input ring and the
  // publisher drain the snapshot ring, joins the threads. Idempotent.
  void stop();

  // SIGHUP: applies `next` (already validated by load_config) where it can.
  // Applied: daemon rates, stale time, checkpoint path and period, log level,
  // fault thresholds, learn window and configured baselines. Learned and
  // restored baselines are kept, also when the file changes something that
  // needs a restart, unless the file now configures that mode's baseline; what
  // the reload discards (flags up or pending, learning in progress, a baseline
  // removed from the file) is logged at warning level. Not applied (logged; a
  // restart applies them): LCM URL and channels, ring sizes, and the
  // model/estimator; when the model or estimator differ the running estimator
  // continues unchanged. Returns a one-line summary. Throws InputError (the
  // running configuration stays) when the new checkpoint directory does not
  // exist. Call from the control thread only, after start().
  std::string reload(const Config& next);

  // Writes daemon.checkpoint from the final state; call after stop() only
  // (while running, the checkpointer thread writes the periodic ones; throws
  // std::logic_error otherwise). Skipped (true) during the warm-up and without
  // a checkpoint path; false (and an error log) on failure, e.g. a full disk.
  bool write_checkpoint();

  DaemonCounters counters() const;
  bool restored_from_checkpoint() const;  // this instance resumed from a checkpoint
  bool warming_up() const;                // the estimator is still in its warm-up window
  const Config& config() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  friend struct DaemonAccess;  // test hooks, outside the public API
};

}  // namespace modalwatch
