#include "estimation_loop.hpp"

#include <spdlog/spdlog.h>
#include <systemd/sd-daemon.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

#include "loop_probe.hpp"
#include "realtime.hpp"

namespace modalwatch::daemon_detail {
namespace {

// How long a run of samples behind the last accepted one must go on to be a
// sender restart (see estimation_loop.hpp).
constexpr double kRestartConfirm = 0.1;  // s of sample time
constexpr int kRestartConfirmSamples = 8;

bool finite(const StampedSample& s) {
  bool ok = std::isfinite(s.u) && std::isfinite(s.y) && std::isfinite(s.r);
  for (int j = 0; j < s.further_inputs; ++j) ok = ok && std::isfinite(s.further_u[static_cast<std::size_t>(j)]);
  return ok;
}

// The fitter thread runs the warm-up fit (see warmup_fitter.hpp).
EstimatorSettings with_deferred_fit(EstimatorSettings s) {
  s.defer_warmup_fit = true;
  return s;
}

// The config's detector with the baselines kept from before (a checkpoint, the
// detector of the config a reload replaces), covariance and all, for the modes
// the config gives no baseline.
FaultDetector make_detector(const Config& c, const std::vector<std::optional<ModeBaseline>>& kept) {
  FaultDetector detector(fault_detector_settings(c));
  for (std::size_t i = 0; i < kept.size(); ++i) {
    const bool configured = i < c.faults.baselines.size() && c.faults.baselines[i].has_value();
    if (!configured && kept[i]) detector.restore_baseline(static_cast<int>(i), *kept[i]);
  }
  return detector;
}

}  // namespace

EstimationLoop::EstimationLoop(const Config& config, const std::optional<Checkpoint>& checkpoint,
                               SpscRing<StampedSample>& input, SpscRing<Snapshot>& output, Doorbell& output_bell,
                               Counters& counters, std::int64_t start_ns)
    : config_(config),
      input_(input),
      output_(output),
      output_bell_(output_bell),
      counters_(counters.loop),
      all_counters_(counters),
      start_ns_(start_ns),
      estimator_(config.model, with_deferred_fit(config.estimator)),
      detector_input_(estimator_),
      fitter_(estimator_) {
  const auto K = config.model.submodels.size();
  std::vector<std::optional<ModeBaseline>> restored_baselines;
  if (checkpoint) {
    try {
      estimator_.restore(checkpoint->estimator);  // no warm-up; the prefilters restart as after a gap
      restored_ = true;
    } catch (const std::invalid_argument& e) {
      spdlog::warn("checkpoint {} does not fit the estimator ({}): starting with a warm-up",
                   config.daemon.checkpoint_path, e.what());
    }
  }
  if (restored_) {
    restored_baselines = checkpoint->baselines;
    have_seq_ = true;
    have_ref_time_ = true;
    last_seq_ = checkpoint->last_seq;
    last_utime_ = checkpoint->last_utime;
    spdlog::info("restored checkpoint {}: last sample utime {} us, seq {}; no warm-up", config.daemon.checkpoint_path,
                 last_utime_, last_seq_);
  }
  if (config.estimator.warmup_samples > 0) {  // a warm-up, or later a refit (estimator.hpp)
    // Touched here (value-initialised), so that holding input never page-faults on the loop.
    const double held = std::ceil(config.daemon.warmup_backlog / config.sample_time);
    backlog_.resize(static_cast<std::size_t>(std::max(1.0, held)));
  }
  set_detector(restored_baselines);
  sample_.further_inputs = config.model.n_inputs() - 1;
  flag_changes_.reserve(kQuantities * K);
}

EstimationLoop::~EstimationLoop() {
  stop(true);
  fitter_.stop();
}

void EstimationLoop::set_probe(LoopProbe* probe) {
  probe_ = probe;
  fitter_.set_probe(probe);
}

void EstimationLoop::start_fitter() {
  // Before the loop runs: after that only it and the fitter touch the estimator.
  // Also after a restore: a divergence may end in a refit, which it runs too.
  if (config_.estimator.warmup_samples > 0) fitter_.start();
}

void EstimationLoop::start() {
  if (thread_.joinable()) return;
  const DaemonSettings& d = config_.daemon;
  const std::int64_t period_us = std::max<std::int64_t>(1, std::llround(d.publish_period * 1e6));
  // The estimates (and the fault detector's updates) fall on the sample-time
  // grid utime0 + k period, as in `track --faults`. A pause (a checkpoint, a
  // reload) keeps it: re-anchored on the last sample, it moved by however far
  // the loop had got when paused, and so did the flags. A new period starts
  // its grid from utime0 too.
  if (have_time_ && period_us != publish_period_us_)
    next_publish_utime_ = utime0_ + ((last_utime_ - utime0_) / period_us + 1) * period_us;
  publish_period_us_ = period_us;
  gap_us_ = std::llround(config_.estimator.gap_factor * config_.sample_time * 1e6);
  tick_period_ns_ = std::max<std::int64_t>(10'000, static_cast<std::int64_t>(std::llround(1e9 / d.loop_rate_hz)));
  tick_origin_ns_ = mono_ns();
  stop_.store(keep_running);
  thread_ = std::thread([this] { run(); });
}

void EstimationLoop::stop(bool final_stop) {
  if (!thread_.joinable()) return;
  stop_.store(final_stop ? stop_requested : pause_requested, std::memory_order_release);
  thread_.join();
}

void EstimationLoop::run() noexcept {
  minimise_timer_slack();
  name_this_thread("mw-estimate");
  make_realtime(config_.daemon.realtime_priority);
  const std::int64_t period_ns = tick_period_ns_;
  const std::int64_t status_period_ns = static_cast<std::int64_t>(config_.daemon.publish_period * 1e9);
  std::int64_t tick = 0;  // ticks at tick_origin_ns_ + k period_ns
  for (;;) {
    const int request = stop_.load(std::memory_order_acquire);
    const bool stopping = request != keep_running;
    const bool final_stop = request == stop_requested;
    if (fit_in_flight_ && fitter_.take_applied()) {  // the estimator is ours again
      fit_in_flight_ = false;
      detector_input_.fitted(estimator_.status().fitted_window);
    }
    if (probe_ && !probe_fired_ && !fit_in_flight_ && backlog_size_ == 0 && !estimator_.status().warming_up &&
        read(counters_.snapshots) > 0) {
      probe_->warmed_up();
      probe_fired_ = true;
    }
    const std::int64_t tick_start = mono_ns();
    std::int64_t now = tick_start;
    work_off_backlog(final_stop ? std::numeric_limits<std::int64_t>::max() : now + period_ns / 2);
    drain(now);
    // Without input for a publish period, the fault status still goes out
    // (stale after daemon.stale_time), and so it does while the warm-up fit
    // holds the input; otherwise the sample clock paces it.
    const std::int64_t since_input = now - (last_sample_ns_ ? last_sample_ns_ : start_ns_);
    if ((since_input >= status_period_ns || fit_in_flight_) && now - last_snapshot_ns_ >= status_period_ns)
      push_snapshot(Snapshot::status_only, now, false);
    if (watchdog_usec_ > 0 && now - last_watchdog_ns_ >= static_cast<std::int64_t>(watchdog_usec_) * 500) {
      sd_notify(0, "WATCHDOG=1");
      last_watchdog_ns_ = now;
    }
    if (stopping && !(final_stop && fit_in_flight_)) {
      drain(mono_ns());
      if (final_stop) work_off_backlog(std::numeric_limits<std::int64_t>::max());
      push_snapshot(Snapshot::final_state, mono_ns(), false);
      break;
    }
    ++tick;
    now = mono_ns();
    tick_histogram_.record(now - tick_start);
    if (now > tick_origin_ns_ + tick * period_ns) {  // this tick ended after the next one was due
      bump(counters_.overruns);
      tick = (now - tick_origin_ns_) / period_ns + 1;  // the next tick on the grid
    }
    sleep_until(tick_origin_ns_ + tick * period_ns);
  }
  if (probe_) probe_->exiting();
}

void EstimationLoop::drain(std::int64_t now) noexcept {
  const std::size_t limit = input_.capacity();
  std::size_t n = 0;
  while (n < limit) {
    const StampedSample* s = input_.front();
    if (!s) break;
    if (fit_in_flight_ || backlog_size_ > 0)
      enqueue_held(*s);  // behind the backlog, in order
    else
      process(*s);
    input_.pop();
    ++n;
  }
  if (n > 0) last_sample_ns_ = now;
}

// A sample that arrives while the warm-up fit runs or the backlog is worked off.
void EstimationLoop::enqueue_held(const StampedSample& s) noexcept {
  if (backlog_size_ == backlog_.size()) {  // daemon.warmup_backlog too small for this fit
    bump(counters_.held_dropped);
    return;
  }
  backlog_[(backlog_head_ + backlog_size_) % backlog_.size()] = s;
  ++backlog_size_;
  bump(counters_.samples_held);
}

// The held samples, oldest first, until `deadline_ns` (checked per sample: a
// step is a few microseconds), so that a catch-up does not cost the loop its tick.
void EstimationLoop::work_off_backlog(std::int64_t deadline_ns) noexcept {
  while (!fit_in_flight_ && backlog_size_ > 0) {
    process(backlog_[backlog_head_]);
    backlog_head_ = (backlog_head_ + 1) % backlog_.size();
    --backlog_size_;
    if (mono_ns() >= deadline_ns) break;
  }
}

// Whether `s`, behind the last accepted sample in seq and utime, completes a
// run that shows a restarted sender.
bool EstimationLoop::restart_confirmed(const StampedSample& s) noexcept {
  if (!have_ref_time_ || s.utime + utime_offset_ >= last_utime_) {
    restart_run_ = 0;
    return false;
  }
  if (restart_run_ == 0 || s.seq <= restart_run_seq_ || s.utime <= restart_run_utime_) {
    restart_run_ = 0;
    restart_run_first_utime_ = s.utime;
  }
  ++restart_run_;
  restart_run_seq_ = s.seq;
  restart_run_utime_ = s.utime;
  return restart_run_ >= kRestartConfirmSamples &&
         static_cast<double>(s.utime - restart_run_first_utime_) * 1e-6 >= kRestartConfirm;
}

// From `s` on the sender's utime maps to the loop's clock two gaps after the
// last sample: the estimator sees a gap (prefilter states reset), nothing else.
void EstimationLoop::note_restart(const StampedSample& s) noexcept {
  if (s.utime + utime_offset_ <= last_utime_ + gap_us_) utime_offset_ = last_utime_ + 2 * gap_us_ - s.utime;
  restart_run_ = 0;
  bump(counters_.sender_restarts);
  restart_since_snapshot_ = true;
}

void EstimationLoop::process(const StampedSample& s) noexcept {
  if (have_seq_ && s.seq <= last_seq_) {
    if (have_ref_time_ && s.utime + utime_offset_ > last_utime_ + gap_us_) {
      note_restart(s);  // seq back, time on past a gap: a new stream
    } else if (s.seq == last_seq_) {
      bump(counters_.samples_duplicate);
      return;
    } else if (restart_confirmed(s)) {
      note_restart(s);
    } else {
      bump(counters_.samples_out_of_order);
      return;
    }
  }
  const std::int64_t utime = s.utime + utime_offset_;
  if (!have_time_) {
    have_time_ = true;
    utime0_ = utime;
    next_publish_utime_ = utime + publish_period_us_;
  } else if (utime <= last_utime_) {
    // A later seq with an earlier (or equal) time: the estimator would reject it too.
    bump(counters_.samples_out_of_order);
    return;
  }
  have_seq_ = true;
  last_seq_ = s.seq;
  restart_run_ = 0;
  last_utime_ = utime;
  have_ref_time_ = true;
  const double t = static_cast<double>(utime - utime0_) * 1e-6;
  // A non-finite sample goes to the estimator too, which keeps its time slot
  // (holds u and r, lets the model stand in for y, does not update): dropping it
  // here would leave a hole of 2 T that resets the prefilters as a gap.
  sample_.t = t;
  sample_.u = s.u;
  sample_.y = s.y;
  sample_.r = s.r;
  // The subscriber passes only packets of the model's inputs (sample_.further_inputs).
  if (sample_.further_inputs > 0) std::copy_n(s.further_u.begin(), sample_.further_inputs, sample_.further_u.begin());
  const unsigned flags = estimator_.step(sample_);
  bump(finite(s) ? counters_.samples_processed : counters_.samples_nonfinite);
  if (flags & kWarmupFitPending) {
    // The window is complete: the fitter takes the job and, until it has applied
    // it, the estimator (take_warmup_fit moves the window: no allocation here).
    status_before_fit_ = estimator_.status();
    fit_in_flight_ = true;
    fitter_.request(estimator_.take_warmup_fit());
  }
  if (flags & kGap) {
    bump(counters_.gaps);
    gap_since_snapshot_ = true;
  }
  if (flags & kReset) {
    bump(counters_.resets);
    reset_since_snapshot_ = true;
  }
  if (flags & kChangeBoost) bump(counters_.change_boosts);
  if (flags & kModeRestored) bump(counters_.mode_restores);
  if (utime >= next_publish_utime_) {
    push_snapshot(Snapshot::estimate, mono_ns(), true);
    next_publish_utime_ += publish_period_us_;
    if (next_publish_utime_ <= utime) next_publish_utime_ = utime + publish_period_us_;
  }
}

void EstimationLoop::push_snapshot(Snapshot::Kind kind, std::int64_t now, bool update_detector) noexcept {
  Snapshot& snap = next_snapshot_;
  const int K = static_cast<int>(detector_input_.value().size());
  // During the warm-up fit the estimator is the fitter's: the cached status and
  // the last values stand in (flags are suppressed while warming up anyway).
  const EstimatorStatus& st = fit_in_flight_ ? status_before_fit_ : estimator_.status();
  snap.kind = kind;
  snap.n_modes = K;
  snap.utime = have_ref_time_ ? last_utime_ : 0;
  snap.utime0 = utime0_;
  snap.utime_offset = utime_offset_;
  snap.have_sample = have_time_;
  snap.last_seq = last_seq_;
  snap.have_seq = have_seq_;
  snap.warming_up = st.warming_up;
  snap.low_excitation = st.low_excitation;
  snap.misfit = st.misfit;
  snap.estimates_valid = st.estimates_measure_plant();
  snap.reset_reason = st.last_reset_reason;
  snap.warmup_fit_seconds = fitter_.last_fit_seconds();
  snap.warmup_fit_used = st.warmup_fit_used;
  warming_up_.store(st.warming_up, std::memory_order_relaxed);
  if (!fit_in_flight_) detector_input_.read(estimator_);
  for (int i = 0; i < K; ++i) {
    const auto k = static_cast<std::size_t>(i);
    snap.value[k] = detector_input_.value()[k];
    if (!fit_in_flight_) snap.std_dev[k] = estimator_.mode(i).std;
  }
  if (!fit_in_flight_) snap.residual_rms = estimator_.residual_rms();
  snap.n_changes = 0;
  if (update_detector) {
    flag_changes_.clear();
    const double t = static_cast<double>(last_utime_ - utime0_) * 1e-6;
    const bool valid = st.estimates_measure_plant();
    // capacity reserved: no allocation
    detector_input_.update(*detector_, t, valid, flag_changes_);
    for (const FlagChange& c : flag_changes_) {
      if (snap.n_changes == kMaxEntries) break;
      snap.changes[static_cast<std::size_t>(snap.n_changes++)] = c;
    }
    if (snap.n_changes) bump(counters_.flag_changes, static_cast<std::uint64_t>(snap.n_changes));
  }
  std::copy(detector_->status().begin(), detector_->status().end(), snap.modes.begin());
  const std::int64_t since_input = now - (last_sample_ns_ ? last_sample_ns_ : start_ns_);
  snap.stale = since_input > static_cast<std::int64_t>(config_.daemon.stale_time * 1e9);
  snap.gap = gap_since_snapshot_;
  snap.reset = reset_since_snapshot_;
  snap.sender_restart = restart_since_snapshot_;
  gap_since_snapshot_ = reset_since_snapshot_ = restart_since_snapshot_ = false;
  const std::uint64_t dropped = read(all_counters_.subscriber.ring_full) + read(counters_.held_dropped);
  const std::uint64_t decode_errors = read(all_counters_.subscriber.decode_errors);
  snap.input_dropped = dropped != dropped_at_snapshot_;
  snap.decode_errors = decode_errors != decode_errors_at_snapshot_;
  dropped_at_snapshot_ = dropped;
  decode_errors_at_snapshot_ = decode_errors;
  const std::uint64_t overruns = read(counters_.overruns), lost = read(all_counters_.subscriber.samples_lost);
  snap.overrun = overruns != overruns_at_snapshot_;
  snap.samples_lost = lost != lost_at_snapshot_;
  overruns_at_snapshot_ = overruns;
  lost_at_snapshot_ = lost;
  bump(counters_.snapshots);
  snap.counters = all_counters_.load();
  snap.tick = tick_histogram_;
  if (output_.try_push(snap))
    output_bell_.ring();
  else
    bump(counters_.snapshots_dropped);
  last_snapshot_ns_ = now;
}

// The estimator's state() allocates: only while the thread is stopped. While a
// warm-up fit is out (only the stopped loop could have started one) the
// estimator is the fitter's, and there is nothing worth keeping yet.
std::optional<Checkpoint> EstimationLoop::capture(std::uint64_t fingerprint) const {
  if (!fitter_.idle()) return std::nullopt;
  if (!have_seq_ || estimator_.status().warming_up) return std::nullopt;
  Checkpoint ck;
  ck.config_fingerprint = fingerprint;
  ck.last_utime = last_utime_ - utime_offset_;  // the sender's clock
  ck.last_seq = last_seq_;
  ck.estimator = estimator_.state();
  for (int i = 0; i < estimator_.submodels(); ++i) {
    const ModeStatus& m = detector_->status()[static_cast<std::size_t>(i)];
    ck.baselines.push_back(m.baseline_ready ? std::optional<ModeBaseline>(m.baseline) : std::nullopt);
  }
  return ck;
}

// Learned and restored baselines survive unless the rewritten config sets one
// for that mode; configured ones follow the config. What the new detector
// does not carry over is logged at warning level.
void EstimationLoop::reconfigure_detector() {
  if (config_.faults == detector_faults_) return;  // nothing to apply: flags and learning go on
  const std::vector<ModeStatus>& status = detector_->status();
  std::vector<std::optional<ModeBaseline>> kept(status.size());
  const auto& configured = config_.faults.baselines;
  const bool estimating = !estimator_.status().warming_up;
  for (std::size_t i = 0; i < status.size(); ++i) {
    const ModeStatus& s = status[i];
    const std::string& name = config_.model.submodels[i].name;
    const bool now_configured = i < configured.size() && configured[i].has_value();
    if (s.baseline_ready && !baseline_configured_[i]) {
      if (!now_configured)
        kept[i] = s.baseline;
      else if (!(*configured[i] == s.baseline.value))
        spdlog::warn("reload: mode '{}': the {} baseline (f = {:.6g} Hz) is replaced by the one in the file", name,
                     s.baseline.learned ? "learned" : "restored", s.baseline.value.wn / (2.0 * std::numbers::pi));
    } else if (s.baseline_ready && !now_configured) {
      spdlog::warn(
          "reload: mode '{}': its configured baseline is gone from the file: learned anew over {} s, no flags "
          "for this mode meanwhile",
          name, config_.faults.learn_window);
    } else if (!s.baseline_ready && !now_configured && estimating) {
      spdlog::warn("reload: mode '{}': the baseline being learned starts again ({} s)", name,
                   config_.faults.learn_window);
    }
    for (int q = 0; q < kQuantities; ++q) {
      const QuantityStatus& qs = s.quantity[static_cast<std::size_t>(q)];
      if (qs.flagged || qs.pending)
        spdlog::warn(
            "reload: mode '{}': a {} flag on {} is cleared; it rises again after its hold time if the "
            "deviation persists",
            name, qs.flagged ? "raised" : "pending",
            q == 0   ? "wn"
            : q == 1 ? "zeta"
                     : "gain");
    }
  }
  set_detector(kept);
}

void EstimationLoop::set_detector(const std::vector<std::optional<ModeBaseline>>& kept) {
  const auto& configured = config_.faults.baselines;
  detector_faults_ = config_.faults;
  baseline_configured_.assign(config_.model.submodels.size(), false);
  for (std::size_t i = 0; i < baseline_configured_.size() && i < configured.size(); ++i)
    baseline_configured_[i] = configured[i].has_value();
  detector_.emplace(make_detector(config_, kept));
}

}  // namespace modalwatch::daemon_detail
