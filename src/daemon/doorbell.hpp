#pragma once
// A doorbell: one thread tells another "there is something for you" without
// either of them polling. The daemon's estimation loop rings it when it has
// pushed a snapshot into the publisher's ring; the publisher sleeps on it
// until then (or until its next heartbeat is due).
//
//   Doorbell bell;
//   // ringing thread (after its data is visible, e.g. a ring push)
//   bell.ring();
//   // waiting thread
//   const auto seen = bell.rings();      // before looking for data
//   ... consume everything there is ...
//   bell.wait_until(seen, deadline_ns);  // returns at once if rung since `seen`
//
// Contract
// - Any number of ringers, one waiter at a time. A ring after `rings()` was
//   read is never lost: wait_until returns at once. wait_until may also return
//   early (a signal, a spurious futex wake-up): callers re-check their data.
// - ring() never blocks and never allocates. It costs a system call (a futex
//   wake) only when the waiter is asleep or about to sleep; otherwise it is two
//   atomic operations. That is why the publisher sleeps here instead of
//   waking every loop tick to look: at a 10 kHz loop those 10,000 wake-ups a
//   second were most of the daemon's CPU, and each one competes with the
//   latency path for the cores.
// - ring() happens-before the return of a wait_until that it ends (release /
//   acquire on the counter), so data written before ring() is visible after.
//
// Design
// - `count_` is the futex word: ring() increments it, and FUTEX_WAIT sleeps
//   only while it still equals `seen` (checked by the kernel atomically with
//   going to sleep), so a ring between the waiter's last look and its sleep
//   makes the sleep return at once.
// - `sleeping_` saves the ringer the system call when nobody sleeps. The
//   waiter stores it, then reads count_; the ringer increments count_, then
//   reads sleeping_; all four are sequentially consistent, so at least one
//   side sees the other (Dekker): either the waiter sees the new count and
//   does not sleep, or the ringer sees the waiter and wakes it.
// - The deadline is absolute on CLOCK_MONOTONIC (FUTEX_WAIT_BITSET), like the
//   daemon's tick, so a long wait does not drift.
#include <linux/futex.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>

namespace modalwatch {

class Doorbell {
 public:
  Doorbell() = default;
  Doorbell(const Doorbell&) = delete;
  Doorbell& operator=(const Doorbell&) = delete;

  void ring() noexcept {
    count_.fetch_add(1, std::memory_order_seq_cst);
    if (sleeping_.load(std::memory_order_seq_cst))
      syscall(SYS_futex, futex_word(), FUTEX_WAKE_PRIVATE, 1, nullptr, nullptr, 0);
  }

  // The number of rings so far; pass it to wait_until.
  std::uint32_t rings() const noexcept { return count_.load(std::memory_order_acquire); }

  // Sleeps until a ring after `seen`, or until `deadline_ns` on CLOCK_MONOTONIC.
  // True when rung (also when the ring came before the call).
  bool wait_until(std::uint32_t seen, std::int64_t deadline_ns) noexcept {
    sleeping_.store(true, std::memory_order_seq_cst);
    if (count_.load(std::memory_order_seq_cst) == seen) {
      timespec ts{};
      ts.tv_sec = static_cast<time_t>(deadline_ns / 1'000'000'000);
      ts.tv_nsec = static_cast<long>(deadline_ns % 1'000'000'000);
      syscall(SYS_futex, futex_word(), FUTEX_WAIT_BITSET_PRIVATE, seen, &ts, nullptr, FUTEX_BITSET_MATCH_ANY);
    }
    sleeping_.store(false, std::memory_order_relaxed);
    return count_.load(std::memory_order_acquire) != seen;
  }

 private:
  // The futex system call takes the 32-bit word itself.
  std::uint32_t* futex_word() noexcept { return reinterpret_cast<std::uint32_t*>(&count_); }
  static_assert(sizeof(std::atomic<std::uint32_t>) == sizeof(std::uint32_t));
  static_assert(std::atomic<std::uint32_t>::is_always_lock_free);

  std::atomic<std::uint32_t> count_{0};
  std::atomic<bool> sleeping_{false};
};

}  // namespace modalwatch
