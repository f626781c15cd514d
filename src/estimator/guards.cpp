// The guards of the recursive estimator that act on its whole state: the
// stability projection of A, the restart of the filters after a gap, and the
// last good state it saves now and then and returns to on a reset (a
// divergence, a non-finite model or update). The per-sample checks that
// trigger them (outliers, divergence, excitation) are steps 2 and 3 of
// step.cpp.
#include <cmath>
#include <cstdint>

#include <Eigen/Core>

#include "modalwatch/polynomial.hpp"
#include "impl.hpp"

namespace modalwatch {

namespace detail {

// Orders 1 and 2 in closed form without allocation; higher orders through the
// general routine (allocates, only when A is unstable).
bool project(double* a_part, int n) {
  constexpr double margin = 1e-6;
  if (n == 1) {
    if (a_part[0] > 0.0) return false;
    a_part[0] = a_part[0] < 0.0 ? -a_part[0] : margin;
    return true;
  }
  if (n == 2) {
    double& a1 = a_part[0];
    double& a2 = a_part[1];
    if (a1 > 0.0 && a2 > 0.0) return false;
    if (a2 > 0.0) {
      // Both roots in the closed right half plane: reflecting both flips their sum.
      a1 = a1 < 0.0 ? -a1 : 2.0 * margin * std::sqrt(a2);
    } else if (a2 < 0.0) {
      // Real roots of opposite sign: reflect the positive one.
      a1 = std::sqrt(a1 * a1 - 4.0 * a2);
      a2 = -a2;
    } else {
      return false;  // degenerate (order drop): caller rejects
    }
    return true;
  }
  Eigen::Map<Eigen::VectorXd> part(a_part, n);
  Eigen::VectorXd a = part;
  if (!project_stable(a)) return false;
  part = a;
  return true;
}

}  // namespace detail

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
