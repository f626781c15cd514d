#pragma once
// Samples lost in transport, from the sequence numbers in arrival order (before
// the input ring, so that ring drops are not counted here). A window of the
// last kWindow sequence numbers remembers which arrived: a late (reordered)
// sample fills its slot and is not lost; a number counts as lost when it leaves
// the window unseen, or at flush() (the subscriber flushes after an idle
// poll and at stop, so the counter is exact once the input pauses).
//
// A sample far behind the newest (a window or more), or behind it with a time
// that is not (later than the newest, or more than kRestartBack earlier), starts a
// new stream: a sender restart. The unseen numbers of the old stream are lost.
#include <algorithm>
#include <array>
#include <cstdint>

namespace modalwatch::daemon_detail {

class LossCounter {
 public:
  static constexpr std::int64_t kWindow = 8192;
  static constexpr std::int64_t kRestartBackUs = 1'000'000;

  // The number of samples newly found lost.
  std::uint64_t observe(std::int64_t seq, std::int64_t utime) noexcept {
    if (!have_) {
      start(seq, utime);
      return 0;
    }
    if (seq > hi_) return advance(seq, utime);
    if (hi_ - seq >= kWindow || utime > hi_utime_ || hi_utime_ - utime > kRestartBackUs) {
      const std::uint64_t lost = flush();
      start(seq, utime);
      return lost;
    }
    if (seq >= first_) set(seq);  // late or duplicate; before first_: counted lost already
    return 0;
  }

  // Counts every unseen number up to the newest as lost.
  std::uint64_t flush() noexcept {
    if (!have_) return 0;
    std::uint64_t lost = 0;
    for (std::int64_t x = std::max(first_, hi_ - kWindow + 1); x < hi_; ++x)
      if (!test(x)) ++lost;
    first_ = hi_ + 1;
    return lost;
  }

 private:
  void start(std::int64_t seq, std::int64_t utime) noexcept {
    have_ = true;
    first_ = hi_ = seq;
    hi_utime_ = utime;
    set(seq);
  }
  std::uint64_t advance(std::int64_t seq, std::int64_t utime) noexcept {
    std::uint64_t lost = 0;
    // Numbers leaving the window: (hi_ - kWindow, seq - kWindow].
    for (std::int64_t x = std::max(first_, hi_ - kWindow + 1); x <= std::min(hi_, seq - kWindow); ++x)
      if (!test(x)) ++lost;
    if (seq - kWindow > hi_) lost += static_cast<std::uint64_t>(seq - kWindow - hi_);  // never in the window
    for (std::int64_t x = std::max(hi_ + 1, seq - kWindow + 1); x < seq; ++x) clear(x);
    set(seq);
    hi_ = seq;
    hi_utime_ = utime;
    return lost;
  }
  static std::size_t slot(std::int64_t x) noexcept { return static_cast<std::size_t>(x & (kWindow - 1)); }
  bool test(std::int64_t x) const noexcept { return (bits_[slot(x) / 64] >> (slot(x) % 64)) & 1u; }
  void set(std::int64_t x) noexcept { bits_[slot(x) / 64] |= std::uint64_t{1} << (slot(x) % 64); }
  void clear(std::int64_t x) noexcept { bits_[slot(x) / 64] &= ~(std::uint64_t{1} << (slot(x) % 64)); }

  bool have_ = false;
  std::int64_t first_ = 0, hi_ = 0, hi_utime_ = 0;
  std::array<std::uint64_t, kWindow / 64> bits_{};
};

}  // namespace modalwatch::daemon_detail
