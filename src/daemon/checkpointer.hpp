#pragma once
// The daemon's checkpoint file: which one to resume from at start-up, and a
// control-side thread that writes one every daemon.checkpoint_period. To copy
// the state it pauses the estimation loop (the input ring buffers meanwhile),
// so that the loop itself never locks; the file is written after the loop runs
// again.
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "counters.hpp"
#include "modalwatch/io/checkpoint.hpp"
#include "modalwatch/io/config.hpp"

namespace modalwatch::daemon_detail {

// Throws InputError naming the key when daemon.checkpoint.path's directory
// does not exist: every write would fail.
void check_checkpoint_directory(const Config& config);

// daemon.checkpoint when it exists, reads, and was written for this
// configuration (`fingerprint`); otherwise none, with the reason logged.
std::optional<Checkpoint> read_matching_checkpoint(const Config& config, std::uint64_t fingerprint);

class Checkpointer {
 public:
  // Called with `control` held: pauses the loop and returns its state, or none
  // (not running, still warming up).
  using Capture = std::function<std::optional<Checkpoint>()>;

  // `config` is the daemon's, read under `control` (a reload rewrites it).
  Checkpointer(const Config& config, std::mutex& control, Capture capture, CheckpointCounters& counters);
  ~Checkpointer() { stop(); }
  Checkpointer(const Checkpointer&) = delete;
  Checkpointer& operator=(const Checkpointer&) = delete;

  void start();
  void stop();  // call without `control` held: the thread may be waiting for it

  // Writes `ck` to `path` (atomically: the previous file stays on failure).
  // False, counted and logged, on failure; `final_one` logs at info level.
  bool write(const std::string& path, const Checkpoint& ck, bool final_one);

 private:
  void run();

  const Config& config_;
  std::mutex& control_;
  Capture capture_;
  CheckpointCounters& counters_;
  std::thread thread_;
  std::mutex wake_mutex_;
  std::condition_variable wake_;
  bool stop_ = false;                // under wake_mutex_
  bool periodic_ok_logged_ = false;  // this thread's, or the control side's after stop()
};

}  // namespace modalwatch::daemon_detail
