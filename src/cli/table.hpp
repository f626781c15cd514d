#pragma once
// The modal table that `fit` and `track` print: per submodel its frequency (Hz,
// rad/s), damping and gain with standard deviations, or for rigid bodies and
// general transfer functions their coefficients and resonances.
#include <vector>

#include <Eigen/Core>

#include "modalwatch/model.hpp"

namespace modalwatch::cli {

// covariances[i]: covariance of theta_i in physical units (zeros when unknown).
void print_modal_table(const AdditiveModel& model, const std::vector<Eigen::MatrixXd>& covariances);

}  // namespace modalwatch::cli
