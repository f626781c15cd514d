#pragma once
// Experiments shared by the suites that fit simulated plants.
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "modalwatch/simulator.hpp"

namespace modalwatch::test_support {

// Open loop, a unit PRBS input of `register_bits` clocked every `clock` samples.
inline ExperimentSpec open_loop_prbs(double T, double duration, std::uint64_t seed, int clock = 1,
                                     int register_bits = 12) {
  ExperimentSpec e;
  e.sample_time = T;
  e.duration = duration;
  e.seed = seed;
  e.excitation.kind = SignalSpec::Kind::prbs;
  e.excitation.register_bits = register_bits;
  e.excitation.clock_period = clock;
  e.excitation.amplitude = 1.0;
  return e;
}

// Open loop, a multisine of `rms` on the grid k / period_s inside [f_min_hz,
// f_max_hz], its phases drawn from `seed`.
inline ExperimentSpec open_loop_multisine(double T, double duration, std::uint64_t seed, double f_min_hz,
                                          double f_max_hz, double period_s, double rms) {
  ExperimentSpec e;
  e.sample_time = T;
  e.duration = duration;
  e.seed = seed;
  e.excitation.kind = SignalSpec::Kind::multisine;
  e.excitation.f_min_hz = f_min_hz;
  e.excitation.f_max_hz = f_max_hz;
  e.excitation.period_s = period_s;
  e.excitation.rms = rms;
  e.excitation.seed = seed;
  return e;
}

// n samples of unit white Gaussian noise from `seed`: a second shaker's input.
inline Eigen::VectorXd white_noise(Eigen::Index n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::VectorXd v(n);
  for (Eigen::Index k = 0; k < n; ++k) v(k) = normal(rng);
  return v;
}

// A plant of plain modes named mode1, mode2, ..., with output noise at snr_db.
inline PlantSpec plant_of(const std::vector<ModalParameters>& modes, double snr_db) {
  PlantSpec p;
  for (std::size_t i = 0; i < modes.size(); ++i) {
    PlantMode pm;
    pm.modal = modes[i];
    pm.submodel = make_mode("mode" + std::to_string(i + 1), modes[i]);
    p.modes.push_back(pm);
  }
  p.snr_db = snr_db;
  return p;
}

}  // namespace modalwatch::test_support
