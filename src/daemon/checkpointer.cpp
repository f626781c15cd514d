#include "checkpointer.hpp"

#include <spdlog/spdlog.h>

#include <chrono>
#include <filesystem>
#include <system_error>
#include <utility>

#include "modalwatch/error.hpp"
#include "realtime.hpp"

namespace modalwatch::daemon_detail {

void check_checkpoint_directory(const Config& config) {
  const std::string& path = config.daemon.checkpoint_path;
  if (path.empty()) return;
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  if (!dir.empty() && !std::filesystem::is_directory(dir))
    throw InputError(config.source, "key 'daemon.checkpoint.path': directory '" + dir.string() +
                                        "' does not exist (create it, or change the path)");
}

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
    // The first periodic one, and the first after a failure, at info: the rest would flood the log.
    if (final_one || !periodic_ok_logged_)
      spdlog::info(
          "checkpoint written: {} (last seq {}){}", path, ck.last_seq,
          final_one ? ""
                    : fmt::format("; every {} s from now on, logged at debug level", config_.daemon.checkpoint_period));
    else
      spdlog::debug("checkpoint written: {} (last seq {})", path, ck.last_seq);
    periodic_ok_logged_ = true;
    return true;
  } catch (const std::system_error& e) {
    bump(counters_.failures);
    periodic_ok_logged_ = false;
    spdlog::error("checkpoint NOT written ({}): {}; the previous one is kept, the service continues", path, e.what());
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
