#pragma once
// What the config suites share: two valid files whose line numbers the
// expected messages refer to, and small editing helpers.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "support.hpp"

#include "modalwatch/error.hpp"
#include "modalwatch/io/config.hpp"

namespace fs = std::filesystem;
using modalwatch::Config;
using modalwatch::FaultDetector;
using modalwatch::FaultDetectorSettings;
using modalwatch::InputError;
using modalwatch::parse_config;

namespace {

#define EXPECT_CONTAINS(text, part) EXPECT_NE(std::string(text).find(part), std::string::npos) << "message: " << (text)

constexpr double kTwoPi = 6.283185307179586476925286766559;

// A valid open-loop file; tests edit single lines, so the line numbers in the
// expected messages can be read off here.
const std::string kBase =
    "sample_rate_hz: 20\n"       // 1
    "model:\n"                   // 2
    "  loop: open\n"             // 3
    "  submodels:\n"             // 4
    "    - name: m1\n"           // 5
    "      kind: mode\n"         // 6
    "      wn: 2.0\n"            // 7
    "      zeta: 0.25\n"         // 8
    "      gain: 3.0\n"          // 9
    "      forgetting: 0.99\n"   // 10
    "    - name: m2\n"           // 11
    "      frequency_hz: 1.0\n"  // 12
    "      zeta: 0.1\n"          // 13
    "      gain: 1.0\n";         // 14

// Closed loop with a controller, a plant and a simulation.
const std::string kClosed =
    "sample_rate_hz: 20\n"                            // 1
    "model:\n"                                        // 2
    "  loop: closed\n"                                // 3
    "  submodels:\n"                                  // 4
    "    - {name: m1, wn: 2, zeta: 0.25, gain: 3}\n"  // 5
    "controller:\n"                                   // 6
    "  numerator: [0.02329, -0.02058, 0.00454]\n"     // 7
    "  denominator: [1, -1, 0]\n"                     // 8
    "plant:\n"                                        // 9
    "  noise_variance: 0.01\n"                        // 10
    "  modes:\n"                                      // 11
    "    - name: m1\n"                                // 12
    "      wn: 2.0\n"                                 // 13
    "      zeta: 0.25\n"                              // 14
    "      gain: 3.0\n"                               // 15
    "      trajectory:\n"                             // 16
    "        wn: [[100, 2.0], [300, 1.6]]\n"          // 17
    "    - name: body\n"                              // 18
    "      kind: rigid_body\n"                        // 19
    "      gain: 0.01\n"                              // 20
    "simulation:\n"                                   // 21
    "  duration: 10\n"                                // 22
    "  seed: 7\n"                                     // 23
    "  reference:\n"                                  // 24
    "    type: sum_of_sines\n"                        // 25
    "    amplitudes: [3, 1]\n"                        // 26
    "    frequencies_rad_s: [0.005, 2]\n";            // 27

// `text` with the first occurrence of `from` replaced by `to`.
[[maybe_unused]] std::string edit(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << "test bug: '" << from << "' not in the text";
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

using modalwatch::test_support::error_of;

[[maybe_unused]] std::string parse_error(const std::string& yaml) {
  return error_of([&] { parse_config(yaml, "test.yaml"); });
}

// An estimator: section after kBase (its lines 15 ..).
const std::string kEstimator =
    "estimator:\n"                          // 15
    "  block_iterations: 3\n"               // 16
    "  refinements: 2\n"                    // 17
    "  update_divisor: 4\n"                 // 18
    "  warmup: 12.5\n"                      // 19
    "  fit_on_warmup: false\n"              // 20
    "  warmup_iterations: 20\n"             // 21
    "  initial_covariance_relative: 0.5\n"  // 22
    "  random_walk: 1.0e-4\n"               // 23
    "  covariance_bound: 50\n"              // 24
    "  divergence_ratio: 4\n"               // 25
    "  gap_factor: 2.5\n"                   // 26
    "  outlier_sigma: 6\n"                  // 27
    "  residual_window: 30\n"               // 28
    "  low_excitation_ratio: 0.2\n"         // 29
    "  low_excitation_window: 8\n"          // 30
    "  change_ratio: 3\n"                   // 31
    "  change_threshold: 12\n"              // 32
    "  change_hold: 0.5\n";                 // 33

[[maybe_unused]] void expect_estimator_defaults(const modalwatch::EstimatorSettings& e, int warmup_samples) {
  const modalwatch::EstimatorSettings d;
  EXPECT_EQ(e.block_iterations, d.block_iterations);
  EXPECT_EQ(e.refinements, d.refinements);
  EXPECT_EQ(e.update_divisor, d.update_divisor);
  EXPECT_EQ(e.warmup_samples, warmup_samples);
  EXPECT_EQ(e.fit_on_warmup, d.fit_on_warmup);
  EXPECT_EQ(e.warmup_iterations, d.warmup_iterations);
  EXPECT_EQ(e.initial_covariance_relative, d.initial_covariance_relative);
  EXPECT_EQ(e.random_walk, d.random_walk);
  EXPECT_EQ(e.covariance_bound, d.covariance_bound);
  EXPECT_EQ(e.divergence_ratio, d.divergence_ratio);
  EXPECT_EQ(e.gap_factor, d.gap_factor);
  EXPECT_EQ(e.outlier_sigma, d.outlier_sigma);
  EXPECT_EQ(e.residual_window, d.residual_window);
  EXPECT_EQ(e.low_excitation_ratio, d.low_excitation_ratio);
  EXPECT_EQ(e.low_excitation_window, d.low_excitation_window);
  EXPECT_EQ(e.change_ratio, d.change_ratio);
  EXPECT_EQ(e.change_threshold, d.change_threshold);
  EXPECT_EQ(e.change_hold, d.change_hold);
}

// Every `estimator:` key with a value other than its default; appended to
// kBase, so the section starts on line 15.

}  // namespace
