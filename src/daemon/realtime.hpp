#pragma once
// Clocks and real-time scheduling for the daemon's threads. The estimation loop
// calls mono_ns() and sleep_until() every tick: neither allocates nor locks, and
// mono_ns() is no system call (vDSO).
#include <time.h>

#include <cstdint>
#include <string>

namespace modalwatch::daemon_detail {

inline std::int64_t mono_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// Wall-clock time in microseconds since the epoch (heartbeat_t.utime).
std::int64_t wall_us() noexcept;

// Absolute-time sleep on CLOCK_MONOTONIC, resumed after a signal, so that the
// loop's tick grid does not drift with the time each tick takes.
void sleep_until(std::int64_t ns) noexcept;

// Thread names as `top -H`, `ps -L` and /proc/<pid>/task/*/comm show them (at
// most 15 characters), so an engineer can tell which thread takes the CPU.
void name_this_thread(const char* name) noexcept;

// Linux delays a sleeping thread's wake-up by up to its timer slack (50 us by
// default) to batch timers: too much for a 0.1..1 ms tick. Call at thread start.
void minimise_timer_slack() noexcept;

// daemon.realtime_priority: SCHED_FIFO for the calling thread (nothing for 0).
// Returns pthread_setschedparam's error; check_realtime() has made sure at
// start-up that it is permitted, so the threads ignore it.
int make_realtime(int priority) noexcept;

// For daemon.realtime_priority > 0: mlockall and a trial of SCHED_FIFO at that
// priority on the calling thread (then restored), so that a missing permission
// fails loudly at start-up rather than in a thread. Throws InputError naming
// the key (`source` is the config file).
void check_realtime(int priority, const std::string& source);

// The calling thread at SCHED_FIFO `priority` for the scope (nothing for 0), then
// back to its policy: LCM (udpm) starts its receive thread, which is on the
// input's latency path too, at the first subscription, and that thread
// inherits the policy of the thread that subscribes.
class ScopedRealtime {
 public:
  explicit ScopedRealtime(int priority) noexcept;
  ~ScopedRealtime();
  ScopedRealtime(const ScopedRealtime&) = delete;
  ScopedRealtime& operator=(const ScopedRealtime&) = delete;

 private:
  bool on_;
  int policy_ = 0;
  int old_priority_ = 0;
};

}  // namespace modalwatch::daemon_detail
