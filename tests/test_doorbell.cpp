// Doorbell: a ring is never lost, a wait ends at its deadline, a sleeping
// waiter is woken, and the daemon's pattern (ring after a ring push, the
// publisher sleeping between snapshots) moves every item with no wait running
// into its deadline. The threaded tests also run under TSan (.ci/run).
#include "daemon/doorbell.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <thread>

#include "daemon/spsc_ring.hpp"

namespace {

using modalwatch::Doorbell;
using modalwatch::SpscRing;
using Clock = std::chrono::steady_clock;

std::int64_t mono_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

constexpr std::int64_t kSecond = 1'000'000'000;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

TEST(Doorbell, ARingBeforeTheWaitIsNotLost) {
  Doorbell bell;
  const std::uint32_t seen = bell.rings();
  bell.ring();
  const auto t0 = Clock::now();
  EXPECT_TRUE(bell.wait_until(seen, mono_ns() + 10 * kSecond));
  EXPECT_LT(seconds_since(t0), 1.0);  // at once, not at the deadline
  EXPECT_EQ(bell.rings(), seen + 1);
}

TEST(Doorbell, AWaitWithoutARingEndsAtItsDeadline) {
  Doorbell bell;
  const std::uint32_t seen = bell.rings();
  const std::int64_t deadline = mono_ns() + 30'000'000;  // 30 ms
  // A spurious futex return is allowed by the contract; callers loop, as here.
  while (mono_ns() < deadline) EXPECT_FALSE(bell.wait_until(seen, deadline));
  EXPECT_GE(mono_ns(), deadline);
}

TEST(Doorbell, ADeadlineInThePastReturnsAtOnce) {
  Doorbell bell;
  const auto t0 = Clock::now();
  EXPECT_FALSE(bell.wait_until(bell.rings(), mono_ns() - kSecond));
  EXPECT_LT(seconds_since(t0), 1.0);
}

TEST(Doorbell, WakesASleepingWaiterLongBeforeItsDeadline) {
  Doorbell bell;
  const std::uint32_t seen = bell.rings();
  bool rung = false;
  double waited = 0.0;
  // Timed from before the thread starts, which a loaded machine delays: the
  // wait cannot end before the ring 50 ms on unless it returned early.
  const auto t0 = Clock::now();
  std::thread waiter([&] {
    rung = bell.wait_until(seen, mono_ns() + 20 * kSecond);
    waited = seconds_since(t0);
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(50));  // let it fall asleep
  bell.ring();
  waiter.join();
  EXPECT_TRUE(rung);
  EXPECT_GE(waited, 0.05);
  EXPECT_LT(waited, 10.0);  // a lost wake-up would wait the full 20 s
}

// The daemon's hand-off: the producer pushes and rings, the consumer reads the
// ring count, drains, and sleeps until the next ring. Producer bursts and pauses
// make the consumer fall asleep often, so a lost wake-up (a ring landing
// between the consumer's last look and its sleep) would show up as a wait that
// runs into its 2 s deadline. Items are checked for order and completeness,
// which also checks that what was written before ring() is seen after the wait.
TEST(DoorbellThreads, EveryItemArrivesWithoutAWaitRunningIntoItsDeadline) {
#if defined(__SANITIZE_THREAD__) || defined(__SANITIZE_ADDRESS__)
  constexpr std::uint64_t kItems = 20'000;
#else
  constexpr std::uint64_t kItems = 200'000;
#endif
  SpscRing<std::uint64_t> ring(64);
  Doorbell bell;
  std::atomic<bool> done{false};
  std::uint64_t received = 0, out_of_order = 0, sleeps = 0, timeouts = 0;
  std::thread consumer([&] {
    std::uint64_t expect = 0;
    for (;;) {
      const std::uint32_t seen = bell.rings();
      const bool finished = done.load(std::memory_order_acquire);
      while (const std::uint64_t* v = ring.front()) {
        if (*v != expect) ++out_of_order;
        expect = *v + 1;
        ++received;
        ring.pop();
      }
      if (finished) break;
      if (timeouts > 0) {  // already failed: finish without sleeping, to report it
        std::this_thread::yield();
        continue;
      }
      ++sleeps;
      // The producer rings far more often than every 2 s, so reaching the
      // deadline is what a lost wake-up looks like, whatever wait_until
      // returns (the ring did happen; the sleeper was not woken). A false
      // return before it is a spurious wake-up, which the contract allows.
      const std::int64_t deadline = mono_ns() + 2 * kSecond;
      bell.wait_until(seen, deadline);
      if (mono_ns() >= deadline) ++timeouts;
    }
  });
  for (std::uint64_t i = 0; i < kItems; ++i) {
    while (!ring.try_push(i)) std::this_thread::yield();
    bell.ring();
    if (i % 997 == 0) std::this_thread::sleep_for(std::chrono::microseconds(50));
  }
  done.store(true, std::memory_order_release);
  bell.ring();
  consumer.join();
  EXPECT_EQ(received, kItems);
  EXPECT_EQ(out_of_order, 0u);
  EXPECT_EQ(timeouts, 0u);
  EXPECT_GT(sleeps, kItems / 997 / 2);  // the consumer did fall asleep, often
}

}  // namespace
