#include "warmup_fitter.hpp"

#include <spdlog/spdlog.h>

#include <exception>
#include <limits>
#include <utility>

#include "loop_probe.hpp"
#include "realtime.hpp"

namespace modalwatch::daemon_detail {

void WarmupFitter::start() {
  if (thread_.joinable()) return;
  stop_.store(false);
  thread_ = std::thread([this] { run(); });
}

void WarmupFitter::stop() {
  if (!thread_.joinable()) return;
  stop_.store(true, std::memory_order_release);
  bell_.ring();
  thread_.join();
}

void WarmupFitter::request(WarmupFit&& job) noexcept {
  job_ = std::move(job);
  phase_.store(requested, std::memory_order_release);
  bell_.ring();
}

bool WarmupFitter::take_applied() noexcept {
  if (phase_.load(std::memory_order_acquire) != applied) return false;
  phase_.store(idle_phase, std::memory_order_relaxed);
  return true;
}

void WarmupFitter::run() {
  name_this_thread("mw-fit");
  for (;;) {
    const std::uint32_t seen = bell_.rings();
    if (stop_.load(std::memory_order_acquire)) break;
    if (phase_.load(std::memory_order_acquire) != requested) {
      bell_.wait_until(seen, std::numeric_limits<std::int64_t>::max());
      continue;
    }
    const std::int64_t t0 = mono_ns();
    spdlog::info("{} window complete ({} samples): fitting on the fitter thread; input is held meanwhile",
                 job_.refit() ? "refit (the output error diverged and did not settle)" : "warm-up", job_.samples());
    if (probe_) probe_->warmup_fit_running();
    job_.run();
    try {
      estimator_.apply_warmup_fit(std::move(job_));
    } catch (const std::exception& e) {
      spdlog::error("the warm-up fit could not be applied ({}): the warm-up starts again", e.what());
    }
    job_ = WarmupFit();  // the fit's buffers are freed here, not on the loop
    fit_duration_ns_.store(mono_ns() - t0, std::memory_order_relaxed);
    phase_.store(applied, std::memory_order_release);
  }
}

}  // namespace modalwatch::daemon_detail
