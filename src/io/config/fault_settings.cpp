// fault_detector_settings: the one translation of a Config into the fault
// detector's settings, shared by the daemon and `track --faults`.
#include <cstddef>

#include "modalwatch/io/config.hpp"

namespace modalwatch {

FaultDetectorSettings fault_detector_settings(const Config& config) {
  const FaultSettings& f = config.faults;
  const std::size_t n = config.model.submodels.size();
  FaultDetectorSettings s;
  for (const auto& sub : config.model.submodels) s.mode_names.push_back(sub.name);
  s.baselines = f.baselines;
  s.baselines.resize(n);
  bool any_std = false;
  for (const auto& sd : f.baseline_std) any_std = any_std || sd.has_value();
  if (any_std) {
    s.baseline_std.assign(n, ModalParameters{0.0, 0.0, 0.0});
    for (std::size_t i = 0; i < n && i < f.baseline_std.size(); ++i)
      if (f.baseline_std[i]) s.baseline_std[i] = *f.baseline_std[i];
  }
  s.learn_window = f.learn_window;
  // The estimator forgets with lambda_i per sample (eq. 13): its errors decorrelate
  // over Ts / (1 - lambda_i). Without forgetting there is no such time; the
  // learning window, the longest span the detector averages over, stands in.
  for (std::size_t i = 0; i < n; ++i) {
    const double lambda = i < config.estimator.forgetting.size() ? config.estimator.forgetting[i] : 1.0;
    s.memory_time.push_back(lambda < 1.0 ? config.sample_time / (1.0 - lambda) : f.learn_window);
  }
  s.update_period = config.daemon.publish_period;
  s.false_alarm_interval = f.false_alarm_interval;
  s.cusum_shift = f.cusum_shift;
  s.settle_std_fraction = f.settle_std_fraction;
  s.settle_change_fraction = f.settle_change_fraction;
  s.thresholds = f.thresholds;
  return s;
}

}  // namespace modalwatch
