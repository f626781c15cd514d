#include "modalwatch/estimator.hpp"
#include "modalwatch/fault_detector.hpp"

namespace modalwatch {

DetectorInput::DetectorInput(const RecursiveEstimator& estimator)
    : value_(static_cast<std::size_t>(estimator.submodels())),
      covariance_(value_.size(), Eigen::Matrix3d::Zero()),
      settle_covariance_(value_.size(), Eigen::Matrix3d::Zero()),
      warming_up_(estimator.status().warming_up),
      fits_(estimator.status().fits) {}

bool DetectorInput::fitted_in_step(const EstimatorStatus& status) {
  const bool fit = (warming_up_ && !status.warming_up) || status.fits != fits_;
  warming_up_ = status.warming_up;
  fits_ = status.fits;
  if (fit) fitted(status.fitted_window);
  return fit;
}

void DetectorInput::read(const RecursiveEstimator& estimator) {
  for (std::size_t k = 0; k < value_.size(); ++k) {
    const int i = static_cast<int>(k);
    value_[k] = estimator.mode(i).value;
    covariance_[k] = estimator.mode_covariance(i);
    settle_covariance_[k] = estimator.mode_covariance_given_others(i);
  }
}

void DetectorInput::update(FaultDetector& detector, double t, bool valid, std::vector<FlagChange>& changes) {
  detector.update(t, value_, covariance_, valid, changes, evidence_span_, &settle_covariance_);
  if (valid) evidence_span_ = 0.0;
}

}  // namespace modalwatch
