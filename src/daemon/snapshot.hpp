#pragma once
// What the estimation loop hands the publisher, through a lock-free ring: fixed
// size and trivially copyable, so that making one neither allocates nor locks.
// It carries values (estimates, the fault detector's state, events since the
// last snapshot); the publisher alone turns them into messages and their bits.
#include <array>
#include <cstdint>
#include <type_traits>

#include "metrics.hpp"
#include "modalwatch/daemon/daemon.hpp"
#include "modalwatch/fault_detector.hpp"
#include "modalwatch/model.hpp"

namespace modalwatch::daemon_detail {

inline constexpr int kMaxModes = Daemon::kMaxModes;
inline constexpr int kMaxEntries = kQuantities * kMaxModes;

struct Snapshot {
  enum Kind : int {
    estimate = 0,     // a publish period of sample time passed: estimates and fault status
    status_only = 1,  // no input for a publish period of wall time: fault status (stale)
    final_state = 2,  // the loop's last tick before it stops or pauses
  };
  int kind = estimate;
  int n_modes = 0;
  std::int64_t utime = 0;         // us, newest sample included (0: none yet), on the loop's clock
  std::int64_t utime0 = 0;        // us, the first sample's: detector times are seconds after it
  std::int64_t utime_offset = 0;  // us, loop clock - sender utime (changes at a sender restart)
  bool have_sample = false;       // a sample was taken since start
  std::int64_t last_seq = -1;
  bool have_seq = false;
  // The estimator's state.
  bool warming_up = true;
  bool low_excitation = false;
  bool misfit = false;  // EstimatorStatus::misfit
  bool estimates_valid = false;  // EstimatorStatus::estimates_measure_plant(): the detector's `valid`
  std::array<ModalParameters, kMaxModes> value{}, std_dev{};
  double residual_rms = 0.0;
  const char* reset_reason = "";    // static string from the estimator
  double warmup_fit_seconds = 0.0;  // how long the last warm-up fit took
  bool warmup_fit_used = false;     // the estimate started from that fit (else from the configured model)
  // The fault detector's state, and its flag changes in this publish period.
  std::array<ModeStatus, kMaxModes> modes{};
  int n_changes = 0;
  std::array<FlagChange, kMaxEntries> changes{};
  // Input and estimator events since the previous snapshot.
  bool stale = false;           // no sample for daemon.stale_time
  bool gap = false;             // the estimator reset its prefilters after a time gap
  bool reset = false;           // the estimator returned to its last good state
  bool input_dropped = false;   // the input ring or the warm-up backlog was full
  bool decode_errors = false;   // undecodable packets arrived
  bool overrun = false;         // loop ticks overran
  bool samples_lost = false;    // sequence numbers never arrived
  bool sender_restart = false;  // the sender restarted
  DaemonCounters counters;
  TickHistogram tick;  // the loop's tick durations since start (metrics)
};
static_assert(std::is_trivially_copyable_v<Snapshot>);

}  // namespace modalwatch::daemon_detail
