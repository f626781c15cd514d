// Daemon: wires the subscriber, the estimation loop (with its warm-up fitter),
// the publisher and the checkpointer, and serialises the control side
// (start, stop, reload, checkpoints) under one mutex.
#include "modalwatch/daemon/daemon.hpp"

#include <lcm/lcm.h>
#include <spdlog/spdlog.h>
#include <systemd/sd-daemon.h>

#include <atomic>
#include <mutex>
#include <stdexcept>
#include <vector>

#include "checkpointer.hpp"
#include "counters.hpp"
#include "doorbell.hpp"
#include "estimation_loop.hpp"
#include "loop_probe.hpp"
#include "modalwatch/error.hpp"
#include "modalwatch/io/checkpoint.hpp"
#include "publisher.hpp"
#include "realtime.hpp"
#include "snapshot.hpp"
#include "spsc_ring.hpp"
#include "subscriber.hpp"

namespace modalwatch {

using namespace daemon_detail;

namespace {

// Checks what the threads cannot report: the model's size and the real-time
// permissions, before the LCM instance exists.
const Config& checked(const Config& config) {
  const auto K = config.model.submodels.size();
  if (K > static_cast<std::size_t>(Daemon::kMaxModes))
    throw InputError(config.source, "model.submodels: the daemon carries at most " + std::to_string(Daemon::kMaxModes) +
                                        " submodels (this model has " + std::to_string(K) + ")");
  check_realtime(config.daemon.realtime_priority, config.source);
  check_checkpoint_directory(config);
  return config;
}

// The caller's lcm_t, or one opened for config.lcm.url (destroyed with the Daemon).
struct LcmCloser {
  bool owned = false;
  void operator()(lcm_t* lcm) const {
    if (owned) lcm_destroy(lcm);
  }
};
using LcmHandle = std::unique_ptr<lcm_t, LcmCloser>;

LcmHandle open_lcm(const Config& config, lcm_t* shared) {
  if (shared) return LcmHandle(shared, LcmCloser{false});
  lcm_t* lcm = lcm_create(config.lcm.url.c_str());
  if (!lcm)
    throw InputError(config.source, "key 'lcm.url': cannot open LCM provider '" + config.lcm.url +
                                        "' (a udpm:// URL needs a multicast route, e.g. "
                                        "'ip route add 224.0.0.0/4 dev lo')");
  return LcmHandle(lcm, LcmCloser{true});
}

// What reload() cannot apply to a running daemon, for its summary.
std::vector<std::string> needing_restart(const Config& now, const Config& next, bool same_fingerprint) {
  std::vector<std::string> kept;
  if (!same_fingerprint)
    kept.emplace_back("model structure/loop/controller/forgetting (the running estimator continues; restart to apply)");
  else if (!(next.model == now.model))
    kept.emplace_back("model initial values (the running estimator continues; restart to apply)");
  if (!(next.estimator == now.estimator)) kept.emplace_back("estimator settings");
  if (!(next.lcm == now.lcm)) kept.emplace_back("LCM URL/channels");
  if (next.daemon.sample_ring != now.daemon.sample_ring || next.daemon.snapshot_ring != now.daemon.snapshot_ring ||
      next.daemon.warmup_backlog != now.daemon.warmup_backlog)
    kept.emplace_back("ring sizes");
  if (next.daemon.realtime_priority != now.daemon.realtime_priority) kept.emplace_back("realtime priority");
  if (next.daemon.metrics_listen != now.daemon.metrics_listen || next.axis != now.axis)
    kept.emplace_back("metrics endpoint (address, axis)");
  return kept;
}

}  // namespace

struct Daemon::Impl {
  Impl(const Config& cfg, lcm_t* shared)
      : config(checked(cfg)),
        fingerprint(checkpoint_fingerprint(cfg)),
        start_ns(mono_ns()),
        samples(static_cast<std::size_t>(cfg.daemon.sample_ring)),
        snapshots(static_cast<std::size_t>(cfg.daemon.snapshot_ring)),
        loop(config, read_matching_checkpoint(config, fingerprint), samples, snapshots, snapshot_bell, counters,
             start_ns),
        lcm(open_lcm(config, shared)),
        subscriber(lcm.get(), config, samples, counters.subscriber),
        publisher(config,
                  Publisher::Wiring{lcm.get(), snapshots, snapshot_bell, counters, run_state, loop.warming_up_flag(),
                                    start_ns},
                  loop.restored()),
        checkpointer(
            config, control, [this] { return capture_paused(); }, counters.checkpoints) {}

  // Under `control`, while running: pause the loop, copy its state, resume.
  std::optional<Checkpoint> capture_paused() {
    if (!running) return std::nullopt;
    loop.stop(false);
    std::optional<Checkpoint> ck = loop.capture(fingerprint);
    loop.start();
    return ck;
  }

  Config config;  // rewritten by reload() while the loop and the publisher are stopped
  const std::uint64_t fingerprint;
  const std::int64_t start_ns;
  Counters counters;
  std::atomic<int> run_state{static_cast<int>(RunState::starting)};
  std::mutex control;    // serialises start(), stop(), reload() and the checkpointer's pauses
  bool running = false;  // under `control`
  std::uint64_t watchdog_usec = 0;
  SpscRing<StampedSample> samples;  // subscriber -> loop
  SpscRing<Snapshot> snapshots;     // loop -> publisher
  Doorbell snapshot_bell;           // rung by the loop after each push
  EstimationLoop loop;
  LcmHandle lcm;  // after the loop, whose construction may throw
  Subscriber subscriber;
  Publisher publisher;
  Checkpointer checkpointer;
};

void DaemonAccess::attach_loop_probe(Daemon& daemon, LoopProbe& probe) {
  std::lock_guard<std::mutex> lock(daemon.impl_->control);
  if (daemon.impl_->running) throw std::logic_error("attach_loop_probe: call before Daemon::start()");
  daemon.impl_->loop.set_probe(&probe);
}

Daemon::Daemon(const Config& config, lcm_t* lcm) : impl_(std::make_unique<Impl>(config, lcm)) {}

Daemon::~Daemon() { stop(); }

void Daemon::start() {
  Impl& m = *impl_;
  std::lock_guard<std::mutex> lock(m.control);
  if (m.running) return;
  if (sd_watchdog_enabled(0, &m.watchdog_usec) <= 0) m.watchdog_usec = 0;
  m.loop.set_watchdog_usec(m.watchdog_usec);
  const Config& c = m.config;
  std::string inputs;  // with several: their names, and the messages that carry them
  if (c.model.n_inputs() > 1) {
    inputs = ", inputs";
    for (const std::string& name : c.model.inputs) inputs += " " + name;
    inputs += " (sample2_t / sample_batch2_t)";
  }
  spdlog::info(
      "modalwatchd: {} ({}), {} submodels at {} Hz, {} loop{}, output hold {}{}; LCM {} in: {} / {}, out: {} / {} / "
      "{}; loop {} Hz, "
      "publish every {} s, heartbeat every {} s; rings {} samples / {} snapshots; checkpoint {}; {}{}",
      c.source, m.loop.restored() ? "resumed from checkpoint" : "fresh start", c.model.submodels.size(),
      1.0 / c.sample_time, c.closed_loop ? "closed" : "open", inputs, hold_name(c.estimator.output_hold),
      c.output_hold ? "" : " by default", c.lcm.url, c.lcm.samples_channel, c.lcm.batches_channel,
      c.lcm.estimates_channel, c.lcm.fault_status_channel, c.lcm.heartbeat_channel, c.daemon.loop_rate_hz,
      c.daemon.publish_period, c.daemon.heartbeat_period, c.daemon.sample_ring, c.daemon.snapshot_ring,
      c.daemon.checkpoint_path.empty()
          ? std::string("off")
          : c.daemon.checkpoint_path + " every " + std::to_string(c.daemon.checkpoint_period) + " s",
      m.loop.restored() ? "no warm-up"
                        : "warm-up " + std::to_string(c.estimator.warmup_samples) + " samples (fit off the loop, " +
                              std::to_string(m.loop.backlog_capacity()) + " samples held at most)",
      (m.watchdog_usec ? ", systemd watchdog " + std::to_string(m.watchdog_usec / 1000) + " ms" : std::string()) +
          (c.daemon.realtime_priority > 0 ? ", SCHED_FIFO " + std::to_string(c.daemon.realtime_priority) + " + mlockall"
                                          : std::string()));
  m.loop.start_fitter();
  m.publisher.start();
  m.loop.start();
  m.subscriber.start();
  m.running = true;
  m.checkpointer.start();
  m.run_state.store(static_cast<int>(RunState::running));
}

void Daemon::stop() {
  Impl& m = *impl_;
  {
    std::lock_guard<std::mutex> lock(m.control);
    if (!m.running) return;
    m.run_state.store(static_cast<int>(RunState::stopping));
  }
  m.checkpointer.stop();  // without `control`: it may be waiting for it
  std::lock_guard<std::mutex> lock(m.control);
  m.subscriber.stop();
  m.loop.stop(true);  // waits for a running warm-up fit and works off the backlog
  m.publisher.stop();
  m.loop.stop_fitter();
  m.running = false;
  const DaemonCounters c = m.counters.load();
  spdlog::info(
      "stopped: {} samples received: {} processed, {} non-finite, {} dropped, {} duplicate, {} out of order; {} lost "
      "in "
      "transport, {} decode errors, {} sender restarts, {} flag changes",
      c.samples_received, c.samples_processed, c.samples_nonfinite, c.samples_dropped, c.samples_duplicate,
      c.samples_out_of_order, c.samples_lost, c.decode_errors, c.sender_restarts, c.flag_changes);
}

std::string Daemon::reload(const Config& next) {
  Impl& m = *impl_;
  std::lock_guard<std::mutex> control_lock(m.control);
  check_checkpoint_directory(next);  // throws: the running configuration stays
  const bool same_fingerprint = checkpoint_fingerprint(next) == m.fingerprint;
  const std::vector<std::string> kept = needing_restart(m.config, next, same_fingerprint);
  m.run_state.store(static_cast<int>(RunState::reloading));
  const bool was_running = m.running;
  if (was_running) {  // the subscriber keeps filling the input ring
    m.loop.stop(false);
    m.publisher.stop();
  }
  Config applied = m.config;  // keeps model, estimator, LCM and rings
  applied.daemon.loop_rate_hz = next.daemon.loop_rate_hz;
  applied.daemon.publish_period = next.daemon.publish_period;
  applied.daemon.heartbeat_period = next.daemon.heartbeat_period;
  applied.daemon.stale_time = next.daemon.stale_time;
  applied.daemon.checkpoint_path = next.daemon.checkpoint_path;
  applied.daemon.checkpoint_period = next.daemon.checkpoint_period;
  applied.daemon.log_level = next.daemon.log_level;
  if (same_fingerprint) {
    applied.faults = next.faults;
  } else {  // configured baselines may not match the running model's submodels
    FaultSettings faults = next.faults;
    faults.baselines = applied.faults.baselines;
    faults.baseline_std = applied.faults.baseline_std;
    applied.faults = faults;
  }
  m.config = applied;
  m.loop.reconfigure_detector();
  spdlog::set_level(spdlog::level::from_str(m.config.daemon.log_level));
  if (was_running) {
    m.publisher.start();
    m.loop.start();
  }
  m.run_state.store(static_cast<int>(RunState::running));
  std::string summary = "reloaded " + next.source + ": applied rates (loop " +
                        std::to_string(m.config.daemon.loop_rate_hz) + " Hz, publish " +
                        std::to_string(m.config.daemon.publish_period) +
                        " s), fault detector settings, "
                        "baselines, checkpoint, log level " +
                        m.config.daemon.log_level + " (flags restart their hold timers)";
  if (!kept.empty()) {
    summary += "; NOT applied, restart the service for: ";
    for (std::size_t i = 0; i < kept.size(); ++i) summary += (i ? ", " : "") + kept[i];
  }
  return summary;
}

bool Daemon::write_checkpoint() {
  Impl& m = *impl_;
  std::lock_guard<std::mutex> lock(m.control);
  if (m.running) throw std::logic_error("Daemon::write_checkpoint: call after stop()");
  if (m.config.daemon.checkpoint_path.empty()) return true;
  const std::optional<Checkpoint> ck = m.loop.capture(m.fingerprint);
  if (!ck) {
    spdlog::info("checkpoint skipped: the estimator is still warming up (no estimate worth keeping)");
    return true;
  }
  return m.checkpointer.write(m.config.daemon.checkpoint_path, *ck, true);
}

DaemonCounters Daemon::counters() const { return impl_->counters.load(); }
bool Daemon::restored_from_checkpoint() const { return impl_->loop.restored(); }
bool Daemon::warming_up() const { return impl_->loop.warming_up(); }
const Config& Daemon::config() const { return impl_->config; }

}  // namespace modalwatch
