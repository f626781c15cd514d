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
constexpr double kWarningPeriod = 5.0;   // s, at most one line per repeated warning

const char* quantity_name(Quantity q) {
  static constexpr const char* names[kQuantities] = {"wn", "zeta", "gain"};
  return names[static_cast<int>(q)];
}

// Detector times are seconds after the first sample, on the loop's clock;
// messages carry the sender's utime.
std::int64_t utime_of(const Snapshot& s, double t) { return s.utime0 + std::llround(t * 1e6) - s.utime_offset; }

// The sample time of the newest sample, seconds after the first.
double t_of(const Snapshot& s) { return s.have_sample ? static_cast<double>(s.utime - s.utime0) * 1e-6 : 0.0; }

// Named states of fault_status_t (its .lcm file defines them).
const char* quantity_state(const QuantityStatus& q, bool baseline_ready, bool valid) {
  if (q.flagged) return "raised";
  if (q.pending) return "pending";
  if (!baseline_ready) return "learning";
  if (!valid) return "suppressed";
  return "ok";
}

int severity(const std::string& state) {
  static constexpr const char* order[] = {"ok", "suppressed", "learning", "pending", "raised"};
  for (int i = 4; i > 0; --i)
    if (state == order[i]) return i;
  return 0;
}

const char* daemon_state(const Snapshot& s) {
  if (!s.have_sample) return "no_input";
  if (s.warming_up) return "warming_up";
  for (int i = 0; i < s.n_modes; ++i)
    if (!s.modes[static_cast<std::size_t>(i)].baseline_ready) return "learning";
  return "watching";
}

struct HealthBit {
  std::int32_t bit;
  const char* name;
  bool Snapshot::*set;
};
constexpr HealthBit kHealthBits[] = {
    {Fault::HEALTH_ESTIMATOR_RESET, "estimator_reset", &Snapshot::reset},
    {Fault::HEALTH_INPUT_GAP, "input_gap", &Snapshot::gap},
    {Fault::HEALTH_RING_OVERFLOW, "ring_overflow", &Snapshot::input_dropped},
    {Fault::HEALTH_LOW_EXCITATION, "low_excitation", &Snapshot::low_excitation},
    {Fault::HEALTH_STALE_INPUT, "stale_input", &Snapshot::stale},
    {Fault::HEALTH_DECODE_ERRORS, "decode_errors", &Snapshot::decode_errors},
    {Fault::HEALTH_OVERRUN, "overrun", &Snapshot::overrun},
    {Fault::HEALTH_SAMPLES_LOST, "samples_lost", &Snapshot::samples_lost},
    {Fault::HEALTH_SENDER_RESTART, "sender_restart", &Snapshot::sender_restart},
    {Fault::HEALTH_MODEL_MISFIT, "model_misfit", &Snapshot::misfit},
};

}  // namespace

Publisher::Publisher(const Config& config, const Wiring& wiring, bool restored)
    : config_(config), wiring_(wiring), counters_(wiring.counters.publisher), restored_(restored) {
  encoded_.reserve(4096);
  if (!config.daemon.metrics_listen.empty()) {
    std::vector<std::string> names;
    for (const Submodel& m : config.model.submodels) names.push_back(m.name);
    metrics_.emplace(MetricsSettings{config.daemon.metrics_listen}, config.axis, std::move(names));
  }
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
    log_repeated(wiring_.counters.load(), now);
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
  log_repeated(s.counters, mono_ns());
  if (metrics_) export_metrics(s);
}

void Publisher::export_metrics(const Snapshot& s) {
  MetricsSnapshot& m = metrics_snapshot_;
  m.n_modes = s.n_modes;
  for (int i = 0; i < s.n_modes; ++i) {
    const auto k = static_cast<std::size_t>(i);
    m.modes[k].value = s.value[k];
    m.modes[k].std_dev = s.std_dev[k];
    m.modes[k].status = s.modes[k];
  }
  m.warming_up = s.warming_up;
  m.low_excitation = s.low_excitation;
  m.misfit = s.misfit;
  m.stale = s.stale;
  m.counters = s.counters;
  m.tick = s.tick;
  metrics_->update(m);
}

template <class Line>
void Publisher::warn_repeated(RepeatedWarning& w, std::uint64_t total, std::int64_t now, Line&& line) {
  if (total == w.logged || now < w.next_ns) return;
  const double over = w.last_ns ? static_cast<double>(now - w.last_ns) * 1e-9 : 0.0;
  line(total - w.logged, over, total);
  w.logged = total;
  w.last_ns = now;
  w.next_ns = now + static_cast<std::int64_t>(kWarningPeriod * 1e9);
}

void Publisher::log_repeated(const DaemonCounters& c, std::int64_t now) {
  // "n in x s" after the first line: x is the time since the previous line.
  const auto in = [](double over) { return over > 0.0 ? fmt::format(" in the last {:.1f} s", over) : std::string(); };
  warn_repeated(gaps_, c.gaps, now, [&](std::uint64_t n, double over, std::uint64_t total) {
    spdlog::warn("input gap: prefilter states reset (parameters kept): {}{}, {} gaps so far", n, in(over), total);
  });
  warn_repeated(resets_, c.resets, now, [&](std::uint64_t n, double over, std::uint64_t total) {
    spdlog::warn("estimator reset to its last good state (last: {}): {}{}, {} resets so far", last_reset_reason_, n,
                 in(over), total);
  });
  warn_repeated(boosts_, c.change_boosts, now, [&](std::uint64_t n, double over, std::uint64_t total) {
    spdlog::info(
        "change test: the output error changed, covariance of the submodels it points to boosted: {}{}, "
        "{} so far",
        n, in(over), total);
  });
  warn_repeated(restores_, c.mode_restores, now, [&](std::uint64_t n, double over, std::uint64_t total) {
    spdlog::warn("estimator: a mode whose gain changed sign went back to its last good estimate: {}{}, {} so far", n,
                 in(over), total);
  });
  warn_repeated(lost_, c.samples_lost, now, [&](std::uint64_t n, double over, std::uint64_t total) {
    spdlog::warn("samples lost in transport (sequence numbers that never arrived): {}{}, {} so far", n, in(over),
                 total);
  });
  warn_repeated(dropped_, c.samples_dropped, now, [&](std::uint64_t n, double over, std::uint64_t total) {
    spdlog::warn("samples dropped, input ring or warm-up backlog full: {}{}, {} so far", n, in(over), total);
  });
}

bool Publisher::send(const std::string& channel, const auto& message) {
  encoded_.resize(static_cast<std::size_t>(message.getEncodedSize()));
  message.encode(encoded_.data(), 0, static_cast<int>(encoded_.size()));
  return lcm_publish(wiring_.lcm, channel.c_str(), encoded_.data(), static_cast<unsigned>(encoded_.size())) == 0;
}

void Publisher::publish_estimates(const Snapshot& s) {
  modalwatch::estimates_t msg;
  msg.utime = s.utime - s.utime_offset;
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
  msg.version = Fault::VERSION;
  msg.utime = s.utime - s.utime_offset;
  msg.t = t_of(s);
  msg.state = daemon_state(s);
  msg.n_modes = s.n_modes;
  msg.modes.resize(static_cast<std::size_t>(s.n_modes));
  const bool valid = s.estimates_valid;
  for (int i = 0; i < s.n_modes; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const ModeStatus& mode = s.modes[k];
    modalwatch::mode_status_t& m = msg.modes[k];
    m.name = config_.model.submodels[k].name;
    m.baseline_ready = mode.baseline_ready;
    m.state = "ok";
    modalwatch::quantity_status_t* fields[kQuantities] = {&m.wn, &m.zeta, &m.gain};
    for (int q = 0; q < kQuantities; ++q) {
      const QuantityStatus& in = mode.quantity[static_cast<std::size_t>(q)];
      modalwatch::quantity_status_t& out = *fields[q];
      out.state = quantity_state(in, mode.baseline_ready, valid);
      out.deviation_sigma = in.deviation_sigma;
      out.deviation_percent = 100.0 * in.deviation_relative;
      const bool timed = in.flagged || in.pending;
      out.since = timed ? utime_of(s, in.since) : 0;
      out.since_t = timed ? in.since : 0.0;
      if (severity(out.state) > severity(m.state)) m.state = out.state;
    }
  }
  msg.health = 0;
  for (const HealthBit& h : kHealthBits)
    if (s.*h.set) {
      msg.health |= h.bit;
      (msg.health_text += msg.health_text.empty() ? "" : ",") += h.name;
    }
  if (msg.health_text.empty()) msg.health_text = "ok";
  const DaemonCounters& c = s.counters;
  msg.samples_received = static_cast<std::int64_t>(c.samples_received);
  msg.samples_processed = static_cast<std::int64_t>(c.samples_processed);
  msg.samples_lost = static_cast<std::int64_t>(c.samples_lost);
  msg.overruns = static_cast<std::int64_t>(c.overruns);
  msg.sender_restarts = static_cast<std::int64_t>(c.sender_restarts);
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
    case RunState::starting:
      msg.state = "starting";
      break;
    case RunState::reloading:
      msg.state = "reloading";
      break;
    case RunState::stopping:
      msg.state = "stopping";
      break;
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
    // t: sample time since the first sample; the log line's own stamp is the wall clock.
    if (c.raised)
      spdlog::warn(
          "FLAG RAISED: mode '{}' {}: {:.6g} vs baseline {:.6g} ({:+.2f} %, {:+.1f} sigma) at t = {:.3f} s (utime {})",
          name, quantity_name(c.quantity), c.value, c.baseline, 100.0 * c.deviation_relative, c.deviation_sigma, c.time,
          utime_of(s, c.time));
    else
      spdlog::info("flag cleared: mode '{}' {}: {:.6g} vs baseline {:.6g} ({:+.2f} %) at t = {:.3f} s (utime {})", name,
                   quantity_name(c.quantity), c.value, c.baseline, 100.0 * c.deviation_relative, c.time,
                   utime_of(s, c.time));
  }
  if (s.reset) last_reset_reason_ = s.reset_reason;
  if (s.sender_restart)
    spdlog::warn(
        "sender restart: seq and utime started again (now seq {}, utime {}); prefilter states reset, parameters and "
        "baselines kept; {} restarts so far",
        s.last_seq, s.utime - s.utime_offset, s.counters.sender_restarts);
  if (!logged_warmup_over_ && !s.warming_up && s.counters.samples_processed > 0) {
    logged_warmup_over_ = true;
    if (restored_)
      spdlog::info("estimating from the restored checkpoint (no warm-up)");
    else if (s.warmup_fit_used || !config_.estimator.fit_on_warmup)
      spdlog::info(
          "warm-up over after {} samples; estimating from {} (the fit took {:.2f} s; {} samples held "
          "meanwhile)",
          s.counters.samples_processed,
          s.warmup_fit_used ? "the fit on the warm-up window" : "the configured model (fit_on_warmup off)",
          s.warmup_fit_seconds, s.counters.samples_held);
    else
      spdlog::warn(
          "warm-up over after {} samples; the fit on the warm-up window is not used ({}): estimating from the "
          "configured model ({} samples held meanwhile)",
          s.counters.samples_processed, kWarmupFitNotUsed, s.counters.samples_held);
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
  if (s.stale && !logged_stale_) {
    logged_stale_ = true;
    received_when_stale_ = s.counters.samples_received;
    if (s.counters.samples_received == 0)
      spdlog::warn("no input yet: no sample for more than {} s since start", config_.daemon.stale_time);
    else
      spdlog::warn("stale input: no sample for more than {} s", config_.daemon.stale_time);
  } else if (!s.stale && logged_stale_ && s.counters.samples_received > received_when_stale_) {
    logged_stale_ = false;  // only a sample ends it (a reload of stale_time does not)
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
        "(ring full), {} lost in transport, {} decode errors, {} non-finite, {} duplicate, {} out of order, {} "
        "gaps, {} resets, {} overruns, {} sender restarts",
        dt, rate(c.samples_received, rate_base_.samples_received),
        rate(c.samples_processed, rate_base_.samples_processed),
        rate(c.estimates_published, rate_base_.estimates_published), c.samples_dropped, c.samples_lost, c.decode_errors,
        c.samples_nonfinite, c.samples_duplicate, c.samples_out_of_order, c.gaps, c.resets, c.overruns,
        c.sender_restarts);
  }
  rate_base_ = c;
  rate_base_ns_ = now;
}

}  // namespace modalwatch::daemon_detail
