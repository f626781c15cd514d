#include "modalwatch/estimator.hpp"
#include "modalwatch/fault_detector.hpp"

namespace modalwatch {

DetectorInput::DetectorInput(const RecursiveEstimator& estimator)
    : value_(static_cast<std::size_t>(estimator.submodels())),
      covariance_(value_.size(), Eigen::Matrix3d::Zero()),
      settle_covariance_(value_.size(), Eigen::Matrix3d::Zero()),
      sampling_covariance_(value_.size(), Eigen::Matrix3d::Zero()),
      joint_(Eigen::MatrixXd::Zero(3 * static_cast<Eigen::Index>(value_.size()),
                                   3 * static_cast<Eigen::Index>(value_.size()))),
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
    sampling_covariance_[k] = estimator.mode_sampling_covariance(i);
  }
  for (std::size_t k = 0; k < value_.size(); ++k) {
    const auto at = static_cast<Eigen::Index>(3 * k);
    joint_.block<3, 3>(at, at) = covariance_[k];
    for (std::size_t l = k + 1; l < value_.size(); ++l) {
      const auto to = static_cast<Eigen::Index>(3 * l);
      joint_.block<3, 3>(at, to) = estimator.mode_cross_covariance(static_cast<int>(k), static_cast<int>(l));
      joint_.block<3, 3>(to, at) = joint_.block<3, 3>(at, to).transpose();
    }
  }
}

void DetectorInput::update(FaultDetector& detector, double t, bool valid, std::vector<FlagChange>& changes) {
  detector.update(t, value_, covariance_, valid, changes, evidence_span_, &settle_covariance_, &joint_,
                  &sampling_covariance_);
  if (valid) evidence_span_ = 0.0;
}

}  // namespace modalwatch
