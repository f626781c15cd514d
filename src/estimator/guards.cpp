// The guards of the recursive estimator that act on its whole state: the
// restart of the filters after a gap, and the last good state it saves now and
// then and returns to on a reset (a divergence, a non-finite model or update).
// The per-sample checks that trigger them (outliers, divergence, excitation)
// are steps 2 and 3 of step.cpp; the stability projection is update.hpp's.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include <Eigen/Core>

#include "impl.hpp"

namespace modalwatch {

void RecursiveEstimator::Impl::reset_filters() {
  for (auto& b : blocks) {
    b.filters.reset();
    b.xu = b.xz = 0.0;
  }
  controller.reset();
}

// After a gap (or a reset) the filters restart from rest, and the model output
// needs a few time constants of the slowest mode to catch up with the data. That
// transient is neither a divergence nor information about theta: as in the
// warm-up (section 4.7), the filters run without updating theta, first until
// the modes' free response has died out (transient_samples()), then until the
// output error is back near the noise level (at most kSettleWindows residual
// windows more, after which updates resume so that a plant that changed during
// the gap can still be followed); the divergence detector is not consulted
// meanwhile. A gap within that time starts the wait again: a cluster of gaps
// is missing information, never new information.
void RecursiveEstimator::Impl::restart_filters() {
  constexpr double kSettleWindows = 4.0;
  reset_filters();
  // Unsettled until the short-term error, started at the divergence level, has
  // come down to near the noise level on the restarted filters' own output.
  e_short = cfg.divergence_ratio * cfg.divergence_ratio * e_var_good;
  transient = transient_samples();
  settling = transient + static_cast<std::uint64_t>(kSettleWindows / (1.0 - e_alpha));
  outlier_run = 0;
}

// Samples until the free response of the slowest mode (and first-order
// submodel) of the current model has decayed to kTransientDecay (a tenth) of
// its start:
// the restarted prefilters and the plant's response to the input before the gap
// differ by that response, and the output error can fall near the noise level
// while its part correlated with the instrument still biases theta. Submodels
// with poles at the origin or of other orders have no such bound (the output
// error alone decides for them).
std::uint64_t RecursiveEstimator::Impl::transient_samples() const {
  constexpr double kTransientDecay = 0.1;
  double rate = std::numeric_limits<double>::infinity();  // slowest decay rate, 1/s
  for (const auto& b : blocks) {
    const double r = b.decay_rate();
    if (r > 0.0) rate = std::min(rate, r);
  }
  if (!std::isfinite(rate) || !(rate > 0.0)) return 0;
  const double samples = std::ceil(-std::log(kTransientDecay) / (rate * cfg.sample_time));
  return samples < 1e12 ? static_cast<std::uint64_t>(samples) : std::uint64_t{1000000000000};
}

void RecursiveEstimator::Impl::save_good() {
  for (auto& b : blocks) {
    b.good_theta = b.theta;
    b.good_P = b.P;
  }
  e_var_good = e_var;
  updates_since_good = 0;
}

void RecursiveEstimator::Impl::restore_good(const char* reason) {
  for (auto& b : blocks) {
    b.theta = b.good_theta;
    b.P = b.good_P;
    rediscretise(b);
  }
  // The noise level goes back with the state. The first residuals on the
  // restarted filters are their transient, not noise: they must not set e_var
  // again (as the very first residual does), only the outlier test restarts
  // (after a hundred residuals, as at the start).
  e_var = e_var_good;
  e_count = 1;
  restart_filters();
  // Give the restored state one residual window before judging it again.
  rearm = static_cast<std::uint64_t>(1.0 / (1.0 - e_alpha));
  ++status.resets;
  status.last_reset_reason = reason;
}

}  // namespace modalwatch
