// Acceptance 4: no heap allocation on the daemon's estimation thread after
// start-up. The Daemon runs in process on memq:// over the drifting flexible
// beam (warm-up, baseline learning, a fault flag rising) and with bad input
// mixed in (NaN, duplicates, reordering, a gap); a LoopProbe starts counting on
// the estimation thread once the warm-up is over and stops when the loop exits.
//
// Counting as in test_allocation.cpp: every global operator new/delete is
// replaced, and (outside sanitizer builds) malloc & co. are interposed, since
// Eigen allocates with malloc. Counts are per thread (thread_local flag), so
// the subscriber and publisher threads, which may allocate, do not count.
#include <atomic>
#include <cstdlib>
#include <new>

#include "daemon_support.hpp"

#include "modalwatch/daemon.hpp"

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__) || defined(__SANITIZE_MEMORY__)
#define MODALWATCH_INTERPOSE_MALLOC 0
#else
#define MODALWATCH_INTERPOSE_MALLOC 1
#endif

namespace {
thread_local bool t_counting = false;
thread_local std::uint64_t t_allocations = 0;
inline void note() {
  if (t_counting) ++t_allocations;
}
}  // namespace

#if MODALWATCH_INTERPOSE_MALLOC
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);
void __libc_free(void*);
void* malloc(std::size_t size) noexcept {
  note();
  return __libc_malloc(size);
}
void* calloc(std::size_t n, std::size_t size) noexcept {
  note();
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t size) noexcept {
  note();
  return __libc_realloc(p, size);
}
void free(void* p) noexcept { __libc_free(p); }
void* aligned_alloc(std::size_t alignment, std::size_t size) noexcept {
  note();
  return __libc_memalign(alignment, size);
}
int posix_memalign(void** out, std::size_t alignment, std::size_t size) noexcept {
  note();
  void* p = __libc_memalign(alignment, size);
  if (!p) return 12;
  *out = p;
  return 0;
}
}
#define RAW_MALLOC __libc_malloc
#define RAW_FREE __libc_free
#define RAW_MEMALIGN __libc_memalign
#else
[[gnu::noinline]] void raw_free(void* p) noexcept { std::free(p); }
#define RAW_MALLOC std::malloc
#define RAW_FREE raw_free
#define RAW_MEMALIGN(a, s) std::aligned_alloc((a), ((s) + (a) - 1) / (a) * (a))
#endif

void* operator new(std::size_t n) {
  note();
  if (void* p = RAW_MALLOC(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) {
  note();
  if (void* p = RAW_MALLOC(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  note();
  return RAW_MALLOC(n ? n : 1);
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  note();
  return RAW_MALLOC(n ? n : 1);
}
void* operator new(std::size_t n, std::align_val_t a) {
  note();
  const auto al = std::max(static_cast<std::size_t>(a), sizeof(void*));
  if (void* p = RAW_MEMALIGN(al, n ? n : al)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n, std::align_val_t a) { return operator new(n, a); }
void operator delete(void* p) noexcept { RAW_FREE(p); }
void operator delete[](void* p) noexcept { RAW_FREE(p); }
void operator delete(void* p, std::size_t) noexcept { RAW_FREE(p); }
void operator delete[](void* p, std::size_t) noexcept { RAW_FREE(p); }
void operator delete(void* p, std::align_val_t) noexcept { RAW_FREE(p); }
void operator delete[](void* p, std::align_val_t) noexcept { RAW_FREE(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { RAW_FREE(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { RAW_FREE(p); }

using namespace modalwatch;
using namespace modalwatch::test_support;

namespace {

class CountingProbe : public LoopProbe {
 public:
  void warmed_up() override {
    t_allocations = 0;
    t_counting = true;
    started = true;
  }
  void exiting() override {
    t_counting = false;
    allocations = t_allocations;
  }
  std::atomic<bool> started{false};
  std::atomic<std::uint64_t> allocations{~0ull};
};

}  // namespace

TEST(DaemonAllocation, NoneOnTheEstimationThreadAfterStartUp) {
  const DriftData& data = drift_data();
  const Record& rec = data.record;
  Config c = load_config(kDriftConfig);
  c.daemon.stale_time = 0.2;
  lcm_t* lcm = lcm_create("memq://");
  ASSERT_NE(lcm, nullptr);
  Received rx;
  rx.subscribe(lcm, c.lcm);
  CountingProbe probe;
  {
    Daemon d(c, lcm, &probe);
    d.start();
    const auto handled = [&] {
      const DaemonCounters k = d.counters();
      return k.samples_processed + k.samples_dropped + k.samples_nonfinite + k.samples_duplicate +
             k.samples_out_of_order;
    };
    // memq queues without bound: pace by what was sent, not by what the daemon received.
    std::uint64_t published = 0;
    Eigen::Index done = 0;
    const auto pace = [&](Eigen::Index next) {
      published += static_cast<std::uint64_t>(next - done);
      done = next;
      wait_for([&] { return published < handled() + 8192; }, 10.0);
    };
    const Eigen::Index mid = 20 * 4096, end = rec.size();
    publish_range(lcm, c.lcm.batches_channel, rec, 0, mid, 64, 0, 0, pace);
    ASSERT_TRUE(wait_for([&] { return probe.started.load(); }, 20.0)) << "the warm-up never ended";
    // Bad input after the warm-up: NaN, a duplicate, reordering.
    for (int i = 0; i < 3; ++i) {
      SampleRecord s{kUtime0 + std::llround(rec.t(mid + i) * 1e6), mid + i, rec.u(mid + i), std::nan(""), rec.r(mid + i)};
      const auto bytes = encode_sample(s);
      lcm_publish(lcm, c.lcm.samples_channel.c_str(), bytes.data(), static_cast<unsigned>(bytes.size()));
      if (i == 1) lcm_publish(lcm, c.lcm.samples_channel.c_str(), bytes.data(), static_cast<unsigned>(bytes.size()));
    }
    // Then silence (stale input), and the rest 2 s later in sample time (a gap), with the drift.
    std::this_thread::sleep_for(std::chrono::milliseconds(400));
    done = mid + 3;
    publish_range(lcm, c.lcm.batches_channel, rec, mid + 3, end, 64, 2'000'000, 0, pace);
    published += 4;  // the single samples
    ASSERT_TRUE(wait_for([&] { return d.counters().samples_received == published && handled() == published; }, 30.0));
    d.stop();
    const DaemonCounters k = d.counters();
    EXPECT_EQ(k.samples_nonfinite, 3u);
    EXPECT_EQ(k.samples_duplicate, 1u);
    EXPECT_EQ(k.gaps, 1u);
    EXPECT_GT(k.flag_changes, 0u) << "the fault detector's flag path was not exercised";
    EXPECT_GT(k.samples_processed, std::uint64_t(end) - 10);
  }
  lcm_destroy(lcm);
  EXPECT_EQ(probe.allocations.load(), 0u) << "heap allocations on the estimation thread after start-up";
}
