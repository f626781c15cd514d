#include "checkpointer.hpp"

#include <spdlog/spdlog.h>

#include <chrono>
#include <filesystem>
#include <system_error>
#include <utility>

#include "modalwatch/error.hpp"
#include "realtime.hpp"

namespace modalwatch::daemon_detail {

std::optional<Checkpoint> read_matching_checkpoint(const Config& config, std::uint64_t fingerprint) {
  const std::string& path = config.daemon.checkpoint_path;
  if (path.empty()) return std::nullopt;
  if (!std::filesystem::exists(path)) {
    spdlog::info("checkpoint {}: none yet, starting with the configured model", path);
    return std::nullopt;
  }
  Checkpoint ck;
  try {
    ck = read_checkpoint(path);
  } catch (const InputError& e) {
    spdlog::warn("checkpoint ignored: {}; starting with a warm-up", e.what());
    return std::nullopt;
  }
  if (ck.config_fingerprint != fingerprint) {
    spdlog::warn(
        "checkpoint {} was written for another configuration (sample time, loop, controller, model structure or "
        "forgetting differ): ignored, starting with a warm-up",
        path);
    return std::nullopt;
  }
  if (ck.baselines.size() != config.model.submodels.size()) {
    spdlog::warn("checkpoint {}: {} baselines for {} submodels: ignored", path, ck.baselines.size(),
                 config.model.submodels.size());
    return std::nullopt;
  }
  return ck;
}

Checkpointer::Checkpointer(const Config& config, std::mutex& control, Capture capture, CheckpointCounters& counters)
    : config_(config), control_(control), capture_(std::move(capture)), counters_(counters) {}

void Checkpointer::start() {
  if (thread_.joinable()) return;
  {
    std::lock_guard<std::mutex> lock(wake_mutex_);
    stop_ = false;
  }
  thread_ = std::thread([this] { run(); });
}

void Checkpointer::stop() {
  if (!thread_.joinable()) return;
  {
    std::lock_guard<std::mutex> lock(wake_mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

bool Checkpointer::write(const std::string& path, const Checkpoint& ck, bool final_one) {
  try {
    write_checkpoint(path, ck);
    bump(counters_.written);
    if (final_one)
      spdlog::info("checkpoint written: {} (last seq {})", path, ck.last_seq);
    else
      spdlog::debug("checkpoint written: {} (last seq {})", path, ck.last_seq);
    return true;
  } catch (const std::system_error& e) {
    bump(counters_.failures);
    spdlog::error("checkpoint NOT written ({}): {}; the previous one is kept, the service continues", path,
                  e.what());
    return false;
  }
}

void Checkpointer::run() {
  name_this_thread("mw-checkpoint");
  for (;;) {
    double period = 0.0;
    {
      std::lock_guard<std::mutex> lock(control_);
      period = config_.daemon.checkpoint_period;
    }
    {
      std::unique_lock<std::mutex> lock(wake_mutex_);
      if (wake_.wait_for(lock, std::chrono::duration<double>(period), [this] { return stop_; })) return;
    }
    std::optional<Checkpoint> ck;
    std::string path;
    {
      std::lock_guard<std::mutex> lock(control_);
      if (config_.daemon.checkpoint_path.empty()) continue;
      path = config_.daemon.checkpoint_path;
      ck = capture_();
    }
    if (ck) write(path, *ck, false);
  }
}

}  // namespace modalwatch::daemon_detail
