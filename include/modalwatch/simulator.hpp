#pragma once
// Data from a plant described as a sum of modes whose parameters follow
// piecewise-linear trajectories in time, exactly discretised under ZOH, in open
// loop or in closed loop with a discrete controller C_d(q).
#include <algorithm>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "modalwatch/effects.hpp"
#include "modalwatch/model.hpp"
#include "modalwatch/record.hpp"
#include "modalwatch/signals.hpp"
#include "modalwatch/transfer_function.hpp"

namespace modalwatch {

// A quantity over time: piecewise linear through the points (t, value), held
// constant before the first and after the last. Empty means constant `base`.
struct Trajectory {
  std::vector<std::pair<double, double>> points;
  double at(double t, double base) const;
  bool operator==(const Trajectory&) const = default;
};

struct PlantMode {
  // A resonant mode (wn, zeta, gain), or any submodel given by its coefficients
  // (rigid bodies, higher orders), which then stays constant in time.
  Submodel submodel;
  bool resonant = true;   // trajectories apply to (wn, zeta, gain)
  ModalParameters modal;  // nominal values when resonant
  Trajectory wn, zeta, gain;
  bool operator==(const PlantMode&) const = default;
};

struct PlantSpec {
  std::vector<PlantMode> modes;
  // Output noise: white Gaussian with this variance, or set by snr_db
  // (10 log10 of noise-free output power over noise power) when given.
  double noise_variance = 0.0;
  std::optional<double> snr_db;
  PlantEffects effects;  // none by default (include/modalwatch/effects.hpp)
  bool operator==(const PlantSpec&) const = default;
};

struct ExperimentSpec {
  double sample_time = 0.05;  // s
  double duration = 10.0;     // s
  std::uint64_t seed = 1;     // noise
  bool closed_loop = false;
  DiscreteTransferFunction controller;  // closed loop: u = C_d(q)(r - y)
  SignalSpec excitation;                // input (open loop) or reference (closed loop)
  // Samples of the excitation when it comes from a file (SignalSpec::Kind::csv),
  // already on the time grid.
  Eigen::VectorXd excitation_samples;
  // Open loop with several actuators: inputs 2, 3, ..., which drive the modes
  // whose submodel.input is 1, 2, ... (the effects act on the first input
  // only). Input j + 2 is further_input_samples[j] when that is given (a file,
  // already on the time grid), else generated from further_excitations[j].
  // Both empty for one input.
  std::vector<SignalSpec> further_excitations;
  std::vector<Eigen::VectorXd> further_input_samples;
  int further_inputs() const {
    return static_cast<int>(std::max(further_excitations.size(), further_input_samples.size()));
  }

  bool operator==(const ExperimentSpec& other) const;
};

struct SimulationResult {
  Record record;            // t, r (closed loop), u, y
  Eigen::VectorXd y_clean;  // noise-free output
  // Truth over time: one row per sample, columns per mode <name>_wn, <name>_zeta,
  // <name>_gain (resonant modes) and theta entries otherwise.
  std::vector<std::string> truth_columns;
  Eigen::MatrixXd truth;
  double noise_variance = 0.0;  // the variance actually used
};

// Throws std::invalid_argument on an inconsistent spec and std::domain_error
// when the simulated output diverges (naming the time it does).
SimulationResult simulate(const PlantSpec& plant, const ExperimentSpec& experiment);

// The plant's model at time t (the truth the estimators are judged against).
AdditiveModel plant_model_at(const PlantSpec& plant, double t);

}  // namespace modalwatch
