#pragma once
// Experiments shared by the suites that fit simulated plants.
#include <cstdint>

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

}  // namespace modalwatch::test_support
