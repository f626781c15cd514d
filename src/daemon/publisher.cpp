#include "publisher.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include <modalwatch/estimates_t.hpp>
#include <modalwatch/fault_status_t.hpp>
#include <modalwatch/heartbeat_t.hpp>

#include "realtime.hpp"

namespace modalwatch::daemon_detail {
namespace {

using Fault = modalwatch::fault_status_t;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kRateLogPeriod = 10.0;  // s

const char* quantity_name(Quantity q) {
  static constexpr const char* names[kQuantities] = {"wn", "zeta", "gain"};
  return names[static_cast<int>(q)];
}

// Detector times are seconds after the first sample; messages carry utime.
std::int64_t utime_of(const Snapshot& s, double t) { return s.utime0 + std::llround(t * 1e6); }

// fault_status_t.flags of one quantity.
std::int32_t flag_bits(const QuantityStatus& q, bool valid) {
  std::int32_t f = 0;
  if (q.flagged) f |= Fault::FLAG_RAISED;
  if (q.pending) f |= Fault::FLAG_PENDING;
  if (q.deviation_sigma < 0.0 || q.deviation_relative < 0.0) f |= Fault::FLAG_LOW;
  if (!valid) f |= Fault::FLAG_SUPPRESSED;
  return f;
}

std::int32_t health_bits(const Snapshot& s) {
  std::int32_t h = 0;
  if (s.gap) h |= Fault::HEALTH_INPUT_GAP;
  if (s.reset) h |= Fault::HEALTH_ESTIMATOR_RESET;
  if (s.low_excitation) h |= Fault::HEALTH_LOW_EXCITATION;
  if (s.stale) h |= Fault::HEALTH_STALE_INPUT;
  if (s.input_dropped) h |= Fault::HEALTH_RING_OVERFLOW;
  if (s.decode_errors) h |= Fault::HEALTH_DECODE_ERRORS;
  return h;
}

}  // namespace

Publisher::Publisher(const Config& config, const Wiring& wiring, bool restored)
    : config_(config), wiring_(wiring), counters_(wiring.counters.publisher), restored_(restored) {
  encoded_.reserve(4096);
}

void Publisher::start() {
  if (thread_.joinable()) return;
  stop_.store(false);
  thread_ = std::thread([this] { run(); });
}

void Publisher::stop() {
  if (!thread_.joinable()) return;
  stop_.store(true, std::memory_order_release);
  wiring_.input_bell.ring();
  thread_.join();
}

void Publisher::run() {
  minimise_timer_slack();
  name_this_thread("mw-publish");
  make_realtime(config_.daemon.realtime_priority);
  for (;;) {
    // Read before looking at the ring: a snapshot pushed after the look rings
    // the bell past `seen`, and the wait below returns at once.
    const std::uint32_t seen = wiring_.input_bell.rings();
    const bool stopping = stop_.load(std::memory_order_acquire);
    while (const Snapshot* s = wiring_.input.front()) {
      handle(*s);
      wiring_.input.pop();
    }
    const std::int64_t now = mono_ns();
    if (now >= next_heartbeat_ns_) {
      publish_heartbeat(now);
      next_heartbeat_ns_ = now + static_cast<std::int64_t>(config_.daemon.heartbeat_period * 1e9);
    }
    if (now >= next_rate_log_ns_) {
      log_rates(now);
      next_rate_log_ns_ = now + static_cast<std::int64_t>(kRateLogPeriod * 1e9);
    }
    if (stopping) break;
    wiring_.input_bell.wait_until(seen, std::min(next_heartbeat_ns_, next_rate_log_ns_));
  }
}

void Publisher::handle(const Snapshot& s) {
  if (s.kind == Snapshot::estimate) publish_estimates(s);
  if (s.kind != Snapshot::final_state || s.n_changes) publish_fault_status(s);
  log_snapshot(s);
}

bool Publisher::send(const std::string& channel, const auto& message) {
  encoded_.resize(static_cast<std::size_t>(message.getEncodedSize()));
  message.encode(encoded_.data(), 0, static_cast<int>(encoded_.size()));
  return lcm_publish(wiring_.lcm, channel.c_str(), encoded_.data(), static_cast<unsigned>(encoded_.size())) == 0;
}

void Publisher::publish_estimates(const Snapshot& s) {
  modalwatch::estimates_t msg;
  msg.utime = s.utime;
  msg.n_modes = s.n_modes;
  msg.modes.resize(static_cast<std::size_t>(s.n_modes));
  for (int i = 0; i < s.n_modes; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const bool ready = s.modes[k].baseline_ready;
    const ModalParameters& baseline = s.modes[k].baseline.value;
    auto& m = msg.modes[k];
    m.name = config_.model.submodels[k].name;
    m.wn = s.value[k].wn;
    m.hz = s.value[k].wn / (2.0 * std::numbers::pi);
    m.zeta = s.value[k].zeta;
    m.gain = s.value[k].gain;
    m.wn_std = s.std_dev[k].wn;
    m.zeta_std = s.std_dev[k].zeta;
    m.gain_std = s.std_dev[k].gain;
    m.baseline_wn = ready ? baseline.wn : kNaN;
    m.baseline_zeta = ready ? baseline.zeta : kNaN;
    m.baseline_gain = ready ? baseline.gain : kNaN;
  }
  msg.residual_rms = s.residual_rms;
  msg.samples_processed = static_cast<std::int64_t>(s.counters.samples_processed);
  if (send(config_.lcm.estimates_channel, msg)) bump(counters_.estimates_published);
}

void Publisher::publish_fault_status(const Snapshot& s) {
  Fault msg;
  msg.utime = s.utime;
  msg.n_modes = s.n_modes;
  msg.n_entries = kQuantities * s.n_modes;
  const bool valid = !s.warming_up && !s.low_excitation;
  for (int i = 0; i < s.n_modes; ++i) {
    const auto k = static_cast<std::size_t>(i);
    msg.mode_names.push_back(config_.model.submodels[k].name);
    for (const QuantityStatus& q : s.modes[k].quantity) {
      msg.flags.push_back(flag_bits(q, valid));
      msg.deviation_sigma.push_back(q.deviation_sigma);
      msg.deviation_percent.push_back(100.0 * q.deviation_relative);
      msg.since.push_back((q.flagged || q.pending) ? utime_of(s, q.since) : 0);
    }
  }
  msg.health = health_bits(s);
  const DaemonCounters& c = s.counters;
  msg.samples_received = static_cast<std::int64_t>(c.samples_received);
  msg.samples_dropped = static_cast<std::int64_t>(c.samples_dropped);
  msg.samples_nonfinite = static_cast<std::int64_t>(c.samples_nonfinite);
  msg.samples_duplicate = static_cast<std::int64_t>(c.samples_duplicate);
  msg.samples_out_of_order = static_cast<std::int64_t>(c.samples_out_of_order);
  msg.gaps = static_cast<std::int64_t>(c.gaps);
  msg.decode_errors = static_cast<std::int64_t>(c.decode_errors);
  msg.resets = static_cast<std::int64_t>(c.resets);
  if (send(config_.lcm.fault_status_channel, msg)) bump(counters_.fault_status_published);
}

void Publisher::publish_heartbeat(std::int64_t now) {
  modalwatch::heartbeat_t msg;
  msg.utime = wall_us();
  switch (static_cast<RunState>(wiring_.run_state.load(std::memory_order_relaxed))) {
    case RunState::starting: msg.state = "starting"; break;
    case RunState::reloading: msg.state = "reloading"; break;
    case RunState::stopping: msg.state = "stopping"; break;
    case RunState::running:
      msg.state = wiring_.warming_up.load(std::memory_order_relaxed) ? "warming_up" : "running";
      break;
  }
  msg.uptime_us = (now - wiring_.start_ns) / 1000;
  if (send(config_.lcm.heartbeat_channel, msg)) bump(counters_.heartbeats_published);
}

void Publisher::log_snapshot(const Snapshot& s) {
  for (int k = 0; k < s.n_changes; ++k) {
    const FlagChange& c = s.changes[static_cast<std::size_t>(k)];
    const std::string& name = config_.model.submodels[static_cast<std::size_t>(c.mode)].name;
    if (c.raised)
      spdlog::warn("FLAG RAISED: mode '{}' {}: {:.6g} vs baseline {:.6g} ({:+.2f} %, {:+.1f} sigma) at utime {}", name,
                   quantity_name(c.quantity), c.value, c.baseline, 100.0 * c.deviation_relative, c.deviation_sigma,
                   utime_of(s, c.time));
    else
      spdlog::info("flag cleared: mode '{}' {}: {:.6g} vs baseline {:.6g} ({:+.2f} %) at utime {}", name,
                   quantity_name(c.quantity), c.value, c.baseline, 100.0 * c.deviation_relative, utime_of(s, c.time));
  }
  if (s.reset)
    spdlog::warn("estimator reset to its last good state ({}); {} resets so far", s.reset_reason, s.counters.resets);
  if (s.gap) spdlog::warn("input gap: prefilter states reset (parameters kept); {} gaps so far", s.counters.gaps);
  if (!logged_warmup_over_ && !s.warming_up && s.counters.samples_processed > 0) {
    logged_warmup_over_ = true;
    if (restored_)
      spdlog::info("estimating from the restored checkpoint (no warm-up)");
    else
      spdlog::info("warm-up over after {} samples; estimating (the fit took {:.2f} s; {} samples held meanwhile)",
                   s.counters.samples_processed, s.warmup_fit_seconds, s.counters.samples_held);
  }
  if (s.counters.held_dropped != logged_held_dropped_) {
    logged_held_dropped_ = s.counters.held_dropped;
    spdlog::warn("{} samples dropped while the warm-up fit ran: daemon.warmup_backlog ({} s) is too short for it",
                 s.counters.held_dropped, config_.daemon.warmup_backlog);
  }
  for (int i = 0; i < s.n_modes; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const ModeStatus& m = s.modes[k];
    if (m.baseline_ready && !logged_baseline_[k]) {
      logged_baseline_[k] = true;
      spdlog::info("baseline of mode '{}' ({}): f = {:.6g} Hz, zeta = {:.4g}, gain = {:.6g}",
                   config_.model.submodels[k].name, m.baseline.learned ? "learned" : "configured or restored",
                   m.baseline.value.wn / (2.0 * std::numbers::pi), m.baseline.value.zeta, m.baseline.value.gain);
    }
  }
  if (s.stale != logged_stale_) {
    logged_stale_ = s.stale;
    if (s.stale)
      spdlog::warn("stale input: no sample for more than {} s", config_.daemon.stale_time);
    else
      spdlog::info("input resumed");
  }
}

void Publisher::log_rates(std::int64_t now) {
  const DaemonCounters c = wiring_.counters.load();
  if (rate_base_ns_ != 0) {
    const double dt = static_cast<double>(now - rate_base_ns_) * 1e-9;
    const auto rate = [dt](std::uint64_t a, std::uint64_t b) { return static_cast<double>(a - b) / dt; };
    spdlog::info(
        "rates over {:.1f} s: {:.0f} samples/s in, {:.0f} processed, {:.1f} estimates/s; since start: {} dropped "
        "(ring full), {} decode errors, {} non-finite, {} duplicate, {} out of order, {} gaps, {} resets, {} "
        "overruns",
        dt, rate(c.samples_received, rate_base_.samples_received),
        rate(c.samples_processed, rate_base_.samples_processed),
        rate(c.estimates_published, rate_base_.estimates_published), c.samples_dropped, c.decode_errors,
        c.samples_nonfinite, c.samples_duplicate, c.samples_out_of_order, c.gaps, c.resets, c.overruns);
  }
  rate_base_ = c;
  rate_base_ns_ = now;
}

}  // namespace modalwatch::daemon_detail
