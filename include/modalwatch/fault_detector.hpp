#pragma once
// Fault detection on modal estimates (DESIGN.md, "Fault detection"): per mode a
// baseline (configured, or learned over a window), and per publish period the
// deviation of wn, zeta and gain in units of the estimate's standard deviation
// and as a relative change. A flag rises when a deviation stays past its
// threshold for a hold time and falls with hysteresis; no flag while the
// estimator warms up or the excitation is too low.
//
// A plain class: no I/O, no threads, no allocation in update().
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "modalwatch/model.hpp"

namespace modalwatch {

enum class Quantity : int { wn = 0, zeta = 1, gain = 2 };
inline constexpr int kQuantities = 3;

struct FaultThresholds {
  // A quantity deviates when BOTH hold: |x - x0| > sigma_threshold * std(x) and
  // |x - x0| / |x0| > relative_threshold. (Statistics alone flag noise-free drifts of
  // 0.01 %; percentages alone flag noisy estimates.)
  double sigma_threshold = 4.0;
  double relative_threshold = 0.05;
  double hold_time = 2.0;      // s past the thresholds before the flag rises
  double clear_fraction = 0.5; // hysteresis: falls below this fraction of both thresholds
  double clear_time = 2.0;     // s below before it falls
  bool operator==(const FaultThresholds&) const = default;
};

struct ModeBaseline {
  ModalParameters value;  // wn, zeta, gain
  bool learned = false;   // from the learning window rather than the config
};

struct FaultDetectorSettings {
  std::vector<std::string> mode_names;
  // Per mode: a configured baseline, or none (learned as the mean estimate over
  // learn_window seconds once estimates are valid).
  std::vector<std::optional<ModalParameters>> baselines;
  double learn_window = 30.0;  // s
  // Per quantity (wn, zeta, gain); zeta is noisier, so it usually gets looser limits.
  std::array<FaultThresholds, kQuantities> thresholds{};
  bool operator==(const FaultDetectorSettings&) const = default;
};

// The detector's view of one quantity of one mode.
struct QuantityStatus {
  bool flagged = false;
  double deviation_sigma = 0.0;    // (x - x0) / std
  double deviation_relative = 0.0; // (x - x0) / |x0|
  double since = 0.0;              // time the flag rose (or the condition began, when pending)
  bool pending = false;            // past the thresholds, hold time not yet elapsed
};

struct ModeStatus {
  std::array<QuantityStatus, kQuantities> quantity{};
  ModeBaseline baseline;
  bool baseline_ready = false;
};

// One event per flag change, for logging (the daemon logs every one).
struct FlagChange {
  int mode = 0;
  Quantity quantity = Quantity::wn;
  bool raised = false;
  double time = 0.0;
  double value = 0.0, baseline = 0.0, deviation_sigma = 0.0, deviation_relative = 0.0;
};

class FaultDetector {
 public:
  // Throws std::invalid_argument on inconsistent settings (sizes, thresholds).
  explicit FaultDetector(FaultDetectorSettings settings);

  // One publish period: the current estimate of every mode (value and std) at time t.
  // `valid` is false while the estimator warms up or excitation is low: no flag
  // changes then, and learning pauses. Flag changes since the last call are
  // appended to `changes` (capacity reserved at construction: no allocation for
  // up to 3 changes per mode per call).
  void update(double t, const std::vector<ModalParameters>& value, const std::vector<ModalParameters>& std_dev,
              bool valid, std::vector<FlagChange>& changes);

  const std::vector<ModeStatus>& status() const { return modes_; }
  bool any_flag() const;
  // Bit i*3 + q set when mode i quantity q is flagged (up to 21 modes).
  std::uint64_t flag_bits() const;

 private:
  FaultDetectorSettings settings_;
  std::vector<ModeStatus> modes_;
  // Learning: running sums per mode over the learn window.
  std::vector<std::array<double, kQuantities>> sum_;
  std::vector<double> learn_start_;
  std::vector<int> learn_count_;
  std::vector<std::array<double, kQuantities>> below_since_;  // hysteresis timers
  // Invalid updates pause every timer: each mode runs on its own clock, which
  // advances only between consecutive updates that are valid for that mode.
  std::vector<double> clock_;
  std::vector<std::uint8_t> last_valid_;
  double last_t_ = 0.0;
};

}  // namespace modalwatch
