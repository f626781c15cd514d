// modalwatchd's engine: subscriber, estimation loop and publisher (see
// include/modalwatch/daemon.hpp for the shape, DESIGN.md for the rules).
//
// Decisions:
// - Time. The estimator, the fault detector and the publish period run on
//   sample time, t = (utime - utime0) * 1e-6 with utime0 the first sample's,
//   so the daemon gives the estimates `modalwatch track` gives on the same
//   record and replay faster than real time is just faster. Stale input, the
//   heartbeat, the idle fault status and checkpoints run on the wall clock
//   (CLOCK_MONOTONIC).
// - Sequence numbers. A seq at or below the last accepted one is a duplicate
//   (equal) or out of order (below) and is dropped, unless its utime is more
//   than one gap past the last sample: then the sender has restarted (a new
//   replay, a controller reboot) and the sample is taken, and the time gap
//   resets the prefilter states as any gap does.
// - NaN/Inf in u, y or r: counted and not used for estimation, but passed to
//   the estimator, which keeps the sample's time slot (see process()).
// - Gaps. The estimator detects them itself (estimator.gap_factor, which
//   daemon.gap_time sets), so track and the daemon apply one rule; the daemon
//   counts the StepFlags::kGap it reports.
// - The warm-up fit (section 4.7; estimator.warmup) takes seconds on a long
//   window and allocates, so it does not run on the estimation thread: the
//   estimator is built with defer_warmup_fit, and when step() reports the
//   window complete (kWarmupFitPending) the loop hands the WarmupFit job to the
//   fitter thread, which runs it and applies it to the estimator. Meanwhile the
//   estimator belongs to the fitter: the loop keeps ticking (watchdog, fault
//   status from the status it cached) and moves the input from the ring into a
//   backlog preallocated for daemon.warmup_backlog seconds of input (overflow:
//   counted as dropped, logged). Once the fitter has applied the fit (atomic
//   fit_phase, release/acquire), the loop works the backlog off through the
//   usual input policy, within half of each tick, then continues live. The
//   estimates equal those of `modalwatch track`, which runs the same fit inline.
#include "modalwatch/daemon/daemon.hpp"

#include <lcm/lcm.h>
#include <pthread.h>
#include <sched.h>
#include <spdlog/spdlog.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <systemd/sd-daemon.h>
#include <time.h>

#include <array>
#include <atomic>
#include <cmath>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <limits>
#include <numbers>
#include <optional>
#include <stdexcept>
#include <system_error>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <vector>

#include <modalwatch/estimates_t.hpp>
#include <modalwatch/fault_status_t.hpp>
#include <modalwatch/heartbeat_t.hpp>

#include "modalwatch/io/checkpoint.hpp"
#include "doorbell.hpp"
#include "modalwatch/error.hpp"
#include "modalwatch/estimator.hpp"
#include "modalwatch/fault_detector.hpp"
#include "modalwatch/io/messages.hpp"
#include "spsc_ring.hpp"

namespace modalwatch {
namespace {

constexpr int kMaxModes = Daemon::kMaxModes;
constexpr int kMaxEntries = 3 * kMaxModes;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// Largest batch the subscriber decodes (36 + 24 * 8192 bytes, about 200 kB).
constexpr int kMaxBatch = 8192;
constexpr double kRateLogPeriod = 10.0;  // s

using Fault = modalwatch::fault_status_t;

std::int64_t mono_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);  // vDSO: no system call
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::int64_t wall_us() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000 + ts.tv_nsec / 1000;
}

timespec to_timespec(std::int64_t ns) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(ns / 1'000'000'000);
  ts.tv_nsec = static_cast<long>(ns % 1'000'000'000);
  return ts;
}

// Thread names as `top -H`, `ps -L` and /proc/<pid>/task/*/comm show them (at
// most 15 characters), so an engineer can tell which thread takes the CPU.
void name_this_thread(const char* name) noexcept { pthread_setname_np(pthread_self(), name); }

// daemon.realtime_priority: SCHED_FIFO for the calling thread (one of those on
// the latency path). Returns pthread_setschedparam's error: the Daemon's
// constructor checks it once; the threads then know it is permitted.
int make_realtime(int priority) noexcept {
  if (priority <= 0) return 0;
  sched_param p{};
  p.sched_priority = priority;
  return pthread_setschedparam(pthread_self(), SCHED_FIFO, &p);
}

// The calling thread at SCHED_FIFO `priority` for the scope (nothing for 0), then
// back to its policy: LCM (udpm) starts its receive thread, which is on the
// input's latency path too, at the first subscription, and that thread
// inherits the policy of the thread that subscribes.
class ScopedRealtime {
 public:
  explicit ScopedRealtime(int priority) noexcept : on_(priority > 0) {
    if (!on_) return;
    pthread_getschedparam(pthread_self(), &policy_, &param_);
    make_realtime(priority);
  }
  ~ScopedRealtime() {
    if (on_) pthread_setschedparam(pthread_self(), policy_, &param_);
  }
  ScopedRealtime(const ScopedRealtime&) = delete;
  ScopedRealtime& operator=(const ScopedRealtime&) = delete;

 private:
  bool on_;
  int policy_ = SCHED_OTHER;
  sched_param param_{};
};

void sleep_until(std::int64_t ns) noexcept {
  const timespec ts = to_timespec(ns);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

const char* quantity_name(int q) {
  static constexpr const char* names[kQuantities] = {"wn", "zeta", "gain"};
  return names[q];
}


bool finite(const StampedSample& s) { return std::isfinite(s.u) && std::isfinite(s.y) && std::isfinite(s.r); }

// Everything the loop tells the publisher: fixed size, trivially copyable.
struct Snapshot {
  enum Kind : int { estimate = 0, status_only = 1, final_state = 2 };
  int kind = estimate;
  int n_modes = 0;
  std::int64_t utime = 0;     // us, newest sample included (0: none yet)
  std::int64_t last_seq = -1;
  bool have_seq = false;
  bool warming_up = true;
  bool low_excitation = false;
  bool stale = false;
  std::array<ModalParameters, kMaxModes> value{}, std_dev{}, baseline{};
  std::array<std::uint8_t, kMaxModes> baseline_ready{}, baseline_learned{};
  double residual_rms = 0.0;
  std::array<std::int32_t, kMaxEntries> flags{};
  std::array<double, kMaxEntries> deviation_sigma{}, deviation_percent{};
  std::array<std::int64_t, kMaxEntries> since{};
  std::int32_t health = 0;
  DaemonCounters counters;
  const char* reset_reason = "";  // static string from the estimator
  int n_changes = 0;
  std::array<FlagChange, kMaxEntries> changes{};
  std::array<std::int64_t, kMaxEntries> change_utime{};
};
static_assert(std::is_trivially_copyable_v<Snapshot>);

struct AtomicCounters {
  std::atomic<std::uint64_t> samples_received{0}, samples_dropped{0}, decode_errors{0}, samples_nonfinite{0},
      samples_duplicate{0}, samples_out_of_order{0}, samples_processed{0}, gaps{0}, resets{0}, overruns{0},
      samples_held{0}, held_dropped{0},
      snapshots{0}, snapshots_dropped{0}, estimates_published{0}, fault_status_published{0},
      heartbeats_published{0}, flag_changes{0}, checkpoints_written{0}, checkpoint_failures{0};

  DaemonCounters load() const {
    constexpr auto r = std::memory_order_relaxed;
    DaemonCounters c;
    c.samples_received = samples_received.load(r);
    c.samples_dropped = samples_dropped.load(r);
    c.decode_errors = decode_errors.load(r);
    c.samples_nonfinite = samples_nonfinite.load(r);
    c.samples_duplicate = samples_duplicate.load(r);
    c.samples_out_of_order = samples_out_of_order.load(r);
    c.samples_processed = samples_processed.load(r);
    c.gaps = gaps.load(r);
    c.resets = resets.load(r);
    c.overruns = overruns.load(r);
    c.samples_held = samples_held.load(r);
    c.held_dropped = held_dropped.load(r);
    c.snapshots = snapshots.load(r);
    c.snapshots_dropped = snapshots_dropped.load(r);
    c.estimates_published = estimates_published.load(r);
    c.fault_status_published = fault_status_published.load(r);
    c.heartbeats_published = heartbeats_published.load(r);
    c.flag_changes = flag_changes.load(r);
    c.checkpoints_written = checkpoints_written.load(r);
    c.checkpoint_failures = checkpoint_failures.load(r);
    return c;
  }
};

// Counters owned by one thread: a relaxed load + store (no read-modify-write).
inline void bump(std::atomic<std::uint64_t>& c, std::uint64_t n = 1) noexcept {
  c.store(c.load(std::memory_order_relaxed) + n, std::memory_order_relaxed);
}

enum class RunState : int { starting, running, reloading, stopping };

FaultDetectorSettings detector_settings(const Config& c, const std::vector<std::optional<ModalParameters>>& learned) {
  FaultDetectorSettings s;
  for (const auto& sub : c.model.submodels) s.mode_names.push_back(sub.name);
  s.baselines = c.faults.baselines;
  s.baselines.resize(c.model.submodels.size());
  for (std::size_t i = 0; i < s.baselines.size() && i < learned.size(); ++i)
    if (!s.baselines[i] && learned[i]) s.baselines[i] = learned[i];
  s.learn_window = c.faults.learn_window;
  s.thresholds = c.faults.thresholds;
  return s;
}

spdlog::level::level_enum level_of(const std::string& name) { return spdlog::level::from_str(name); }

}  // namespace

namespace {

// The estimator for the config, or, when a matching checkpoint exists, one that
// resumes from it without a warm-up (stand-in restore: modal parameters).
struct Start {
  AdditiveModel model;
  EstimatorSettings settings;
  bool restored = false;
  std::optional<Checkpoint> checkpoint;
};

Start plan_start(const Config& config, std::uint64_t fingerprint) {
  Start st{config.model, config.estimator, false, std::nullopt};
  st.settings.defer_warmup_fit = true;  // the fitter thread runs it (see the top of this file)
  const std::string& path = config.daemon.checkpoint_path;
  if (path.empty()) return st;
  if (!std::filesystem::exists(path)) {
    spdlog::info("checkpoint {}: none yet, starting with the configured model", path);
    return st;
  }
  Checkpoint ck;
  try {
    ck = read_checkpoint(path);
  } catch (const InputError& e) {
    spdlog::warn("checkpoint ignored: {}; starting with a warm-up", e.what());
    return st;
  }
  if (ck.config_fingerprint != fingerprint) {
    spdlog::warn(
        "checkpoint {} was written for another configuration (sample time, loop, controller, model structure or "
        "forgetting differ): ignored, starting with a warm-up",
        path);
    return st;
  }
  if (ck.baselines.size() != config.model.submodels.size()) {
    spdlog::warn("checkpoint {}: {} baselines for {} submodels: ignored", path, ck.baselines.size(),
                 config.model.submodels.size());
    return st;
  }
  st.restored = true;
  st.checkpoint = ck;
  return st;
}

}  // namespace

// ============================================================================

struct Daemon::Impl {
  Impl(const Config& cfg, lcm_t* shared, LoopProbe* p);
  ~Impl();

  // ---- set-up (control thread)
  Config config;
  std::uint64_t fingerprint = 0;
  lcm_t* lcm = nullptr;
  bool owns_lcm = false;
  LoopProbe* probe = nullptr;
  Start plan;  // configured start or checkpoint restore; before `estimator`, which it builds
  std::uint64_t watchdog_usec = 0;

  // ---- subscriber thread
  std::thread subscriber;
  std::atomic<bool> stop_subscriber{false};
  lcm_subscription_t* sub_samples = nullptr;
  lcm_subscription_t* sub_batches = nullptr;
  std::vector<StampedSample> decode_buffer;
  bool closed_loop = false;  // a copy: reload() rewrites `config` while this thread runs
  int realtime_priority = 0;  // daemon.realtime_priority, for every thread (not reloaded)
  std::atomic<int> last_decode_error{0};

  // ---- input ring: subscriber -> estimation loop
  SpscRing<StampedSample> samples;

  // ---- estimation thread (the only thread touching these while it runs)
  std::thread estimation;
  std::atomic<bool> stop_estimation{false};
  std::int64_t tick_origin_ns = 0, tick_period_ns = 0;  // set before the threads start
  RecursiveEstimator estimator;
  std::optional<FaultDetector> detector;
  std::vector<ModalParameters> det_value, det_std;
  std::vector<FlagChange> det_changes;
  bool have_seq = false;
  std::int64_t last_seq = -1;
  bool have_time = false;      // utime0 set (a sample since start)
  bool have_ref_time = false;  // last_utime is meaningful (a sample, or a restored checkpoint)
  std::int64_t utime0 = 0, last_utime = 0;
  std::int64_t next_publish_utime = 0;
  std::int64_t publish_period_us = 0, gap_us = 0;
  std::int64_t last_sample_ns = 0, last_snapshot_ns = 0;
  std::int64_t last_watchdog_ns = 0;
  std::int32_t pending_health = 0;
  std::uint64_t dropped_at_snapshot = 0, decode_errors_at_snapshot = 0;
  bool probe_fired = false;
  Snapshot scratch;  // built here, copied into the ring
  // While the fitter owns the estimator (fit_in_flight), the loop reports this
  // status and holds the input in `backlog`, a FIFO preallocated at start-up.
  bool fit_in_flight = false;
  EstimatorStatus status_before_fit;
  std::vector<StampedSample> backlog;
  std::size_t backlog_head = 0, backlog_size = 0;

  // ---- the warm-up fit: estimation loop -> fitter thread and back
  enum FitPhase : int { fit_idle = 0, fit_requested = 1, fit_applied = 2 };
  std::atomic<int> fit_phase{fit_idle};  // releases fit_job and the estimator to the other side
  WarmupFit fit_job;
  std::thread fitter;
  std::atomic<bool> stop_fitter{false};
  Doorbell fitter_bell;  // rung with a fit request, and to stop
  std::atomic<std::int64_t> fit_duration_ns{0};  // for the log

  // ---- output ring: estimation loop -> publisher, and the bell the loop rings
  // after each push (the publisher sleeps on it between snapshots)
  SpscRing<Snapshot> snapshots;
  Doorbell publisher_bell;

  // ---- publisher thread
  std::thread publisher;
  std::atomic<bool> stop_publisher{false};
  std::vector<std::uint8_t> encode_buffer;
  std::int64_t next_heartbeat_ns = 0, next_rate_log_ns = 0;
  DaemonCounters rate_base;
  std::int64_t rate_base_ns = 0;
  bool logged_warmup_over = false, logged_stale = false;
  std::uint64_t logged_held_dropped = 0;
  std::array<bool, kMaxModes> logged_baseline{};

  // ---- shared
  AtomicCounters counters;
  std::atomic<int> state{static_cast<int>(RunState::starting)};
  std::atomic<bool> warming_up{true};
  std::int64_t start_ns = 0;

  // subscriber
  static void on_sample_packet(const lcm_recv_buf_t* rbuf, const char* channel, void* user);
  static void on_batch_packet(const lcm_recv_buf_t* rbuf, const char* channel, void* user);
  void on_packet(const lcm_recv_buf_t* rbuf, bool batch) noexcept;
  void subscriber_main();

  // estimation
  void estimation_main() noexcept;
  void drain(std::int64_t now) noexcept;
  void process(const StampedSample& s) noexcept;
  void hold(const StampedSample& s) noexcept;
  void catch_up(std::int64_t deadline_ns) noexcept;
  void push_snapshot(int kind, std::int64_t now, bool update_detector) noexcept;
  void fitter_main();

  // publisher
  void publisher_main();
  void handle(const Snapshot& s);
  void publish_estimates(const Snapshot& s);
  void publish_fault_status(const Snapshot& s);
  void publish_heartbeat(std::int64_t now);
  void log_snapshot(const Snapshot& s);
  void log_rates(std::int64_t now);
  // checkpoints (control side): the estimation thread is paused for the copy
  std::thread checkpointer;
  std::mutex control;  // serialises reload(), stop() and the checkpointer's pauses
  std::mutex wake_mutex;
  std::condition_variable wake_checkpointer;
  bool stop_checkpointer = false;  // under wake_mutex
  void checkpointer_main();
  std::optional<Checkpoint> capture();  // estimation thread stopped
  bool write(const std::string& path, const Checkpoint& ck, bool final_one);
  void start_estimation();
  void stop_estimation_thread();

  void start_threads(bool with_subscriber);
  void stop_threads(bool with_subscriber);
  bool running = false;

};


Daemon::Impl::Impl(const Config& cfg, lcm_t* shared, LoopProbe* p)
    : config(cfg),
      fingerprint(checkpoint_fingerprint(cfg)),
      probe(p),
      plan(plan_start(cfg, fingerprint)),
      samples(static_cast<std::size_t>(cfg.daemon.sample_ring)),
      estimator(plan.model, plan.settings),
      snapshots(static_cast<std::size_t>(cfg.daemon.snapshot_ring)) {
  const int K = static_cast<int>(config.model.submodels.size());
  if (K > kMaxModes)
    throw InputError(config.source, "model.submodels: the daemon carries at most " + std::to_string(kMaxModes) +
                                        " submodels (this model has " + std::to_string(K) + ")");
  std::vector<std::optional<ModalParameters>> restored_baselines;
  if (plan.checkpoint) {
    try {
      estimator.restore(plan.checkpoint->estimator);  // no warm-up; the prefilters restart as after a gap
    } catch (const std::invalid_argument& e) {
      spdlog::warn("checkpoint {} does not fit the estimator ({}): starting with a warm-up",
                   config.daemon.checkpoint_path, e.what());
      plan.checkpoint.reset();
      plan.restored = false;
    }
  }
  if (plan.checkpoint) {
    restored_baselines = plan.checkpoint->baselines;
    have_seq = true;
    have_ref_time = true;
    last_seq = plan.checkpoint->last_seq;
    last_utime = plan.checkpoint->last_utime;
    spdlog::info("restored checkpoint {}: last sample utime {} us, seq {}; no warm-up", config.daemon.checkpoint_path,
                 last_utime, last_seq);
  }
  if (estimator.status().warming_up) {
    // Touched here (value-initialised), so that holding input never page-faults on the loop.
    const double held = std::ceil(config.daemon.warmup_backlog / config.sample_time);
    backlog.resize(static_cast<std::size_t>(std::max(1.0, held)));
  }
  detector.emplace(detector_settings(config, restored_baselines));
  det_value.resize(static_cast<std::size_t>(K));
  det_std.resize(static_cast<std::size_t>(K));
  det_changes.reserve(static_cast<std::size_t>(3 * K));
  decode_buffer.resize(kMaxBatch);
  closed_loop = config.closed_loop;
  realtime_priority = config.daemon.realtime_priority;
  if (config.daemon.realtime_priority > 0) {
    // Here, where it can fail loudly, rather than in the threads; and before the
    // LCM instance exists, which a throwing constructor would leak.
    const std::string key = "key 'daemon.realtime_priority': ";
    if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0)
      throw InputError(config.source, key + "mlockall failed (" + std::strerror(errno) +
                                          "); under systemd set LimitMEMLOCK=infinity");
    int policy = 0;
    sched_param old{};
    pthread_getschedparam(pthread_self(), &policy, &old);
    if (const int e = make_realtime(config.daemon.realtime_priority); e != 0)
      throw InputError(config.source, key + "SCHED_FIFO at priority " +
                                          std::to_string(config.daemon.realtime_priority) + " not permitted (" +
                                          std::strerror(e) + "); under systemd set LimitRTPRIO=" +
                                          std::to_string(config.daemon.realtime_priority) +
                                          " (README.md, \"Running under systemd\"), or grant CAP_SYS_NICE");
    pthread_setschedparam(pthread_self(), policy, &old);  // the control thread stays as it was
  }
  encode_buffer.reserve(4096);
  if (shared) {
    lcm = shared;
  } else {
    lcm = lcm_create(config.lcm.url.c_str());
    if (!lcm)
      throw InputError(config.source, "key 'lcm.url': cannot open LCM provider '" + config.lcm.url +
                                          "' (a udpm:// URL needs a multicast route, e.g. "
                                          "'ip route add 224.0.0.0/4 dev lo')");
    owns_lcm = true;
  }
  start_ns = mono_ns();
}

Daemon::Impl::~Impl() {
  if (owns_lcm && lcm) lcm_destroy(lcm);
}

// ---------------------------------------------------------------- subscriber

void Daemon::Impl::on_sample_packet(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  static_cast<Impl*>(user)->on_packet(rbuf, false);
}
void Daemon::Impl::on_batch_packet(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  static_cast<Impl*>(user)->on_packet(rbuf, true);
}

void Daemon::Impl::on_packet(const lcm_recv_buf_t* rbuf, bool batch) noexcept {
  int n = 0;
  const int size = rbuf->data_size > static_cast<std::uint32_t>(std::numeric_limits<int>::max())
                       ? std::numeric_limits<int>::max()
                       : static_cast<int>(rbuf->data_size);
  const DecodeResult r =
      batch ? decode_batch(rbuf->data, size, closed_loop, decode_buffer.data(), kMaxBatch, n)
            : decode_sample(rbuf->data, size, closed_loop, decode_buffer.data(), kMaxBatch, n);
  if (r != DecodeResult::ok) {
    bump(counters.decode_errors);
    last_decode_error.store(static_cast<int>(r), std::memory_order_relaxed);
    return;
  }
  bump(counters.samples_received, static_cast<std::uint64_t>(n));
  std::uint64_t dropped = 0;
  for (int i = 0; i < n; ++i)
    if (!samples.try_push(decode_buffer[static_cast<std::size_t>(i)])) ++dropped;
  if (dropped) bump(counters.samples_dropped, dropped);
}

void Daemon::Impl::subscriber_main() {
  name_this_thread("mw-subscribe");
  make_realtime(realtime_priority);
  while (!stop_subscriber.load(std::memory_order_acquire)) {
    if (lcm_handle_timeout(lcm, 20) < 0) {
      spdlog::error("lcm_handle failed; retrying in 100 ms");
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  }
}

// ---------------------------------------------------------------- estimation loop

void Daemon::Impl::estimation_main() noexcept {
  // Linux delays a sleeping thread's wake-up by up to its timer slack (50 us by
  // default) to batch timers: too much for a 0.1..1 ms tick. Set at start-up.
  prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
  name_this_thread("mw-estimate");
  make_realtime(realtime_priority);
  const std::int64_t period_ns = tick_period_ns;
  std::int64_t tick = 0;  // ticks at tick_origin_ns + k period_ns
  for (;;) {
    const bool stopping = stop_estimation.load(std::memory_order_acquire);
    // Final stop (not a pause for a checkpoint or reload): a running warm-up fit
    // is waited for, ticking as usual, and the backlog is worked off in full.
    const bool final_stop = stopping && state.load(std::memory_order_relaxed) == static_cast<int>(RunState::stopping);
    if (fit_in_flight && fit_phase.load(std::memory_order_acquire) == fit_applied) {
      fit_in_flight = false;  // the estimator is ours again
      fit_phase.store(fit_idle, std::memory_order_relaxed);
    }
    if (probe && !probe_fired && !fit_in_flight && backlog_size == 0 && !estimator.status().warming_up &&
        counters.snapshots.load(std::memory_order_relaxed) > 0) {
      probe->warmed_up();
      probe_fired = true;
    }
    std::int64_t now = mono_ns();
    catch_up(final_stop ? std::numeric_limits<std::int64_t>::max() : now + period_ns / 2);
    drain(now);
    // Without input, the fault status still goes out (with the stale flag).
    if (now - last_snapshot_ns >= static_cast<std::int64_t>(config.daemon.publish_period * 1e9))
      push_snapshot(Snapshot::status_only, now, false);
    if (watchdog_usec > 0 && now - last_watchdog_ns >= static_cast<std::int64_t>(watchdog_usec) * 500) {
      sd_notify(0, "WATCHDOG=1");
      last_watchdog_ns = now;
    }
    if (stopping && !(final_stop && fit_in_flight)) {
      drain(mono_ns());
      if (final_stop) catch_up(std::numeric_limits<std::int64_t>::max());
      push_snapshot(Snapshot::final_state, mono_ns(), false);
      break;
    }
    ++tick;
    now = mono_ns();
    if (now > tick_origin_ns + tick * period_ns) {  // this tick ended after the next one was due
      bump(counters.overruns);
      tick = (now - tick_origin_ns) / period_ns + 1;  // the next tick on the grid
    }
    sleep_until(tick_origin_ns + tick * period_ns);
  }
  if (probe) probe->exiting();
}

void Daemon::Impl::drain(std::int64_t now) noexcept {
  const std::size_t limit = samples.capacity();
  std::size_t n = 0;
  while (n < limit) {
    const StampedSample* s = samples.front();
    if (!s) break;
    if (fit_in_flight || backlog_size > 0) hold(*s);  // behind the backlog, in order
    else process(*s);
    samples.pop();
    ++n;
  }
  if (n > 0) last_sample_ns = now;
}

// A sample that arrives while the warm-up fit runs or the backlog is worked off.
void Daemon::Impl::hold(const StampedSample& s) noexcept {
  if (backlog_size == backlog.size()) {  // daemon.warmup_backlog too small for this fit
    bump(counters.held_dropped);
    bump(counters.samples_dropped);
    return;
  }
  backlog[(backlog_head + backlog_size) % backlog.size()] = s;
  ++backlog_size;
  bump(counters.samples_held);
}

// The held samples, oldest first, until `deadline_ns` (checked per sample: a
// step is a few microseconds), so that a catch-up does not cost the loop its tick.
void Daemon::Impl::catch_up(std::int64_t deadline_ns) noexcept {
  while (!fit_in_flight && backlog_size > 0) {
    process(backlog[backlog_head]);
    backlog_head = (backlog_head + 1) % backlog.size();
    --backlog_size;
    if (mono_ns() >= deadline_ns) break;
  }
}

void Daemon::Impl::process(const StampedSample& s) noexcept {
  if (have_seq && s.seq <= last_seq && !(have_ref_time && s.utime > last_utime + gap_us)) {
    bump(s.seq == last_seq ? counters.samples_duplicate : counters.samples_out_of_order);
    return;
  }
  have_seq = true;
  last_seq = s.seq;
  if (!have_time) {
    have_time = true;
    utime0 = s.utime;
    next_publish_utime = s.utime + publish_period_us;
  } else if (s.utime <= last_utime) {
    // A later seq with an earlier (or equal) time: the estimator would reject it too.
    bump(counters.samples_out_of_order);
    return;
  }
  last_utime = s.utime;
  have_ref_time = true;
  const double t = static_cast<double>(s.utime - utime0) * 1e-6;
  // A non-finite sample goes to the estimator too, which keeps its time slot
  // (holds u and r, lets the model stand in for y, does not update): dropping it
  // here would leave a hole of 2 T that resets the prefilters as a gap.
  const unsigned flags = estimator.step(Sample{t, s.u, s.y, s.r});
  bump(finite(s) ? counters.samples_processed : counters.samples_nonfinite);
  if (flags & kWarmupFitPending) {
    // The window is complete: the fitter takes the job and, until it has applied
    // it, the estimator (take_warmup_fit moves the window: no allocation here).
    status_before_fit = estimator.status();
    fit_job = estimator.take_warmup_fit();
    fit_in_flight = true;
    fit_phase.store(fit_requested, std::memory_order_release);
    fitter_bell.ring();  // once per warm-up
  }
  if (flags & kGap) {
    bump(counters.gaps);
    pending_health |= Fault::HEALTH_INPUT_GAP;
  }
  if (flags & kReset) {
    bump(counters.resets);
    pending_health |= Fault::HEALTH_ESTIMATOR_RESET;
  }
  if (s.utime >= next_publish_utime) {
    push_snapshot(Snapshot::estimate, mono_ns(), true);
    next_publish_utime += publish_period_us;
    if (next_publish_utime <= s.utime) next_publish_utime = s.utime + publish_period_us;
  }
}

void Daemon::Impl::push_snapshot(int kind, std::int64_t now, bool update_detector) noexcept {
  Snapshot& snap = scratch;
  const int K = static_cast<int>(det_value.size());
  // During the warm-up fit the estimator is the fitter's: the cached status and
  // the last values stand in (flags are suppressed while warming up anyway).
  const EstimatorStatus& st = fit_in_flight ? status_before_fit : estimator.status();
  snap.kind = kind;
  snap.n_modes = K;
  snap.utime = have_ref_time ? last_utime : 0;
  snap.last_seq = last_seq;
  snap.have_seq = have_seq;
  snap.warming_up = st.warming_up;
  snap.low_excitation = st.low_excitation;
  warming_up.store(st.warming_up, std::memory_order_relaxed);
  for (int i = 0; i < K && !fit_in_flight; ++i) {
    const ModeEstimate m = estimator.mode(i);
    det_value[static_cast<std::size_t>(i)] = m.value;
    det_std[static_cast<std::size_t>(i)] = m.std;
    snap.value[static_cast<std::size_t>(i)] = m.value;
    snap.std_dev[static_cast<std::size_t>(i)] = m.std;
  }
  if (!fit_in_flight) snap.residual_rms = estimator.residual_rms();
  const bool valid = !st.warming_up && !st.low_excitation;
  snap.n_changes = 0;
  if (update_detector) {
    det_changes.clear();
    const double t = static_cast<double>(last_utime - utime0) * 1e-6;
    detector->update(t, det_value, det_std, valid, det_changes);  // capacity reserved: no allocation
    for (const FlagChange& c : det_changes) {
      if (snap.n_changes == kMaxEntries) break;
      snap.changes[static_cast<std::size_t>(snap.n_changes)] = c;
      snap.change_utime[static_cast<std::size_t>(snap.n_changes)] = utime0 + std::llround(c.time * 1e6);
      ++snap.n_changes;
    }
    if (snap.n_changes) bump(counters.flag_changes, static_cast<std::uint64_t>(snap.n_changes));
  }
  const auto& modes = detector->status();
  for (int i = 0; i < K; ++i) {
    const ModeStatus& m = modes[static_cast<std::size_t>(i)];
    snap.baseline_ready[static_cast<std::size_t>(i)] = m.baseline_ready;
    snap.baseline_learned[static_cast<std::size_t>(i)] = m.baseline.learned;
    snap.baseline[static_cast<std::size_t>(i)] = m.baseline.value;
    for (int q = 0; q < kQuantities; ++q) {
      const QuantityStatus& qs = m.quantity[static_cast<std::size_t>(q)];
      const auto e = static_cast<std::size_t>(3 * i + q);
      std::int32_t f = 0;
      if (qs.flagged) f |= Fault::FLAG_RAISED;
      if (qs.pending) f |= Fault::FLAG_PENDING;
      if (qs.deviation_sigma < 0.0 || qs.deviation_relative < 0.0) f |= Fault::FLAG_LOW;
      if (!valid) f |= Fault::FLAG_SUPPRESSED;
      snap.flags[e] = f;
      snap.deviation_sigma[e] = qs.deviation_sigma;
      snap.deviation_percent[e] = 100.0 * qs.deviation_relative;
      snap.since[e] = (qs.flagged || qs.pending) ? utime0 + std::llround(qs.since * 1e6) : 0;
    }
  }
  std::int32_t health = pending_health;
  pending_health = 0;
  if (st.low_excitation) health |= Fault::HEALTH_LOW_EXCITATION;
  const std::int64_t since_input = now - (last_sample_ns ? last_sample_ns : start_ns);
  snap.stale = since_input > static_cast<std::int64_t>(config.daemon.stale_time * 1e9);
  if (snap.stale) health |= Fault::HEALTH_STALE_INPUT;
  const std::uint64_t dropped = counters.samples_dropped.load(std::memory_order_relaxed);
  const std::uint64_t decode_errors = counters.decode_errors.load(std::memory_order_relaxed);
  if (dropped != dropped_at_snapshot) health |= Fault::HEALTH_RING_OVERFLOW;
  if (decode_errors != decode_errors_at_snapshot) health |= Fault::HEALTH_DECODE_ERRORS;
  dropped_at_snapshot = dropped;
  decode_errors_at_snapshot = decode_errors;
  snap.health = health;
  snap.reset_reason = st.last_reset_reason;
  bump(counters.snapshots);
  snap.counters = counters.load();
  if (snapshots.try_push(snap)) publisher_bell.ring();
  else bump(counters.snapshots_dropped);
  last_snapshot_ns = now;
}

// ---------------------------------------------------------------- fitter

// The warm-up fit off the estimation thread (see the top of this file). Sleeps
// on its doorbell, which the loop rings once per warm-up (it used to poll every
// 2 ms: 500 wake-ups a second for the daemon's whole life).
void Daemon::Impl::fitter_main() {
  name_this_thread("mw-fit");
  for (;;) {
    const std::uint32_t seen = fitter_bell.rings();
    if (stop_fitter.load(std::memory_order_acquire)) break;
    if (fit_phase.load(std::memory_order_acquire) != fit_requested) {
      fitter_bell.wait_until(seen, std::numeric_limits<std::int64_t>::max());
      continue;
    }
    const std::int64_t t0 = mono_ns();
    spdlog::info("warm-up window complete ({} samples): fitting on the fitter thread; input is held meanwhile",
                 fit_job.samples());
    if (probe) probe->warmup_fit_running();
    fit_job.run();
    try {
      estimator.apply_warmup_fit(std::move(fit_job));
    } catch (const std::exception& e) {
      spdlog::error("the warm-up fit could not be applied ({}): the warm-up starts again", e.what());
    }
    fit_job = WarmupFit();  // the fit's buffers are freed here, not on the loop
    fit_duration_ns.store(mono_ns() - t0, std::memory_order_relaxed);
    fit_phase.store(fit_applied, std::memory_order_release);
  }
}

// ---------------------------------------------------------------- publisher

void Daemon::Impl::publisher_main() {
  prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);  // as in estimation_main
  name_this_thread("mw-publish");
  make_realtime(realtime_priority);
  for (;;) {
    // Read before looking at the ring: a snapshot pushed after the look rings
    // the bell past `seen`, and the wait below returns at once.
    const std::uint32_t seen = publisher_bell.rings();
    const bool stopping = stop_publisher.load(std::memory_order_acquire);
    while (const Snapshot* s = snapshots.front()) {
      handle(*s);
      snapshots.pop();
    }
    const std::int64_t now = mono_ns();
    if (now >= next_heartbeat_ns) {
      publish_heartbeat(now);
      next_heartbeat_ns = now + static_cast<std::int64_t>(config.daemon.heartbeat_period * 1e9);
    }
    if (now >= next_rate_log_ns) {
      log_rates(now);
      next_rate_log_ns = now + static_cast<std::int64_t>(kRateLogPeriod * 1e9);
    }
    if (stopping) break;
    publisher_bell.wait_until(seen, std::min(next_heartbeat_ns, next_rate_log_ns));
  }
}

void Daemon::Impl::handle(const Snapshot& s) {
  if (s.kind == Snapshot::estimate) publish_estimates(s);
  if (s.kind != Snapshot::final_state || s.n_changes) publish_fault_status(s);
  log_snapshot(s);
}

void Daemon::Impl::publish_estimates(const Snapshot& s) {
  modalwatch::estimates_t msg;
  msg.utime = s.utime;
  msg.n_modes = s.n_modes;
  msg.modes.resize(static_cast<std::size_t>(s.n_modes));
  for (int i = 0; i < s.n_modes; ++i) {
    const auto k = static_cast<std::size_t>(i);
    auto& m = msg.modes[k];
    m.name = config.model.submodels[k].name;
    m.wn = s.value[k].wn;
    m.hz = s.value[k].wn / (2.0 * std::numbers::pi);
    m.zeta = s.value[k].zeta;
    m.gain = s.value[k].gain;
    m.wn_std = s.std_dev[k].wn;
    m.zeta_std = s.std_dev[k].zeta;
    m.gain_std = s.std_dev[k].gain;
    m.baseline_wn = s.baseline_ready[k] ? s.baseline[k].wn : kNaN;
    m.baseline_zeta = s.baseline_ready[k] ? s.baseline[k].zeta : kNaN;
    m.baseline_gain = s.baseline_ready[k] ? s.baseline[k].gain : kNaN;
  }
  msg.residual_rms = s.residual_rms;
  msg.samples_processed = static_cast<std::int64_t>(s.counters.samples_processed);
  encode_buffer.resize(static_cast<std::size_t>(msg.getEncodedSize()));
  msg.encode(encode_buffer.data(), 0, static_cast<int>(encode_buffer.size()));
  if (lcm_publish(lcm, config.lcm.estimates_channel.c_str(), encode_buffer.data(),
                  static_cast<unsigned>(encode_buffer.size())) == 0)
    bump(counters.estimates_published);
}

void Daemon::Impl::publish_fault_status(const Snapshot& s) {
  Fault msg;
  msg.utime = s.utime;
  msg.n_modes = s.n_modes;
  msg.n_entries = 3 * s.n_modes;
  for (int i = 0; i < s.n_modes; ++i) msg.mode_names.push_back(config.model.submodels[static_cast<std::size_t>(i)].name);
  const auto n = static_cast<std::size_t>(msg.n_entries);
  msg.flags.assign(s.flags.begin(), s.flags.begin() + static_cast<std::ptrdiff_t>(n));
  msg.deviation_sigma.assign(s.deviation_sigma.begin(), s.deviation_sigma.begin() + static_cast<std::ptrdiff_t>(n));
  msg.deviation_percent.assign(s.deviation_percent.begin(),
                               s.deviation_percent.begin() + static_cast<std::ptrdiff_t>(n));
  msg.since.assign(s.since.begin(), s.since.begin() + static_cast<std::ptrdiff_t>(n));
  msg.health = s.health;
  const DaemonCounters& c = s.counters;
  msg.samples_received = static_cast<std::int64_t>(c.samples_received);
  msg.samples_dropped = static_cast<std::int64_t>(c.samples_dropped);
  msg.samples_nonfinite = static_cast<std::int64_t>(c.samples_nonfinite);
  msg.samples_duplicate = static_cast<std::int64_t>(c.samples_duplicate);
  msg.samples_out_of_order = static_cast<std::int64_t>(c.samples_out_of_order);
  msg.gaps = static_cast<std::int64_t>(c.gaps);
  msg.decode_errors = static_cast<std::int64_t>(c.decode_errors);
  msg.resets = static_cast<std::int64_t>(c.resets);
  encode_buffer.resize(static_cast<std::size_t>(msg.getEncodedSize()));
  msg.encode(encode_buffer.data(), 0, static_cast<int>(encode_buffer.size()));
  if (lcm_publish(lcm, config.lcm.fault_status_channel.c_str(), encode_buffer.data(),
                  static_cast<unsigned>(encode_buffer.size())) == 0)
    bump(counters.fault_status_published);
}

void Daemon::Impl::publish_heartbeat(std::int64_t now) {
  modalwatch::heartbeat_t msg;
  msg.utime = wall_us();
  switch (static_cast<RunState>(state.load(std::memory_order_relaxed))) {
    case RunState::starting: msg.state = "starting"; break;
    case RunState::reloading: msg.state = "reloading"; break;
    case RunState::stopping: msg.state = "stopping"; break;
    case RunState::running: msg.state = warming_up.load(std::memory_order_relaxed) ? "warming_up" : "running"; break;
  }
  msg.uptime_us = (now - start_ns) / 1000;
  encode_buffer.resize(static_cast<std::size_t>(msg.getEncodedSize()));
  msg.encode(encode_buffer.data(), 0, static_cast<int>(encode_buffer.size()));
  if (lcm_publish(lcm, config.lcm.heartbeat_channel.c_str(), encode_buffer.data(),
                  static_cast<unsigned>(encode_buffer.size())) == 0)
    bump(counters.heartbeats_published);
}

void Daemon::Impl::log_snapshot(const Snapshot& s) {
  for (int k = 0; k < s.n_changes; ++k) {
    const FlagChange& c = s.changes[static_cast<std::size_t>(k)];
    const std::string& name = config.model.submodels[static_cast<std::size_t>(c.mode)].name;
    const int q = static_cast<int>(c.quantity);
    if (c.raised)
      spdlog::warn("FLAG RAISED: mode '{}' {}: {:.6g} vs baseline {:.6g} ({:+.2f} %, {:+.1f} sigma) at utime {}", name,
                   quantity_name(q), c.value, c.baseline, 100.0 * c.deviation_relative, c.deviation_sigma,
                   s.change_utime[static_cast<std::size_t>(k)]);
    else
      spdlog::info("flag cleared: mode '{}' {}: {:.6g} vs baseline {:.6g} ({:+.2f} %) at utime {}", name,
                   quantity_name(q), c.value, c.baseline, 100.0 * c.deviation_relative,
                   s.change_utime[static_cast<std::size_t>(k)]);
  }
  if (s.health & Fault::HEALTH_ESTIMATOR_RESET)
    spdlog::warn("estimator reset to its last good state ({}); {} resets so far", s.reset_reason, s.counters.resets);
  if (s.health & Fault::HEALTH_INPUT_GAP)
    spdlog::warn("input gap: prefilter states reset (parameters kept); {} gaps so far", s.counters.gaps);
  if (!logged_warmup_over && !s.warming_up && s.counters.samples_processed > 0) {
    logged_warmup_over = true;
    if (plan.restored)
      spdlog::info("estimating from the restored checkpoint (no warm-up)");
    else
      spdlog::info("warm-up over after {} samples; estimating (the fit took {:.2f} s; {} samples held meanwhile)",
                   s.counters.samples_processed,
                   static_cast<double>(fit_duration_ns.load(std::memory_order_relaxed)) * 1e-9,
                   s.counters.samples_held);
  }
  if (s.counters.held_dropped != logged_held_dropped) {
    logged_held_dropped = s.counters.held_dropped;
    spdlog::warn("{} samples dropped while the warm-up fit ran: daemon.warmup_backlog ({} s) is too short for it",
                 s.counters.held_dropped, config.daemon.warmup_backlog);
  }
  for (int i = 0; i < s.n_modes; ++i) {
    const auto k = static_cast<std::size_t>(i);
    if (s.baseline_ready[k] && !logged_baseline[k]) {
      logged_baseline[k] = true;
      spdlog::info("baseline of mode '{}' ({}): f = {:.6g} Hz, zeta = {:.4g}, gain = {:.6g}",
                   config.model.submodels[k].name, s.baseline_learned[k] ? "learned" : "configured or restored",
                   s.baseline[k].wn / (2.0 * std::numbers::pi), s.baseline[k].zeta, s.baseline[k].gain);
    }
  }
  if (s.stale != logged_stale) {
    logged_stale = s.stale;
    if (s.stale)
      spdlog::warn("stale input: no sample for more than {} s", config.daemon.stale_time);
    else
      spdlog::info("input resumed");
  }
}

void Daemon::Impl::log_rates(std::int64_t now) {
  const DaemonCounters c = counters.load();
  if (rate_base_ns != 0) {
    const double dt = static_cast<double>(now - rate_base_ns) * 1e-9;
    const auto rate = [dt](std::uint64_t a, std::uint64_t b) { return static_cast<double>(a - b) / dt; };
    spdlog::info(
        "rates over {:.1f} s: {:.0f} samples/s in, {:.0f} processed, {:.1f} estimates/s; since start: {} dropped "
        "(ring full), {} decode errors, {} non-finite, {} duplicate, {} out of order, {} gaps, {} resets, {} "
        "overruns",
        dt, rate(c.samples_received, rate_base.samples_received), rate(c.samples_processed, rate_base.samples_processed),
        rate(c.estimates_published, rate_base.estimates_published), c.samples_dropped, c.decode_errors,
        c.samples_nonfinite, c.samples_duplicate, c.samples_out_of_order, c.gaps, c.resets, c.overruns);
  }
  rate_base = c;
  rate_base_ns = now;
}

// ---------------------------------------------------------------- checkpoints

// The state to resume from. The estimation thread must be stopped: its
// variables and the estimator are read here (and, with the io branch's
// EstimatorState, state() allocates, which the estimation thread must not).
// While a warm-up fit is out (only the stopped loop could have started one)
// the estimator is the fitter's, and there is nothing worth keeping yet.
std::optional<Checkpoint> Daemon::Impl::capture() {
  if (fit_phase.load(std::memory_order_acquire) != fit_idle) return std::nullopt;
  if (!have_seq || estimator.status().warming_up) return std::nullopt;
  Checkpoint ck;
  ck.config_fingerprint = fingerprint;
  ck.last_utime = last_utime;
  ck.last_seq = last_seq;
  ck.estimator = estimator.state();
  for (int i = 0; i < estimator.submodels(); ++i) {
    const ModeStatus& m = detector->status()[static_cast<std::size_t>(i)];
    ck.baselines.push_back(m.baseline_ready ? std::optional<ModalParameters>(m.baseline.value) : std::nullopt);
  }
  return ck;
}

// `path` is passed in, read under the control lock: a SIGHUP reload may change
// config while the checkpointer writes.
bool Daemon::Impl::write(const std::string& path, const Checkpoint& ck, bool final_one) {
  try {
    modalwatch::write_checkpoint(path, ck);
    bump(counters.checkpoints_written);
    if (final_one)
      spdlog::info("checkpoint written: {} (last seq {})", path, ck.last_seq);
    else
      spdlog::debug("checkpoint written: {} (last seq {})", path, ck.last_seq);
    return true;
  } catch (const std::system_error& e) {
    bump(counters.checkpoint_failures);
    spdlog::error("checkpoint NOT written ({}): {}; the previous one is kept, the service continues", path,
                  e.what());
    return false;
  }
}

// Every checkpoint period: pause the estimation loop (join it: the input ring
// holds what arrives meanwhile), copy the state, restart the loop, then write
// the file off the estimation path.
void Daemon::Impl::checkpointer_main() {
  name_this_thread("mw-checkpoint");
  for (;;) {
    double period = 0.0;
    {
      std::lock_guard<std::mutex> lock(control);
      period = config.daemon.checkpoint_period;
    }
    {
      std::unique_lock<std::mutex> lock(wake_mutex);
      if (wake_checkpointer.wait_for(lock, std::chrono::duration<double>(period), [this] { return stop_checkpointer; })) return;
    }
    std::optional<Checkpoint> ck;
    std::string path;
    {
      std::lock_guard<std::mutex> lock(control);
      if (!running || config.daemon.checkpoint_path.empty()) continue;
      path = config.daemon.checkpoint_path;
      stop_estimation_thread();
      ck = capture();
      start_estimation();
    }
    if (ck) write(path, *ck, false);
  }
}

// ---------------------------------------------------------------- threads

void Daemon::Impl::start_threads(bool with_subscriber) {
  publish_period_us = std::max<std::int64_t>(1, std::llround(config.daemon.publish_period * 1e6));
  gap_us = std::llround(config.estimator.gap_factor * config.sample_time * 1e6);
  if (have_time) next_publish_utime = last_utime + publish_period_us;
  tick_period_ns =
      std::max<std::int64_t>(10'000, static_cast<std::int64_t>(std::llround(1e9 / config.daemon.loop_rate_hz)));
  tick_origin_ns = mono_ns();
  stop_publisher.store(false);
  publisher = std::thread([this] { publisher_main(); });
  start_estimation();
  if (with_subscriber) {
    stop_subscriber.store(false);
    {
      const ScopedRealtime rt(realtime_priority);  // for LCM's receive thread, started here
      sub_samples = lcm_subscribe(lcm, config.lcm.samples_channel.c_str(), &Impl::on_sample_packet, this);
      sub_batches = lcm_subscribe(lcm, config.lcm.batches_channel.c_str(), &Impl::on_batch_packet, this);
    }
    if (!sub_samples || !sub_batches) throw std::runtime_error("lcm_subscribe failed");
    // LCM's default of 30 queued packets per subscription drops bursts before we see them.
    lcm_subscription_set_queue_capacity(sub_samples, 100000);
    lcm_subscription_set_queue_capacity(sub_batches, 10000);
    subscriber = std::thread([this] { subscriber_main(); });
  }
  running = true;
}

void Daemon::Impl::stop_threads(bool with_subscriber) {
  if (with_subscriber && subscriber.joinable()) {
    stop_subscriber.store(true, std::memory_order_release);
    subscriber.join();
    if (sub_samples) lcm_unsubscribe(lcm, sub_samples);
    if (sub_batches) lcm_unsubscribe(lcm, sub_batches);
    sub_samples = sub_batches = nullptr;
  }
  stop_estimation_thread();
  if (publisher.joinable()) {
    stop_publisher.store(true, std::memory_order_release);
    publisher_bell.ring();
    publisher.join();
  }
}

void Daemon::Impl::start_estimation() {
  stop_estimation.store(false);
  estimation = std::thread([this] { estimation_main(); });
}

void Daemon::Impl::stop_estimation_thread() {
  if (!estimation.joinable()) return;
  stop_estimation.store(true, std::memory_order_release);
  estimation.join();
}

// ============================================================================

Daemon::Daemon(const Config& config, lcm_t* lcm, LoopProbe* probe)
    : impl_(std::make_unique<Impl>(config, lcm, probe)) {}

Daemon::~Daemon() { stop(); }

void Daemon::start() {
  Impl& m = *impl_;
  if (m.running) return;
  int wd = sd_watchdog_enabled(0, &m.watchdog_usec);
  if (wd <= 0) m.watchdog_usec = 0;
  const Config& c = m.config;
  spdlog::info(
      "modalwatchd: {} ({}), {} submodels at {} Hz, {} loop; LCM {} in: {} / {}, out: {} / {} / {}; loop {} Hz, "
      "publish every {} s, heartbeat every {} s; rings {} samples / {} snapshots; checkpoint {}; {}{}",
      c.source, m.plan.restored ? "resumed from checkpoint" : "fresh start", c.model.submodels.size(), 1.0 / c.sample_time,
      c.closed_loop ? "closed" : "open", c.lcm.url, c.lcm.samples_channel, c.lcm.batches_channel,
      c.lcm.estimates_channel, c.lcm.fault_status_channel, c.lcm.heartbeat_channel, c.daemon.loop_rate_hz,
      c.daemon.publish_period, c.daemon.heartbeat_period, c.daemon.sample_ring, c.daemon.snapshot_ring,
      c.daemon.checkpoint_path.empty() ? std::string("off")
                                       : c.daemon.checkpoint_path + " every " +
                                             std::to_string(c.daemon.checkpoint_period) + " s",
      m.plan.restored ? "no warm-up"
                      : "warm-up " + std::to_string(c.estimator.warmup_samples) + " samples (fit off the loop, " +
                            std::to_string(m.backlog.size()) + " samples held at most)",
      (m.watchdog_usec ? ", systemd watchdog " + std::to_string(m.watchdog_usec / 1000) + " ms" : std::string()) +
          (c.daemon.realtime_priority > 0 ? ", SCHED_FIFO " + std::to_string(c.daemon.realtime_priority) + " + mlockall"
                                          : std::string()));
  {
    std::lock_guard<std::mutex> lock(m.control);
    // Before the loop runs: after that only it and the fitter touch the estimator.
    if (m.estimator.status().warming_up && !m.fitter.joinable()) {
      m.stop_fitter.store(false);
      m.fitter = std::thread([&m] { m.fitter_main(); });
    }
    m.start_threads(true);
  }
  {
    std::lock_guard<std::mutex> lock(m.wake_mutex);
    m.stop_checkpointer = false;
  }
  m.checkpointer = std::thread([&m] { m.checkpointer_main(); });
  m.state.store(static_cast<int>(RunState::running));
}

void Daemon::stop() {
  Impl& m = *impl_;
  if (!m.running) return;
  m.state.store(static_cast<int>(RunState::stopping));
  {
    std::lock_guard<std::mutex> lock(m.wake_mutex);
    m.stop_checkpointer = true;
  }
  m.wake_checkpointer.notify_all();
  if (m.checkpointer.joinable()) m.checkpointer.join();
  std::lock_guard<std::mutex> lock(m.control);
  m.stop_threads(true);  // the loop waits for a running warm-up fit and works off the backlog
  if (m.fitter.joinable()) {
    m.stop_fitter.store(true, std::memory_order_release);
    m.fitter_bell.ring();
    m.fitter.join();
  }
  m.running = false;
  const DaemonCounters c = m.counters.load();
  spdlog::info("stopped: {} samples received, {} processed, {} dropped, {} decode errors, {} flag changes",
               c.samples_received, c.samples_processed, c.samples_dropped, c.decode_errors, c.flag_changes);
}

std::string Daemon::reload(const Config& next) {
  Impl& m = *impl_;
  std::vector<std::string> kept;
  if (checkpoint_fingerprint(next) != m.fingerprint)
    kept.emplace_back("model structure/loop/controller/forgetting (the running estimator continues; restart to apply)");
  {
    // The estimator sections, compared as config_to_yaml writes them.
    const auto section = [](const Config& c) {
      const std::string y = config_to_yaml(c, c.model);
      const auto a = y.find("\nestimator:"), b = y.find("\nlcm:");
      return y.substr(a, b - a);
    };
    if (section(next) != section(m.config) || next.estimator.random_walks != m.config.estimator.random_walks)
      kept.emplace_back("estimator settings");
  }
  if (next.lcm.url != m.config.lcm.url || next.lcm.samples_channel != m.config.lcm.samples_channel ||
      next.lcm.batches_channel != m.config.lcm.batches_channel ||
      next.lcm.estimates_channel != m.config.lcm.estimates_channel ||
      next.lcm.fault_status_channel != m.config.lcm.fault_status_channel ||
      next.lcm.heartbeat_channel != m.config.lcm.heartbeat_channel)
    kept.emplace_back("LCM URL/channels");
  if (next.daemon.sample_ring != m.config.daemon.sample_ring || next.daemon.snapshot_ring != m.config.daemon.snapshot_ring ||
      next.daemon.warmup_backlog != m.config.daemon.warmup_backlog)
    kept.emplace_back("ring sizes");
  if (next.daemon.realtime_priority != m.config.daemon.realtime_priority) kept.emplace_back("realtime priority");

  std::lock_guard<std::mutex> control_lock(m.control);
  m.state.store(static_cast<int>(RunState::reloading));
  const bool was_running = m.running;
  if (was_running) m.stop_threads(false);  // the subscriber keeps filling the input ring
  // Learned baselines survive; configured ones come from the new file.
  std::vector<std::optional<ModalParameters>> learned(m.config.model.submodels.size());
  for (std::size_t i = 0; i < learned.size(); ++i) {
    const ModeStatus& s = m.detector->status()[i];
    if (s.baseline_ready && s.baseline.learned) learned[i] = s.baseline.value;
  }
  Config applied = m.config;  // keeps model, estimator, LCM and rings
  applied.daemon.loop_rate_hz = next.daemon.loop_rate_hz;
  applied.daemon.publish_period = next.daemon.publish_period;
  applied.daemon.heartbeat_period = next.daemon.heartbeat_period;
  applied.daemon.stale_time = next.daemon.stale_time;
  applied.daemon.checkpoint_path = next.daemon.checkpoint_path;
  applied.daemon.checkpoint_period = next.daemon.checkpoint_period;
  applied.daemon.log_level = next.daemon.log_level;
  if (m.fingerprint == checkpoint_fingerprint(next)) applied.faults = next.faults;
  else {
    applied.faults.thresholds = next.faults.thresholds;
    applied.faults.learn_window = next.faults.learn_window;
  }
  m.config = applied;
  m.detector.emplace(detector_settings(m.config, learned));
  spdlog::set_level(level_of(m.config.daemon.log_level));
  if (was_running) m.start_threads(false);
  m.state.store(static_cast<int>(RunState::running));
  std::string summary = "reloaded " + next.source + ": applied rates (loop " +
                        std::to_string(m.config.daemon.loop_rate_hz) + " Hz, publish " +
                        std::to_string(m.config.daemon.publish_period) + " s), fault thresholds, learn window, "
                        "baselines, checkpoint, log level " + m.config.daemon.log_level +
                        " (flags restart their hold timers)";
  if (!kept.empty()) {
    summary += "; NOT applied, restart the service for: ";
    for (std::size_t i = 0; i < kept.size(); ++i) summary += (i ? ", " : "") + kept[i];
  }
  return summary;
}

bool Daemon::write_checkpoint() {
  Impl& m = *impl_;
  if (m.running) throw std::logic_error("Daemon::write_checkpoint: call after stop()");
  if (m.config.daemon.checkpoint_path.empty()) return true;
  const std::optional<Checkpoint> ck = m.capture();
  if (!ck) {
    spdlog::info("checkpoint skipped: the estimator is still warming up (no estimate worth keeping)");
    return true;
  }
  return m.write(m.config.daemon.checkpoint_path, *ck, true);
}

DaemonCounters Daemon::counters() const { return impl_->counters.load(); }
bool Daemon::restored_from_checkpoint() const { return impl_->plan.restored; }
bool Daemon::warming_up() const { return impl_->warming_up.load(std::memory_order_relaxed); }
const Config& Daemon::config() const { return impl_->config; }

}  // namespace modalwatch
