#include "realtime.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/prctl.h>

#include <cerrno>
#include <cstring>

#include "modalwatch/error.hpp"

namespace modalwatch::daemon_detail {

std::int64_t wall_us() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000 + ts.tv_nsec / 1000;
}

void sleep_until(std::int64_t ns) noexcept {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(ns / 1'000'000'000);
  ts.tv_nsec = static_cast<long>(ns % 1'000'000'000);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

void name_this_thread(const char* name) noexcept { pthread_setname_np(pthread_self(), name); }

void minimise_timer_slack() noexcept { prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL); }

int make_realtime(int priority) noexcept {
  if (priority <= 0) return 0;
  sched_param p{};
  p.sched_priority = priority;
  return pthread_setschedparam(pthread_self(), SCHED_FIFO, &p);
}

void check_realtime(int priority, const std::string& source) {
  if (priority <= 0) return;
  const std::string key = "key 'daemon.realtime_priority': ";
  if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0)
    throw InputError(source,
                     key + "mlockall failed (" + std::strerror(errno) + "); under systemd set LimitMEMLOCK=infinity");
  int policy = 0;
  sched_param old{};
  pthread_getschedparam(pthread_self(), &policy, &old);
  if (const int e = make_realtime(priority); e != 0)
    throw InputError(source, key + "SCHED_FIFO at priority " + std::to_string(priority) + " not permitted (" +
                                 std::strerror(e) + "); under systemd set LimitRTPRIO=" + std::to_string(priority) +
                                 " (README.md, \"Running under systemd\"), or grant CAP_SYS_NICE");
  pthread_setschedparam(pthread_self(), policy, &old);  // the control thread stays as it was
}

ScopedRealtime::ScopedRealtime(int priority) noexcept : on_(priority > 0) {
  if (!on_) return;
  sched_param old{};
  pthread_getschedparam(pthread_self(), &policy_, &old);
  old_priority_ = old.sched_priority;
  make_realtime(priority);
}

ScopedRealtime::~ScopedRealtime() {
  if (!on_) return;
  sched_param old{};
  old.sched_priority = old_priority_;
  pthread_setschedparam(pthread_self(), policy_, &old);
}

}  // namespace modalwatch::daemon_detail
