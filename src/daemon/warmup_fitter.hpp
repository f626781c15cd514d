#pragma once
// The estimation loop's helper thread for the warm-up fit (section 4.7): the
// fit takes seconds on a long window and allocates, so it does not run on the
// loop. The loop hands over the job when step() reports the window complete;
// until the fitter has applied it, the estimator belongs to the fitter and the
// loop holds the input. The handover is one atomic (release/acquire), and the
// fitter sleeps on a doorbell in between: it wakes once per warm-up.
#include <atomic>
#include <cstdint>
#include <thread>

#include "doorbell.hpp"
#include "modalwatch/estimator.hpp"

namespace modalwatch {
class LoopProbe;
}

namespace modalwatch::daemon_detail {

class WarmupFitter {
 public:
  explicit WarmupFitter(RecursiveEstimator& estimator) : estimator_(estimator) {}
  ~WarmupFitter() { stop(); }
  WarmupFitter(const WarmupFitter&) = delete;
  WarmupFitter& operator=(const WarmupFitter&) = delete;

  void set_probe(LoopProbe* probe) { probe_ = probe; }
  void start();
  void stop();  // after a requested fit was applied, or it is left undone

  // Loop side. request(): the estimator is the fitter's from here (no
  // allocation: the job's buffers move). take_applied(): true once, when the
  // fit has been applied and the estimator is the loop's again.
  void request(WarmupFit&& job) noexcept;
  bool take_applied() noexcept;
  bool idle() const noexcept { return phase_.load(std::memory_order_acquire) == idle_phase; }
  double last_fit_seconds() const noexcept {
    return static_cast<double>(fit_duration_ns_.load(std::memory_order_relaxed)) * 1e-9;
  }

 private:
  enum Phase : int { idle_phase = 0, requested = 1, applied = 2 };
  void run();

  RecursiveEstimator& estimator_;
  LoopProbe* probe_ = nullptr;
  std::atomic<int> phase_{idle_phase};  // releases job_ and the estimator to the other side
  WarmupFit job_;
  Doorbell bell_;  // rung with a request, and to stop
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<std::int64_t> fit_duration_ns_{0};
};

}  // namespace modalwatch::daemon_detail
