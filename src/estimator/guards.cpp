// The guards of the recursive estimator that act on its whole state: the
// restart of the filters after a gap, and the last good state it saves now and
// then and returns to on a reset (a divergence, a non-finite model or update).
// The per-sample checks that trigger them (outliers, divergence, excitation)
// are steps 2 and 3 of step.cpp; the stability projection is update.hpp's.
#include <cmath>
#include <cstdint>

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
// warm-up (section 4.7), the filters run without updating theta until the output
// error is back near the noise level (at most kSettleWindows residual windows,
// after which updates resume so that a plant that changed during the gap can
// still be followed); the divergence detector is not consulted meanwhile.
void RecursiveEstimator::Impl::restart_filters() {
  constexpr double kSettleWindows = 4.0;
  reset_filters();
  // Unsettled until the short-term error, started at the divergence level, has
  // come down to near the noise level on the restarted filters' own output.
  e_short = cfg.divergence_ratio * cfg.divergence_ratio * e_var_good;
  settling = static_cast<std::uint64_t>(kSettleWindows / (1.0 - e_alpha));
  outlier_run = 0;
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
  e_var = e_var_good;
  e_count = 0;  // outlier statistics restart with the filters
  restart_filters();
  // Give the restored state one residual window before judging it again.
  rearm = static_cast<std::uint64_t>(1.0 / (1.0 - e_alpha));
  ++status.resets;
  status.last_reset_reason = reason;
}

}  // namespace modalwatch
