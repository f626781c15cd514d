// SpscRing: single-thread semantics, then a producer and a consumer thread
// hammering it (lossless with back-off, and lossy with drop counting). The
// threaded tests are the ones scripts/check/sanitize.sh runs under TSan.
//
// Stress size: MODALWATCH_STRESS_ITEMS (environment) if set, else 10 million,
// scaled down automatically under TSan and ASan.
#include "daemon/spsc_ring.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>
#include <thread>
#include <type_traits>
#include <vector>

// ---- sanitizer detection (GCC defines the macros, clang answers __has_feature) ----
#if defined(__SANITIZE_THREAD__)
#define MODALWATCH_TEST_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define MODALWATCH_TEST_TSAN 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__)
#define MODALWATCH_TEST_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define MODALWATCH_TEST_ASAN 1
#endif
#endif

// clang links its sanitizer runtimes statically, with their own operator new and
// delete, so the counter below cannot replace them there (duplicate symbols).
#if defined(__clang__) && (defined(MODALWATCH_TEST_TSAN) || defined(MODALWATCH_TEST_ASAN))
#define MODALWATCH_TEST_COUNT_ALLOCATIONS 0
#else
#define MODALWATCH_TEST_COUNT_ALLOCATIONS 1
#endif

// ---- heap allocation counter for this binary ----------------------------------
// Replaces the global operator new/delete (plain and over-aligned) to count
// allocations, so a test can show that the ring allocates only in its constructor.
// Not inlinable, so GCC does not pair free() in them with operator new at a call
// site (-Wmismatched-new-delete).
namespace {
std::atomic<std::uint64_t> g_allocations{0};
}  // namespace

#if MODALWATCH_TEST_COUNT_ALLOCATIONS
namespace {
void* counted_alloc(std::size_t size, std::size_t align) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (size == 0) {
    size = 1;
  }
  void* p = nullptr;
  if (align <= alignof(std::max_align_t)) {
    p = std::malloc(size);
  } else {
    size = (size + align - 1) / align * align;  // aligned_alloc wants a multiple
    p = std::aligned_alloc(align, size);
  }
  if (p == nullptr) {
    throw std::bad_alloc();
  }
  return p;
}
}  // namespace

[[gnu::noinline]] void* operator new(std::size_t size) { return counted_alloc(size, 0); }
[[gnu::noinline]] void* operator new[](std::size_t size) { return counted_alloc(size, 0); }
[[gnu::noinline]] void* operator new(std::size_t size, std::align_val_t al) {
  return counted_alloc(size, static_cast<std::size_t>(al));
}
[[gnu::noinline]] void* operator new[](std::size_t size, std::align_val_t al) {
  return counted_alloc(size, static_cast<std::size_t>(al));
}
[[gnu::noinline]] void operator delete(void* p) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete[](void* p) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete(void* p, std::size_t) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
#endif

namespace modalwatch {
namespace {

// ---- element types ---------------------------------------------------------------

// Shaped like the daemon's input sample.
struct Sample {
  std::int64_t utime;
  std::uint64_t seq;
  double u;
  double y;
  double r;
  char tag[8];
};
static_assert(std::is_trivially_copyable_v<Sample>);

// Trivially copyable, not an aggregate: for try_emplace with constructor arguments
// (clang 14 has no parenthesised aggregate initialisation).
struct Point {
  constexpr Point() noexcept = default;
  constexpr Point(int x_, int y_) noexcept : x(x_), y(y_) {}
  int x = 0;
  int y = 0;
};
static_assert(std::is_trivially_copyable_v<Point>);

// Spans several words and a whole cache line, so a slot read before all of it has
// been published shows up as an inconsistent payload (and as a race under TSan).
struct Payload {
  std::uint64_t seq;
  std::uint64_t inverted;   // ~seq
  double half;              // seq * 0.5
  std::uint32_t words[10];  // seq + k
};
static_assert(sizeof(Payload) >= 64);

Payload make_payload(std::uint64_t seq) {
  Payload p{};
  p.seq = seq;
  p.inverted = ~seq;
  p.half = static_cast<double>(seq) * 0.5;
  for (std::uint32_t k = 0; k < 10; ++k) {
    p.words[k] = static_cast<std::uint32_t>(seq) + k;
  }
  return p;
}

bool consistent(const Payload& p) {
  if (p.inverted != ~p.seq || p.half != static_cast<double>(p.seq) * 0.5) {
    return false;
  }
  for (std::uint32_t k = 0; k < 10; ++k) {
    if (p.words[k] != static_cast<std::uint32_t>(p.seq) + k) {
      return false;
    }
  }
  return true;
}

// ---- single thread ---------------------------------------------------------------

TEST(SpscRingBasics, LayoutSeparatesTheIndicesByAFalseSharingRange) {
  EXPECT_EQ(alignof(SpscRing<char>), kFalseSharingRange);
  EXPECT_EQ(sizeof(SpscRing<char>), 3 * kFalseSharingRange);
  EXPECT_EQ(sizeof(SpscRing<Payload>), 3 * kFalseSharingRange);
  auto heap = std::make_unique<SpscRing<int>>(4);  // over-aligned new
  EXPECT_EQ(reinterpret_cast<std::uintptr_t>(heap.get()) % kFalseSharingRange, 0u);
}

TEST(SpscRingBasics, ZeroCapacityIsRejected) {
  EXPECT_THROW(SpscRing<int>(0), std::invalid_argument);
  EXPECT_THROW(SpscRing<int>(static_cast<std::size_t>(-1)), std::length_error);
}

TEST(SpscRingBasics, NewRingIsEmpty) {
  SpscRing<int> ring(8);
  EXPECT_EQ(ring.capacity(), 8u);
  EXPECT_EQ(ring.size(), 0u);
  EXPECT_TRUE(ring.empty());
  EXPECT_EQ(ring.front(), nullptr);
  int out = -1;
  EXPECT_FALSE(ring.try_pop(out));
  EXPECT_EQ(out, -1);
}

TEST(SpscRingBasics, FullAtCapacityForPowerOfTwoAndOtherSizes) {
  for (std::size_t capacity : {1u, 2u, 3u, 5u, 8u, 1000u, 1024u}) {
    SCOPED_TRACE("capacity " + std::to_string(capacity));
    SpscRing<std::uint64_t> ring(capacity);
    for (std::uint64_t i = 0; i < capacity; ++i) {
      ASSERT_TRUE(ring.try_push(i));
      EXPECT_EQ(ring.size(), i + 1);
    }
    EXPECT_FALSE(ring.try_push(999999));
    EXPECT_FALSE(ring.try_push(999999));
    EXPECT_EQ(ring.size(), capacity);
    EXPECT_FALSE(ring.empty());
    // A refused push changed nothing; one pop frees exactly one slot.
    ASSERT_NE(ring.front(), nullptr);
    EXPECT_EQ(*ring.front(), 0u);
    ring.pop();
    EXPECT_EQ(ring.size(), capacity - 1);
    EXPECT_TRUE(ring.try_push(capacity));
    EXPECT_FALSE(ring.try_push(999999));
    for (std::uint64_t i = 1; i <= capacity; ++i) {
      std::uint64_t out = 0;
      ASSERT_TRUE(ring.try_pop(out));
      EXPECT_EQ(out, i);
    }
    EXPECT_TRUE(ring.empty());
    EXPECT_EQ(ring.front(), nullptr);
  }
}

TEST(SpscRingBasics, FifoOrder) {
  SpscRing<int> ring(16);
  for (int i = 0; i < 10; ++i) {
    ASSERT_TRUE(ring.try_push(i * i));
  }
  for (int i = 0; i < 10; ++i) {
    int* p = ring.front();
    ASSERT_NE(p, nullptr);
    EXPECT_EQ(*p, i * i);
    ring.pop();
  }
  EXPECT_EQ(ring.front(), nullptr);
}

TEST(SpscRingBasics, FrontStaysPutWhileTheProducerFillsTheRing) {
  SpscRing<int> ring(4);
  ASSERT_TRUE(ring.try_push(7));
  const int* p = ring.front();
  ASSERT_NE(p, nullptr);
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE(ring.try_push(100 + i));
  }
  EXPECT_FALSE(ring.try_push(-1));
  EXPECT_EQ(ring.front(), p);
  EXPECT_EQ(*p, 7);
  ring.pop();
  EXPECT_EQ(*ring.front(), 100);
}

TEST(SpscRingBasics, WrapsAroundManyTimes) {
  // Capacity 7 (8 slots): every fill level from 0 to full at every start offset.
  SpscRing<std::uint64_t> ring(7);
  std::uint64_t next_in = 0;
  std::uint64_t next_out = 0;
  for (int round = 0; round < 20000; ++round) {
    const std::size_t burst = static_cast<std::size_t>(round) % 8;  // 0..7
    for (std::size_t k = 0; k < burst; ++k) {
      ASSERT_TRUE(ring.try_push(next_in++));
    }
    ASSERT_EQ(ring.size(), burst);
    if (burst == 7) {
      ASSERT_FALSE(ring.try_push(0));
    }
    // Leave one behind on odd rounds, so the offsets drift relative to the bursts.
    const std::size_t take = (round % 2 == 1 && burst > 0) ? burst - 1 : burst;
    for (std::size_t k = 0; k < take; ++k) {
      std::uint64_t out = 0;
      ASSERT_TRUE(ring.try_pop(out));
      ASSERT_EQ(out, next_out++);
    }
    while (ring.size() > 0) {  // drain the leftover
      std::uint64_t out = 0;
      ASSERT_TRUE(ring.try_pop(out));
      ASSERT_EQ(out, next_out++);
    }
  }
  EXPECT_EQ(next_in, next_out);
  EXPECT_EQ(next_in, 70000u);  // 2500 cycles of 0+1+...+7: the 8 slots wrapped 8750 times
}

TEST(SpscRingBasics, HoldsStructs) {
  SpscRing<Sample> ring(3);
  for (std::uint64_t i = 0; i < 3; ++i) {
    Sample s{static_cast<std::int64_t>(1000 + i), i, 0.5 * i, -1.0 * i, 2.0 * i, "abc"};
    s.tag[3] = static_cast<char>('0' + i);
    ASSERT_TRUE(ring.try_push(s));
  }
  EXPECT_FALSE(ring.try_push(Sample{}));
  for (std::uint64_t i = 0; i < 3; ++i) {
    Sample s{};
    ASSERT_TRUE(ring.try_pop(s));
    EXPECT_EQ(s.utime, static_cast<std::int64_t>(1000 + i));
    EXPECT_EQ(s.seq, i);
    EXPECT_EQ(s.u, 0.5 * i);
    EXPECT_EQ(s.y, -1.0 * i);
    EXPECT_EQ(s.r, 2.0 * i);
    EXPECT_EQ(std::string(s.tag, 4), std::string("abc") + static_cast<char>('0' + i));
  }

  SpscRing<Point> points(2);
  EXPECT_TRUE(points.try_emplace(1, 2));
  EXPECT_TRUE(points.try_emplace());
  EXPECT_FALSE(points.try_emplace(5, 6));
  EXPECT_EQ(points.front()->x, 1);
  EXPECT_EQ(points.front()->y, 2);
  points.pop();
  EXPECT_EQ(points.front()->x, 0);
}

TEST(SpscRingBasics, AllocatesOnlyInTheConstructor) {
  if (!MODALWATCH_TEST_COUNT_ALLOCATIONS) {
    GTEST_SKIP() << "operator new cannot be replaced under clang's sanitizer runtimes";
  }
  const std::uint64_t before = g_allocations.load();
  SpscRing<Payload> ring(100);
  const std::uint64_t after_construction = g_allocations.load();
  EXPECT_EQ(after_construction - before, 1u);
  std::uint64_t sum = 0;
  for (std::uint64_t i = 0; i < 100000; ++i) {
    (void)ring.try_push(make_payload(i));
    if (i % 3 != 0) {
      Payload p{};
      if (ring.try_pop(p)) {
        sum += p.seq;
      }
    }
    sum += ring.size();
  }
  while (const Payload* p = ring.front()) {
    sum += p->seq;
    ring.pop();
  }
  EXPECT_EQ(g_allocations.load(), after_construction);
  EXPECT_GT(sum, 0u);
}

// ---- two threads -----------------------------------------------------------------

std::uint64_t stress_items() {
  if (const char* env = std::getenv("MODALWATCH_STRESS_ITEMS")) {
    const unsigned long long n = std::strtoull(env, nullptr, 10);
    if (n > 0) {
      return n;
    }
  }
#if defined(MODALWATCH_TEST_TSAN)
  return 1'000'000;
#elif defined(MODALWATCH_TEST_ASAN)
  return 2'000'000;
#else
  return 10'000'000;
#endif
}

// Spins briefly, then gives the core away: on a two-core machine running other
// work the other side may not be scheduled at all while we spin.
class Backoff {
 public:
  void wait() {
    if (++spins_ < 64) {
      return;
    }
    spins_ = 0;
    std::this_thread::yield();
  }
  void reset() { spins_ = 0; }

 private:
  int spins_ = 0;
};

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

TEST(SpscRingThreads, LosslessStrictSequenceUnderBackoff) {
  const std::uint64_t n = stress_items();
  SpscRing<std::uint64_t> ring(1000);  // not a power of two, small: fills and empties often
  std::uint64_t producer_full_waits = 0;
  std::uint64_t consumer_empty_waits = 0;
  std::uint64_t first_bad_index = 0;
  std::uint64_t first_bad_value = 0;
  bool bad = false;
  std::size_t max_size_seen = 0;

  const auto t0 = std::chrono::steady_clock::now();
  std::thread producer([&] {
    Backoff backoff;
    for (std::uint64_t i = 0; i < n; ++i) {
      while (!ring.try_push(i)) {
        ++producer_full_waits;
        backoff.wait();
      }
      backoff.reset();
    }
  });
  std::thread consumer([&] {
    Backoff backoff;
    std::uint64_t expected = 0;
    while (expected < n) {
      std::uint64_t value = 0;
      if (!ring.try_pop(value)) {
        ++consumer_empty_waits;
        backoff.wait();
        continue;
      }
      backoff.reset();
      if (value != expected) {  // lost, duplicated or reordered
        bad = true;
        first_bad_index = expected;
        first_bad_value = value;
        return;
      }
      if ((expected & 1023) == 0) {
        const std::size_t s = ring.size();
        max_size_seen = s > max_size_seen ? s : max_size_seen;
      }
      ++expected;
    }
  });
  producer.join();
  consumer.join();
  const double seconds = seconds_since(t0);

  EXPECT_FALSE(bad) << "expected " << first_bad_index << ", popped " << first_bad_value;
  EXPECT_TRUE(ring.empty());
  EXPECT_LE(max_size_seen, ring.capacity());
  std::printf("  %llu items in %.3f s (%.1f M/s); producer full-waits %llu, consumer empty-waits %llu\n",
              static_cast<unsigned long long>(n), seconds, n / seconds / 1e6,
              static_cast<unsigned long long>(producer_full_waits),
              static_cast<unsigned long long>(consumer_empty_waits));
  RecordProperty("items", std::to_string(n));
  RecordProperty("seconds", std::to_string(seconds));
}

TEST(SpscRingThreads, DroppingProducerCountsEveryLostItem) {
  const std::uint64_t n = stress_items();
  SpscRing<Payload> ring(256);
  std::atomic<bool> first_drop{false};
  std::atomic<bool> producer_done{false};
  std::uint64_t dropped = 0;   // producer's; read after join
  std::uint64_t received = 0;  // consumer's; read after join
  bool bad_order = false;
  bool bad_payload = false;
  std::uint64_t last_seq = 0;

  const auto t0 = std::chrono::steady_clock::now();
  std::thread producer([&] {
    // Items arrive in packets of 1..400 (the ring holds 256), pushed back to back
    // without ever waiting on the ring: a refused push is a counted drop, as in the
    // daemon's subscriber. Between packets the producer paces itself to the
    // consumer (as if the next packet had not arrived yet) except on every 16th,
    // so most items get through and bursts overflow. The first packet is twice the
    // capacity and the consumer starts only after a drop, so drops are certain.
    std::uint64_t rng = 0x9E3779B97F4A7C15ull;
    Backoff backoff;
    std::uint64_t i = 0;
    for (std::uint64_t packet = 0; i < n; ++packet) {
      rng = rng * 6364136223846793005ull + 1442695040888963407ull;
      const std::uint64_t len = packet == 0 ? 2 * ring.capacity() : 1 + (rng >> 33) % 400;
      for (std::uint64_t k = 0; k < len && i < n; ++k, ++i) {
        if (!ring.try_push(make_payload(i))) {
          ++dropped;
          if (dropped == 1) {
            first_drop.store(true, std::memory_order_release);
          }
        }
      }
      if (packet % 16 != 15) {
        while (ring.size() > ring.capacity() / 4) {
          backoff.wait();
        }
        backoff.reset();
      }
    }
    producer_done.store(true, std::memory_order_release);
  });
  std::thread consumer([&] {
    // Start only once the producer has hit a full ring, so drops are certain.
    Backoff backoff;
    while (!first_drop.load(std::memory_order_acquire) && !producer_done.load(std::memory_order_acquire)) {
      backoff.wait();
    }
    bool have_last = false;
    for (;;) {
      const Payload* p = ring.front();
      if (p == nullptr) {
        // Everything pushed before producer_done is visible after it; look once more.
        if (producer_done.load(std::memory_order_acquire)) {
          p = ring.front();
          if (p == nullptr) {
            return;
          }
        } else {
          backoff.wait();
          continue;
        }
      }
      backoff.reset();
      if (!consistent(*p)) {
        bad_payload = true;
      }
      if (have_last && p->seq <= last_seq) {
        bad_order = true;
      }
      last_seq = p->seq;
      have_last = true;
      ring.pop();
      ++received;
      if ((received & ((1u << 20) - 1)) == 0) {
        // Fall behind now and then, so drops also happen mid-stream.
        std::this_thread::sleep_for(std::chrono::microseconds(50));
      }
    }
  });
  producer.join();
  consumer.join();
  const double seconds = seconds_since(t0);

  EXPECT_FALSE(bad_payload) << "a popped slot was not the element pushed into it";
  EXPECT_FALSE(bad_order) << "received sequence not strictly increasing";
  EXPECT_EQ(received + dropped, n);
  EXPECT_GE(dropped, 1u);
  EXPECT_GE(received, 1u);
  EXPECT_LT(last_seq, n);
  EXPECT_TRUE(ring.empty());
  std::printf("  %llu produced in %.3f s: %llu received, %llu dropped\n", static_cast<unsigned long long>(n), seconds,
              static_cast<unsigned long long>(received), static_cast<unsigned long long>(dropped));
  RecordProperty("items", std::to_string(n));
  RecordProperty("dropped", std::to_string(dropped));
  RecordProperty("seconds", std::to_string(seconds));
}

}  // namespace
}  // namespace modalwatch
