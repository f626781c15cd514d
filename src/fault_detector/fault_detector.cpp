#include "modalwatch/fault_detector.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

// Decisions the header leaves open:
//
// - Validity. An update counts for a mode only when `valid` is true, t is finite
//   and the mode's wn, zeta and gain are all finite; otherwise nothing about that
//   mode changes (flags, pending states, deviations, learning) and its timers are
//   paused: each mode runs on its own clock that advances by t - t_prev only when
//   both this and the previous update were valid for the mode. Hold, clear and
//   learn times are measured on that clock.
// - A quantity is past its thresholds when |dev_sigma| > sigma_threshold AND
//   |dev_rel| > relative_threshold. A standard deviation that is not positive and
//   finite, or a zero baseline, makes its test fail (the quantity cannot rise;
//   its deviation is reported as 0). A flag falls once the quantity has been out
//   of the reduced box for clear_time, i.e. NOT (|dev_sigma| > f sigma_threshold
//   AND |dev_rel| > f relative_threshold), f = clear_fraction: back in either
//   sense is enough (the complement of the rise rule), and a failed test counts
//   as back.
// - Timers: a pending rise starts at the first valid update past the thresholds
//   and matures at the first valid update at least hold_time (mode clock) later;
//   hold_time = 0 raises at once. Leaving the thresholds cancels it. The clear
//   timer likewise restarts whenever the quantity re-enters the reduced box.
//   below_since_ holds the start of whichever timer runs (rise when unflagged,
//   clear when flagged), on the mode clock; NaN when none does.
// - `since` is the time (t) the condition began while pending, the time the flag
//   rose while flagged, and 0 otherwise.
// - Learning starts at the first update valid for the mode and ends at the first
//   valid update at least learn_window (mode clock) later; the baseline is the
//   mean of the values of every valid update in between, both ends included.
//   Detection starts with that same update.
// - update() allocates nothing: all state is sized at construction. It appends at
//   most one change per quantity, 3 * modes per call; a caller that reserves that
//   capacity and clears `changes` between calls never makes it grow.

namespace modalwatch {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// Timers compare elapsed >= duration - kTimeSlack so that, e.g., a 2 s hold at
// 0.1 s updates matures at exactly the 20th update despite rounding in t.
constexpr double kTimeSlack = 1e-9;
// flag_bits() has 64 bits for 3 quantities per mode.
constexpr std::size_t kMaxModes = 64 / kQuantities;

double get(const ModalParameters& p, int q) {
  switch (q) {
    case 0: return p.wn;
    case 1: return p.zeta;
    default: return p.gain;
  }
}

void set(ModalParameters& p, int q, double x) {
  switch (q) {
    case 0: p.wn = x; break;
    case 1: p.zeta = x; break;
    default: p.gain = x; break;
  }
}

const char* quantity_name(int q) {
  static constexpr const char* names[kQuantities] = {"wn", "zeta", "gain"};
  return names[q];
}

bool finite(const ModalParameters& p) {
  return std::isfinite(p.wn) && std::isfinite(p.zeta) && std::isfinite(p.gain);
}

void check_thresholds(const FaultThresholds& th, int q) {
  const std::string where = std::string("FaultDetector: thresholds for ") + quantity_name(q) + ": ";
  if (!(std::isfinite(th.sigma_threshold) && th.sigma_threshold > 0.0))
    throw std::invalid_argument(where + "sigma_threshold must be positive");
  if (!(std::isfinite(th.relative_threshold) && th.relative_threshold > 0.0))
    throw std::invalid_argument(where + "relative_threshold must be positive");
  if (!(th.clear_fraction > 0.0 && th.clear_fraction < 1.0))
    throw std::invalid_argument(where + "clear_fraction must lie in (0, 1)");
  if (!(std::isfinite(th.hold_time) && th.hold_time >= 0.0))
    throw std::invalid_argument(where + "hold_time must be >= 0");
  if (!(std::isfinite(th.clear_time) && th.clear_time >= 0.0))
    throw std::invalid_argument(where + "clear_time must be >= 0");
}

}  // namespace

FaultDetector::FaultDetector(FaultDetectorSettings settings) : settings_(std::move(settings)) {
  const std::size_t n = settings_.mode_names.size();
  if (n > kMaxModes)
    throw std::invalid_argument("FaultDetector: " + std::to_string(n) + " modes, at most " +
                                std::to_string(kMaxModes) + " fit in the flag bits");
  if (settings_.baselines.size() != n)
    throw std::invalid_argument("FaultDetector: " + std::to_string(settings_.baselines.size()) +
                                " baselines for " + std::to_string(n) + " modes");
  if (!(std::isfinite(settings_.learn_window) && settings_.learn_window > 0.0))
    throw std::invalid_argument("FaultDetector: learn_window must be positive");
  for (int q = 0; q < kQuantities; ++q) check_thresholds(settings_.thresholds[q], q);

  modes_.assign(n, ModeStatus{});
  sum_.assign(n, {0.0, 0.0, 0.0});
  learn_start_.assign(n, 0.0);
  learn_count_.assign(n, 0);
  below_since_.assign(n, {kNaN, kNaN, kNaN});
  clock_.assign(n, 0.0);
  last_valid_.assign(n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    const auto& b = settings_.baselines[i];
    if (!b) continue;
    if (!finite(*b))
      throw std::invalid_argument("FaultDetector: configured baseline of mode '" + settings_.mode_names[i] +
                                  "' is not finite");
    modes_[i].baseline.value = *b;
    modes_[i].baseline.learned = false;
    modes_[i].baseline_ready = true;
  }
}

void FaultDetector::update(double t, const std::vector<ModalParameters>& value,
                           const std::vector<ModalParameters>& std_dev, bool valid, std::vector<FlagChange>& changes) {
  const std::size_t n = modes_.size();
  if (value.size() != n || std_dev.size() != n)
    throw std::invalid_argument("FaultDetector::update: estimates for a different number of modes");
  const bool t_ok = std::isfinite(t);

  for (std::size_t i = 0; i < n; ++i) {
    const bool mode_valid = valid && t_ok && finite(value[i]);
    if (!mode_valid) {
      last_valid_[i] = 0;  // the interval up to the next valid update does not count
      continue;
    }
    if (last_valid_[i] && t > last_t_) clock_[i] += t - last_t_;
    last_valid_[i] = 1;
    const double now = clock_[i];
    ModeStatus& m = modes_[i];

    if (!m.baseline_ready) {
      if (learn_count_[i] == 0) learn_start_[i] = now;
      for (int q = 0; q < kQuantities; ++q) sum_[i][q] += get(value[i], q);
      ++learn_count_[i];
      if (now - learn_start_[i] < settings_.learn_window - kTimeSlack) continue;
      for (int q = 0; q < kQuantities; ++q)
        set(m.baseline.value, q, sum_[i][q] / static_cast<double>(learn_count_[i]));
      m.baseline.learned = true;
      m.baseline_ready = true;
    }

    for (int q = 0; q < kQuantities; ++q) {
      const FaultThresholds& th = settings_.thresholds[q];
      QuantityStatus& s = m.quantity[q];
      const double x = get(value[i], q);
      const double x0 = get(m.baseline.value, q);
      const double sd = get(std_dev[i], q);

      const bool sigma_ok = std::isfinite(sd) && sd > 0.0;
      const bool rel_ok = x0 != 0.0;
      s.deviation_sigma = sigma_ok ? (x - x0) / sd : 0.0;
      s.deviation_relative = rel_ok ? (x - x0) / std::abs(x0) : 0.0;
      const double ds = std::abs(s.deviation_sigma), dr = std::abs(s.deviation_relative);
      const bool past = sigma_ok && rel_ok && ds > th.sigma_threshold && dr > th.relative_threshold;
      const bool in_band = sigma_ok && rel_ok && ds > th.clear_fraction * th.sigma_threshold &&
                           dr > th.clear_fraction * th.relative_threshold;

      double& timer = below_since_[i][q];
      bool changed = false;
      if (!s.flagged) {
        if (!past) {
          s.pending = false;
          s.since = 0.0;
          timer = kNaN;
          continue;
        }
        if (!s.pending) {
          s.pending = true;
          s.since = t;
          timer = now;
        }
        if (now - timer >= th.hold_time - kTimeSlack) {
          s.flagged = true;
          s.pending = false;
          s.since = t;
          timer = kNaN;
          changed = true;
        }
      } else {
        if (in_band) {
          timer = kNaN;
          continue;
        }
        if (std::isnan(timer)) timer = now;
        if (now - timer >= th.clear_time - kTimeSlack) {
          s.flagged = false;
          s.since = 0.0;
          timer = kNaN;
          changed = true;
        }
      }
      if (changed) {
        FlagChange c;
        c.mode = static_cast<int>(i);
        c.quantity = static_cast<Quantity>(q);
        c.raised = s.flagged;
        c.time = t;
        c.value = x;
        c.baseline = x0;
        c.deviation_sigma = s.deviation_sigma;
        c.deviation_relative = s.deviation_relative;
        changes.push_back(c);
      }
    }
  }
  if (t_ok) last_t_ = t;
}

bool FaultDetector::any_flag() const {
  for (const ModeStatus& m : modes_)
    for (const QuantityStatus& s : m.quantity)
      if (s.flagged) return true;
  return false;
}

std::uint64_t FaultDetector::flag_bits() const {
  std::uint64_t bits = 0;
  for (std::size_t i = 0; i < modes_.size(); ++i)
    for (int q = 0; q < kQuantities; ++q)
      if (modes_[i].quantity[q].flagged) bits |= std::uint64_t{1} << (i * kQuantities + static_cast<std::size_t>(q));
  return bits;
}

}  // namespace modalwatch
