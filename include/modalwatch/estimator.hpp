#pragma once
// The recursive additive RSRIVC estimator (Algorithm 1 of the paper): per
// sample, M_l block-coordinate iterations over the K submodels, each with
// M_s SRIVC refinements, updating theta_i and P_i by eqs. (23)-(25) with a
// forgetting factor per submodel. Open loop (instrument eq. 28) or closed loop
// (instrument eq. 29 from z = S_uo(q, t_k) r, a noise-free simulation of the
// loop with the known controller and the current model); rigid-body submodels
// (eqs. 32-33); stability projection of every A_i before it is used as a
// prefilter or auxiliary model; output subsampling (section 4.7).
//
// A plain class: no I/O, no threads, no exceptions and no heap allocation in
// step() once warm-up is over. Everything a caller needs to know about bad
// input (NaN samples, gaps, outliers, low excitation, resets) is counted in
// status().
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "modalwatch/model.hpp"
#include "modalwatch/prefilter.hpp"
#include "modalwatch/transfer_function.hpp"

namespace modalwatch {

struct EstimatorSettings {
  double sample_time = 0.0;  // s
  bool closed_loop = false;
  DiscreteTransferFunction controller;  // closed loop: u = C_d(q)(r - y)
  Hold output_hold = Hold::zoh;         // intersample behaviour of y in the prefilters

  int block_iterations = 1;   // M_l
  int refinements = 0;        // M_s
  int update_divisor = 1;     // subsampling: update every n-th sample, filter every sample
  std::vector<double> forgetting;  // lambda_i in (0, 1], one per submodel

  // Initialisation (section 4.7). With warmup_samples > 0 the filters run over
  // the warm-up window and theta(t0), P(t0) come from the offline additive
  // SRIVC on that window (unless fit_on_warmup is false).
  int warmup_samples = 0;
  bool fit_on_warmup = true;
  int warmup_iterations = 50;
  // P(t0) when not from the warm-up fit: given per submodel (diagonal, physical
  // units of theta_i^2 per output unit^2), or relative: diag((rho theta_j)^2)/var(y).
  std::vector<Eigen::VectorXd> initial_covariance;
  double initial_covariance_relative = 0.1;

  // Guards (DESIGN.md point 4).
  double random_walk = 0.0;        // Q = random_walk^2 diag(theta'^2) added to P at each update
  double covariance_bound = 100.0; // diag(P_i) is held below this times diag(P_i(t0))
  double divergence_ratio = 10.0;  // residual RMS this many times its last good value: reset
  double gap_factor = 1.5;         // a time step above gap_factor T is a gap: filter states reset
  double outlier_sigma = 10.0;     // |y - y_hat| above this many residual std: sample replaced
  double residual_window = 0.0;    // s, residual RMS window (0: 1/(1 - min lambda) samples)
  double low_excitation_ratio = 0.05;  // input power below this fraction of its reference: no update
  double low_excitation_window = 0.0;  // s (0: one period of the slowest mode)
};

struct Sample {
  double t = 0.0, u = 0.0, y = 0.0, r = 0.0;
};

struct EstimatorStatus {
  std::uint64_t samples = 0;        // accepted samples
  std::uint64_t updates = 0;        // parameter updates
  std::uint64_t rejected_nonfinite = 0;
  std::uint64_t rejected_out_of_order = 0;
  std::uint64_t gaps = 0;
  std::uint64_t outliers = 0;
  std::uint64_t low_excitation_samples = 0;
  std::uint64_t projections = 0;
  std::uint64_t covariance_clamps = 0;
  std::uint64_t resets = 0;         // returns to the last good state
  const char* last_reset_reason = "";
  bool warming_up = true;
  bool low_excitation = false;
  bool warmup_fit_used = false;     // theta(t0) from the offline fit on the warm-up window
};

// What step() did with a sample (bit flags).
enum StepFlags : unsigned {
  kUpdated = 1u << 0,
  kRejectedNonFinite = 1u << 1,
  kRejectedOutOfOrder = 1u << 2,
  kGap = 1u << 3,
  kOutlier = 1u << 4,
  kLowExcitation = 1u << 5,
  kReset = 1u << 6,
  kWarmingUp = 1u << 7,
};

struct ModeEstimate {
  ModalParameters value;
  ModalParameters std;
};

class RecursiveEstimator {
 public:
  // Throws std::invalid_argument on an inconsistent configuration.
  RecursiveEstimator(const AdditiveModel& initial, const EstimatorSettings& settings);
  ~RecursiveEstimator();
  RecursiveEstimator(RecursiveEstimator&&) noexcept;
  RecursiveEstimator& operator=(RecursiveEstimator&&) noexcept;

  // One sample. No allocation, no exceptions after warm-up.
  unsigned step(const Sample& sample) noexcept;

  int submodels() const;
  // Current estimate of submodel i in physical units (allocates: call outside the hot path
  // or use mode()).
  Submodel submodel(int i) const;
  AdditiveModel model() const;
  // Modal view of submodel i and its standard deviations (sigma^2 P_i). No allocation.
  ModeEstimate mode(int i) const noexcept;
  // Covariance of theta_i (physical units), sigma^2 P_i.
  Eigen::MatrixXd covariance(int i) const;
  double residual_rms() const noexcept;  // output error over the residual window
  double noise_variance() const noexcept;
  const EstimatorStatus& status() const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace modalwatch
