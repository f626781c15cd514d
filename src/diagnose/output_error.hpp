#pragma once
// The output-error refinement of diagnose: Levenberg-Marquardt on the
// simulated augmented model's output error, with a forward-difference
// Jacobian, in parameters scaled by their start values (p = p0 (1 + delta)).
// Private to src/diagnose (and its benchmark).
#include <limits>

#include <Eigen/Core>

#include "modalwatch/diagnose.hpp"
#include "modalwatch/record.hpp"

namespace modalwatch::diagnose_detail {

inline constexpr double kInf = std::numeric_limits<double>::infinity();

struct Problem {
  const Record& data;
  const LoopSpec& loop;
  long* simulations = nullptr;  // when set, counts the model's simulations (its benchmark)
};

// p = [free_beta; effect parameters that are on], in physical units (a
// shared A counts once: free_beta in model.hpp).
Eigen::VectorXd pack(const AugmentedModel& m);
void unpack(const Eigen::VectorXd& p, AugmentedModel& m);

// Simulated output, or empty when the model cannot be simulated or diverges.
Eigen::VectorXd output(const AugmentedModel& m, const Problem& pb);
// Sum of squared output errors; infinity when y_hat is empty or not finite.
double cost_of(const Eigen::VectorXd& y_hat, const Eigen::VectorXd& y);

struct Refined {
  AugmentedModel model;
  double cost = kInf;  // sum of squared output errors on the estimation part
  // Of pack(model): sigma^2 (J^T J)^{-1} at the model (refine's with_covariance); else empty.
  Eigen::MatrixXd covariance;
};

// At most `iterations` Levenberg-Marquardt steps from `start`; with
// iterations = 0 and with_covariance the model stays and gets its covariance.
Refined refine(const AugmentedModel& start, const Problem& pb, int iterations, bool with_covariance = false);

}  // namespace modalwatch::diagnose_detail
