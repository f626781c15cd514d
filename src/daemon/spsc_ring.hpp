#pragma once
// A bounded, lock-free, wait-free single-producer single-consumer ring: the
// daemon's hand-off from the LCM subscriber thread to the estimation loop, and
// from the loop to the publisher. After Erik Rigtorp's SPSCQueue
// (https://github.com/rigtorp/SPSCQueue, MIT), reduced to what the daemon needs.
//
//   SpscRing<Sample> ring(4096);          // allocates here, and only here
//   // producer thread                    // consumer thread
//   if (!ring.try_push(s)) ++dropped;     while (const Sample* s = ring.front()) {
//                                           use(*s);
//                                           ring.pop();
//                                         }
//
// Contract
// - Exactly one producer thread calls try_push / try_emplace and exactly one
//   consumer thread calls front / pop / try_pop at any one time (they may hand
//   their role to another thread if that hand-off itself synchronises).
//   size(), empty() and capacity() may be called from anywhere.
// - Never blocks, never allocates, never throws after construction. A full ring
//   makes try_push return false; the caller counts the drop.
// - T must be trivially copyable (enforced): slots are overwritten without
//   destruction and elements are read by copying, so no element ever owns a
//   resource (in particular no heap memory that a std::string or std::vector
//   would free on the wrong thread).
//
// Design (why it is fast)
// - Capacity is any n >= 1: indices live in [0, n] over n + 1 slots and wrap by
//   compare-and-reset, so a ring sized "one second at 4096 Hz" holds exactly
//   that and the drop counters stay in the configured unit. One slot stays empty
//   to tell full from empty without a shared counter.
// - Each side's index sits in its own 128-byte block next to a cached copy of
//   the other side's index, reloaded only when the copy says full (producer) or
//   empty (consumer): in steady state each thread touches only its own lines.
//   128 bytes because x86 prefetchers pull line pairs.
// - The slot array is allocated once, 128-byte aligned and padded, so it shares
//   no line with unrelated heap objects.
#include <atomic>
#include <cassert>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <new>
#include <stdexcept>
#include <type_traits>
#include <utility>

namespace modalwatch {

// The separation, in bytes, between data written by different threads.
inline constexpr std::size_t kFalseSharingRange = 128;

template <typename T>
class SpscRing {
  static_assert(std::is_trivially_copyable_v<T>,
                "SpscRing<T>: T must be trivially copyable (slots are overwritten "
                "without destruction and read by copying)");
  static_assert(std::is_copy_constructible_v<T>, "SpscRing<T>: T must be copy constructible");
  static_assert(std::atomic<std::size_t>::is_always_lock_free, "SpscRing needs lock-free std::atomic<std::size_t>");

 public:
  using value_type = T;

  // Allocates room for `capacity` elements (the only allocation this object makes).
  // Throws std::invalid_argument for capacity 0 and std::length_error when the
  // byte size would overflow; std::bad_alloc as usual.
  explicit SpscRing(std::size_t capacity) : capacity_(capacity), slots_count_(capacity + 1) {
    if (capacity == 0) {
      throw std::invalid_argument("SpscRing: capacity must be at least 1");
    }
    constexpr std::size_t kMaxBytes = std::numeric_limits<std::size_t>::max() - kFalseSharingRange;
    if (capacity >= kMaxBytes / sizeof(T) - 1) {
      throw std::length_error("SpscRing: capacity too large");
    }
    std::size_t bytes = slots_count_ * sizeof(T);
    bytes = (bytes + kStorageAlign - 1) / kStorageAlign * kStorageAlign;
    slots_ = static_cast<T*>(::operator new (bytes, std::align_val_t{kStorageAlign}));
  }

  ~SpscRing() {
    // T is trivially destructible (implied by trivially copyable): nothing to destroy.
    // Unsized: clang does not declare the sized aligned form without -fsized-deallocation.
    ::operator delete (static_cast<void*>(slots_), std::align_val_t{kStorageAlign});
  }

  SpscRing(const SpscRing&) = delete;
  SpscRing& operator=(const SpscRing&) = delete;
  SpscRing(SpscRing&&) = delete;
  SpscRing& operator=(SpscRing&&) = delete;

  // ---- producer ----------------------------------------------------------------

  // Copies `value` in. False, with the ring unchanged, when it is full.
  bool try_push(const T& value) noexcept { return try_emplace(value); }

  // Constructs an element in place from `args`. False when full.
  template <typename... Args>
  bool try_emplace(Args&&... args) noexcept {
    static_assert(std::is_nothrow_constructible_v<T, Args&&...>,
                  "SpscRing::try_emplace: T must be nothrow constructible from the arguments");
    // relaxed: write_ is written only by this (the producer) thread, so our own
    // last store is what we read; no other thread's data is consumed through it.
    const std::size_t write = write_.load(std::memory_order_relaxed);
    const std::size_t next = increment(write);
    if (next == read_cache_) {
      // acquire: pairs with the consumer's release store of read_ in pop(). It
      // makes the consumer's reads of the slots it has released happen-before our
      // overwriting them below (no write-after-read race on a reused slot).
      read_cache_ = read_.load(std::memory_order_acquire);
      if (next == read_cache_) {
        return false;
      }
    }
    ::new (static_cast<void*>(slots_ + write)) T(std::forward<Args>(args)...);
    // release: pairs with the consumer's acquire load of write_ in front(). Every
    // byte of the element constructed above becomes visible before the consumer
    // can see the advanced index, so it never reads a partly written slot.
    write_.store(next, std::memory_order_release);
    return true;
  }

  // ---- consumer ----------------------------------------------------------------

  // The oldest element, or nullptr when the ring is empty. The pointer stays
  // valid, and the element unchanged, until pop().
  [[nodiscard]] T* front() noexcept {
    // relaxed: read_ is written only by this (the consumer) thread.
    const std::size_t read = read_.load(std::memory_order_relaxed);
    if (read == write_cache_) {
      // acquire: pairs with the producer's release store of write_ in
      // try_emplace(); the contents of every slot before the loaded index are
      // visible to us from here on.
      write_cache_ = write_.load(std::memory_order_acquire);
      if (read == write_cache_) {
        return nullptr;
      }
    }
    return std::launder(slots_ + read);
  }

  // Removes the oldest element. Precondition: front() returned non-null since the
  // last pop() (i.e. the ring is not empty).
  void pop() noexcept {
    // relaxed: our own index, as in front().
    const std::size_t read = read_.load(std::memory_order_relaxed);
    // Checked against the cached producer index: front() must have seen an element.
    assert(read != write_cache_ && "SpscRing::pop on an empty ring");
    // release: pairs with the producer's acquire load of read_ in try_emplace().
    // Our reads of this slot (through front()) happen-before the producer may
    // reuse it.
    read_.store(increment(read), std::memory_order_release);
  }

  // Copies the oldest element into `out` and removes it. False when empty.
  bool try_pop(T& out) noexcept {
    const T* p = front();
    if (p == nullptr) {
      return false;
    }
    out = *p;
    pop();
    return true;
  }

  // ---- anyone ------------------------------------------------------------------

  // Elements in the ring: exact while neither side is moving, otherwise approximate
  // (the two indices are read at slightly different times), but always within
  // [0, capacity()]. For statistics and pacing, not for deciding to pop or push.
  [[nodiscard]] std::size_t size() const noexcept {
    // relaxed (both): the result is a statistic, never used to access a slot;
    // front() and try_emplace() synchronise on their own loads.
    const std::size_t write = write_.load(std::memory_order_relaxed);
    const std::size_t read = read_.load(std::memory_order_relaxed);
    return write >= read ? write - read : write + slots_count_ - read;
  }

  [[nodiscard]] bool empty() const noexcept { return size() == 0; }

  [[nodiscard]] std::size_t capacity() const noexcept { return capacity_; }

 private:
  static constexpr std::size_t kStorageAlign = alignof(T) > kFalseSharingRange ? alignof(T) : kFalseSharingRange;

  [[nodiscard]] std::size_t increment(std::size_t i) const noexcept {
    ++i;
    return i == slots_count_ ? 0 : i;
  }

  // Read-only after construction: shared freely, on a block nobody writes.
  alignas(kFalseSharingRange) const std::size_t capacity_;
  const std::size_t slots_count_;  // capacity_ + 1: one slot always stays empty
  T* slots_ = nullptr;

  // Producer block: its index and its cached copy of the consumer's.
  alignas(kFalseSharingRange) std::atomic<std::size_t> write_{0};
  std::size_t read_cache_ = 0;

  // Consumer block: its index and its cached copy of the producer's.
  alignas(kFalseSharingRange) std::atomic<std::size_t> read_{0};
  std::size_t write_cache_ = 0;
  // No tail padding needed: sizeof is a multiple of alignof (128), so whatever
  // follows the ring in memory starts on a fresh 128-byte block.
};

}  // namespace modalwatch
