#pragma once
// Excitation signals for simulation: inputs in open loop, references in closed loop.
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace modalwatch {

struct SignalSpec {
  enum class Kind { sum_of_sines, multisine, prbs, square, csv };
  Kind kind = Kind::sum_of_sines;

  // sum_of_sines: sum_k amplitudes[k] sin(frequencies_rad_s[k] t + phases[k])
  std::vector<double> amplitudes;
  std::vector<double> frequencies_rad_s;
  std::vector<double> phases;

  // multisine: random-phase multisine (Schroeder-like flat amplitude spectrum)
  // over [f_min_hz, f_max_hz] on the grid 1/period_s, scaled to `rms`.
  double f_min_hz = 0.0;
  double f_max_hz = 0.0;
  double period_s = 0.0;
  double rms = 1.0;

  // prbs: maximum-length sequence of `register_bits` (2..31), levels +-amplitude,
  // each value held for `clock_period` samples.
  int register_bits = 10;
  int clock_period = 1;
  double amplitude = 1.0;
  // The sequence starts this many register steps in: input j of n takes
  // j (2^register_bits - 1) / n, so that shifted copies of one sequence drive
  // several inputs uncorrelated over whole periods.
  long long prbs_shift = 0;

  // square: amplitude * sign(sin(2 pi frequency_hz t)), plus offset.
  double frequency_hz = 1.0;
  double offset = 0.0;

  // csv: a column of a CSV file (or of an LCM log's samples: t, u, y, r),
  // interpolated linearly onto the time grid.
  std::string csv_path;
  std::string csv_column;
  std::string csv_channel;  // LCM log: the channel of the samples (empty: the only one)

  std::uint64_t seed = 1;  // random phases (multisine)

  bool operator==(const SignalSpec&) const = default;
};

// The signal at the instants t. Kind::csv throws std::invalid_argument here:
// files are read by the I/O layer, which passes the samples in `samples`.
Eigen::VectorXd generate(const SignalSpec& spec, const Eigen::VectorXd& t);

}  // namespace modalwatch
