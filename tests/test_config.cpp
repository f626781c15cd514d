// The YAML configuration: every validation of config/README.md with the exact
// file:line and key path of its message, the shipped configs, csv signals, and
// the round trip through config_to_yaml.
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

#include "modalwatch/io/config.hpp"
#include "modalwatch/error.hpp"

namespace fs = std::filesystem;
using modalwatch::Config;
using modalwatch::InputError;
using modalwatch::parse_config;

namespace {

#define EXPECT_CONTAINS(text, part) \
  EXPECT_NE(std::string(text).find(part), std::string::npos) << "message: " << (text)

constexpr double kTwoPi = 6.283185307179586476925286766559;

// A valid open-loop file; tests edit single lines, so the line numbers in the
// expected messages can be read off here.
const std::string kBase =
    "sample_rate_hz: 20\n"          // 1
    "model:\n"                      // 2
    "  loop: open\n"                // 3
    "  submodels:\n"                // 4
    "    - name: m1\n"              // 5
    "      kind: mode\n"            // 6
    "      wn: 2.0\n"               // 7
    "      zeta: 0.25\n"            // 8
    "      gain: 3.0\n"             // 9
    "      forgetting: 0.99\n"      // 10
    "    - name: m2\n"              // 11
    "      frequency_hz: 1.0\n"     // 12
    "      zeta: 0.1\n"             // 13
    "      gain: 1.0\n";            // 14

// Closed loop with a controller, a plant and a simulation.
const std::string kClosed =
    "sample_rate_hz: 20\n"                          // 1
    "model:\n"                                      // 2
    "  loop: closed\n"                              // 3
    "  submodels:\n"                                // 4
    "    - {name: m1, wn: 2, zeta: 0.25, gain: 3}\n"  // 5
    "controller:\n"                                 // 6
    "  numerator: [0.02329, -0.02058, 0.00454]\n"   // 7
    "  denominator: [1, -1, 0]\n"                   // 8
    "plant:\n"                                      // 9
    "  noise_variance: 0.01\n"                      // 10
    "  modes:\n"                                    // 11
    "    - name: m1\n"                              // 12
    "      wn: 2.0\n"                               // 13
    "      zeta: 0.25\n"                            // 14
    "      gain: 3.0\n"                             // 15
    "      trajectory:\n"                           // 16
    "        wn: [[100, 2.0], [300, 1.6]]\n"        // 17
    "    - name: body\n"                            // 18
    "      kind: rigid_body\n"                      // 19
    "      gain: 0.01\n"                            // 20
    "simulation:\n"                                 // 21
    "  duration: 10\n"                              // 22
    "  seed: 7\n"                                   // 23
    "  reference:\n"                                // 24
    "    type: sum_of_sines\n"                      // 25
    "    amplitudes: [3, 1]\n"                      // 26
    "    frequencies_rad_s: [0.005, 2]\n";          // 27

// `text` with the first occurrence of `from` replaced by `to`.
std::string edit(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << "test bug: '" << from << "' not in the text";
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

using modalwatch::test_support::error_of;

std::string parse_error(const std::string& yaml) {
  return error_of([&] { parse_config(yaml, "test.yaml"); });
}

// ---------------------------------------------------------------- valid files

TEST(Config, ParsesBase) {
  const Config c = parse_config(kBase, "test.yaml");
  EXPECT_EQ(c.source, "test.yaml");
  EXPECT_DOUBLE_EQ(c.sample_time, 0.05);
  EXPECT_FALSE(c.closed_loop);
  EXPECT_EQ(c.output_hold, modalwatch::Hold::zoh);
  ASSERT_EQ(c.model.submodels.size(), 2u);
  ASSERT_EQ(c.submodel_settings.size(), 2u);
  const auto& m1 = c.model.submodels[0];
  EXPECT_EQ(m1.name, "m1");
  EXPECT_TRUE(m1.is_mode());
  EXPECT_DOUBLE_EQ(m1.a(1), 0.25);  // 1 / wn^2
  EXPECT_DOUBLE_EQ(m1.a(0), 0.25);  // 2 zeta / wn
  EXPECT_DOUBLE_EQ(m1.b(0), 3.0);
  EXPECT_DOUBLE_EQ(c.submodel_settings[0].forgetting, 0.99);
  EXPECT_DOUBLE_EQ(c.submodel_settings[1].forgetting, 1.0);
  // kind defaults to mode; frequency_hz becomes rad/s.
  const auto modal = modalwatch::modal_parameters(c.model.submodels[1]);
  EXPECT_NEAR(modal.wn, kTwoPi, 1e-12);
  EXPECT_NEAR(modal.zeta, 0.1, 1e-12);
  EXPECT_TRUE(c.controller.empty());
  EXPECT_FALSE(c.plant.has_value());
  EXPECT_FALSE(c.experiment.has_value());
}

TEST(Config, ParsesClosedLoopPlantAndSimulation) {
  const Config c = parse_config(kClosed, "test.yaml");
  EXPECT_TRUE(c.closed_loop);
  ASSERT_FALSE(c.controller.empty());
  ASSERT_TRUE(c.plant.has_value());
  ASSERT_EQ(c.plant->modes.size(), 2u);
  const auto& m1 = c.plant->modes[0];
  EXPECT_TRUE(m1.resonant);
  EXPECT_DOUBLE_EQ(m1.modal.wn, 2.0);
  ASSERT_EQ(m1.wn.points.size(), 2u);
  EXPECT_EQ(m1.wn.points[1], std::make_pair(300.0, 1.6));
  EXPECT_TRUE(m1.zeta.points.empty());
  const auto& body = c.plant->modes[1];
  EXPECT_FALSE(body.resonant);
  EXPECT_EQ(body.submodel.n, 0);
  EXPECT_EQ(body.submodel.rigid_poles, 2);  // the rigid_body default
  EXPECT_DOUBLE_EQ(body.submodel.b(0), 0.01);
  EXPECT_DOUBLE_EQ(c.plant->noise_variance, 0.01);
  ASSERT_TRUE(c.experiment.has_value());
  const auto& e = *c.experiment;
  EXPECT_DOUBLE_EQ(e.sample_time, 0.05);
  EXPECT_DOUBLE_EQ(e.duration, 10.0);
  EXPECT_EQ(e.seed, 7u);
  EXPECT_TRUE(e.closed_loop);
  EXPECT_EQ(e.controller.denominator().size(), 3u);
  EXPECT_EQ(e.excitation.kind, modalwatch::SignalSpec::Kind::sum_of_sines);
  EXPECT_EQ(e.excitation.amplitudes, (std::vector<double>{3, 1}));
  EXPECT_EQ(e.excitation.frequencies_rad_s, (std::vector<double>{0.005, 2}));
  EXPECT_EQ(e.excitation.seed, 7u);
}

TEST(Config, EstimatorSettingsFollowTheOtherSections) {
  const Config c = parse_config(kClosed, "test.yaml");
  EXPECT_DOUBLE_EQ(c.estimator.sample_time, 0.05);
  EXPECT_TRUE(c.estimator.closed_loop);
  EXPECT_EQ(c.estimator.controller.denominator(), c.controller.denominator());
  EXPECT_EQ(c.estimator.output_hold, c.output_hold);
  const Config b = parse_config(kBase, "test.yaml");
  EXPECT_EQ(b.estimator.forgetting, (std::vector<double>{0.99, 1.0}));
  EXPECT_FALSE(b.estimator.closed_loop);
  // One slot per submodel, empty where no initial_covariance is given.
  ASSERT_EQ(b.estimator.initial_covariance.size(), 2u);
  EXPECT_EQ(b.estimator.initial_covariance[0].size(), 0);
  EXPECT_EQ(b.estimator.initial_covariance[1].size(), 0);
}

// The EstimatorSettings keys of the `estimator:` section (not those the other
// sections fill in) are those of a default EstimatorSettings.
void expect_estimator_defaults(const modalwatch::EstimatorSettings& e, int warmup_samples) {
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
}

// Every `estimator:` key with a value other than its default; appended to
// kBase, so the section starts on line 15.
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
    "  low_excitation_window: 8\n";         // 30

TEST(Config, EstimatorDefaultsWithoutTheSection) {
  expect_estimator_defaults(parse_config(kBase, "test.yaml").estimator, 0);
  expect_estimator_defaults(parse_config(kBase + "estimator: {}\n", "test.yaml").estimator, 0);
}

TEST(Config, EstimatorParsesEveryKey) {
  const Config c = parse_config(kBase + kEstimator, "test.yaml");
  const auto& e = c.estimator;
  EXPECT_EQ(e.block_iterations, 3);
  EXPECT_EQ(e.refinements, 2);
  EXPECT_EQ(e.update_divisor, 4);
  EXPECT_EQ(e.warmup_samples, 250);  // 12.5 s at 20 Hz
  EXPECT_FALSE(e.fit_on_warmup);
  EXPECT_EQ(e.warmup_iterations, 20);
  EXPECT_DOUBLE_EQ(e.initial_covariance_relative, 0.5);
  EXPECT_DOUBLE_EQ(e.random_walk, 1e-4);
  EXPECT_DOUBLE_EQ(e.covariance_bound, 50.0);
  EXPECT_DOUBLE_EQ(e.divergence_ratio, 4.0);
  EXPECT_DOUBLE_EQ(e.gap_factor, 2.5);
  EXPECT_DOUBLE_EQ(e.outlier_sigma, 6.0);
  EXPECT_DOUBLE_EQ(e.residual_window, 30.0);
  EXPECT_DOUBLE_EQ(e.low_excitation_ratio, 0.2);
  EXPECT_DOUBLE_EQ(e.low_excitation_window, 8.0);
  // Still completed from the other sections.
  EXPECT_DOUBLE_EQ(e.sample_time, 0.05);
  EXPECT_EQ(e.forgetting, (std::vector<double>{0.99, 1.0}));
  EXPECT_EQ(e.random_walks, (std::vector<double>{1e-4, 1e-4}));  // estimator.random_walk for each
  // A submodel's own random walk overrides the section's, and survives the round trip.
  const Config own = parse_config(edit(kBase, "      forgetting: 0.99", "      forgetting: 0.99\n      random_walk: 3.0e-4") +
                                      kEstimator,
                                  "test.yaml");
  EXPECT_EQ(own.estimator.random_walks, (std::vector<double>{3e-4, 1e-4}));
  EXPECT_EQ(parse_config(modalwatch::config_to_yaml(own, own.model), "again.yaml").estimator.random_walks,
            own.estimator.random_walks);
  EXPECT_EQ(parse_error(edit(kBase, "      forgetting: 0.99", "      forgetting: 0.99\n      random_walk: -1")),
            "test.yaml:11: key 'model.submodels[0].random_walk': must be >= 0 (got -1)");
  // Boundary values that are allowed.
  const std::string edge = edit(edit(edit(edit(edit(kEstimator, "refinements: 2", "refinements: 0"), "warmup: 12.5",
                                                  "warmup: 0"),
                                             "random_walk: 1.0e-4", "random_walk: 0"),
                                        "low_excitation_ratio: 0.2", "low_excitation_ratio: 0"),
                                   "residual_window: 30", "residual_window: 0");
  const Config z = parse_config(kBase + edge, "test.yaml");
  EXPECT_EQ(z.estimator.refinements, 0);
  EXPECT_EQ(z.estimator.warmup_samples, 0);
  EXPECT_EQ(z.estimator.random_walk, 0.0);
  EXPECT_EQ(z.estimator.low_excitation_ratio, 0.0);
  EXPECT_EQ(z.estimator.residual_window, 0.0);
  EXPECT_TRUE(parse_config(kBase + "estimator:\n  fit_on_warmup: true\n", "test.yaml").estimator.fit_on_warmup);
}

TEST(Config, EstimatorWarmupIsRoundedToSamples) {
  const auto samples = [](const std::string& warmup) {
    return parse_config(kBase + "estimator:\n  warmup: " + warmup + "\n", "test.yaml").estimator.warmup_samples;
  };
  EXPECT_EQ(samples("50"), 1000);
  EXPECT_EQ(samples("0.03"), 1);   // 0.6 samples
  EXPECT_EQ(samples("1.024"), 20);  // 20.48 samples
  EXPECT_EQ(samples("1.026"), 21);  // 20.52 samples
  const Config beam = parse_config(edit(kBase, "sample_rate_hz: 20", "sample_rate_hz: 4096") +
                                       "estimator:\n  warmup: 5\n",
                                   "test.yaml");
  EXPECT_EQ(beam.estimator.warmup_samples, 20480);
}

TEST(Config, InitialCovariancePerSubmodel) {
  const Config c = parse_config(
      edit(kBase, "      forgetting: 0.99", "      forgetting: 0.99\n      initial_covariance: [1.0e-4, 2.0e-3, 0.5]"),
      "test.yaml");
  const auto& cov = c.estimator.initial_covariance;
  ASSERT_EQ(cov.size(), 2u);
  ASSERT_EQ(cov[0].size(), 3);
  EXPECT_DOUBLE_EQ(cov[0](0), 1e-4);
  EXPECT_DOUBLE_EQ(cov[0](1), 2e-3);
  EXPECT_DOUBLE_EQ(cov[0](2), 0.5);
  EXPECT_EQ(cov[1].size(), 0);
  // n_theta = n + m + 1 for the other kinds: a rigid body has b_0 only.
  const std::string yaml =
      "sample_rate_hz: 100\n"
      "model:\n"
      "  submodels:\n"
      "    - {name: tf, kind: transfer_function, a: [0.1, 0.01], b: [1, 0.5], initial_covariance: [1, 2, 3, 4]}\n"
      "    - {name: rb, kind: rigid_body, gain: 0.5, initial_covariance: [0.01]}\n";
  const Config t = parse_config(yaml, "test.yaml");
  ASSERT_EQ(t.estimator.initial_covariance.size(), 2u);
  EXPECT_EQ(t.estimator.initial_covariance[0], Eigen::Vector4d(1, 2, 3, 4));
  EXPECT_EQ(t.estimator.initial_covariance[1], Eigen::VectorXd::Constant(1, 0.01));
}

TEST(Config, TransferFunctionAndRigidBody) {
  const std::string yaml =
      "sample_rate_hz: 100\n"
      "model:\n"
      "  output_hold: foh\n"
      "  submodels:\n"
      "    - {name: tf, kind: transfer_function, a: [0.1, 0.01, 0.001], b: [1, 0.5]}\n"
      "    - {name: rb, kind: rigid_body, gain: 0.5, rigid_poles: 1}\n"
      "    - {name: lead, kind: transfer_function, a: [0.2], b: [1, 2, 3], rigid_poles: 2}\n";
  const Config c = parse_config(yaml, "test.yaml");
  EXPECT_EQ(c.output_hold, modalwatch::Hold::foh);
  const auto& tf = c.model.submodels[0];
  EXPECT_EQ(tf.n, 3);
  EXPECT_EQ(tf.m, 1);
  EXPECT_EQ(tf.rigid_poles, 0);
  EXPECT_DOUBLE_EQ(tf.a(2), 0.001);
  EXPECT_DOUBLE_EQ(tf.b(1), 0.5);
  const auto& rb = c.model.submodels[1];
  EXPECT_EQ(rb.n, 0);
  EXPECT_EQ(rb.m, 0);
  EXPECT_EQ(rb.rigid_poles, 1);
  EXPECT_DOUBLE_EQ(rb.b(0), 0.5);
  const auto& lead = c.model.submodels[2];
  EXPECT_EQ(lead.m, 2);  // m <= n + l = 1 + 2
  EXPECT_EQ(lead.rigid_poles, 2);
}

TEST(Config, ShippedPaperSim) {
  const Config c = modalwatch::load_config(MODALWATCH_SOURCE_DIR "/config/paper-sim.yaml");
  EXPECT_DOUBLE_EQ(c.sample_time, 0.05);
  EXPECT_TRUE(c.closed_loop);
  ASSERT_EQ(c.model.submodels.size(), 3u);
  ASSERT_TRUE(c.plant.has_value());
  ASSERT_EQ(c.plant->modes.size(), 3u);
  const double wn[] = {2, 5, 20}, zeta[] = {0.25, 0.025, 0.1}, gain[] = {3, 0.5, 1};
  // The paper's a_{i,2}, a_{i,1}: the true plant at t = 0.
  const double a2[] = {0.25, 0.04, 0.0025}, a1[] = {0.25, 0.01, 0.01};
  for (int i = 0; i < 3; ++i) {
    const auto& truth = c.plant->modes[static_cast<std::size_t>(i)].submodel;
    EXPECT_EQ(truth.name, "mode" + std::to_string(i + 1));
    const auto p = modalwatch::modal_parameters(truth);
    EXPECT_NEAR(p.wn, wn[i], 1e-12);
    EXPECT_NEAR(p.zeta, zeta[i], 1e-12);
    EXPECT_NEAR(p.gain, gain[i], 1e-12);
    EXPECT_NEAR(truth.a(1), a2[i], 1e-15);
    EXPECT_NEAR(truth.a(0), a1[i], 1e-15);
    // The model starts where the paper starts it: theta*(0) (1 + U(-0.02, 0.02)).
    const auto& s = c.model.submodels[static_cast<std::size_t>(i)];
    EXPECT_EQ(s.name, truth.name);
    EXPECT_NEAR(s.a(1) / a2[i], 1.0, 0.02);
    EXPECT_NEAR(s.a(0) / a1[i], 1.0, 0.02);
    EXPECT_NEAR(s.b(0) / gain[i], 1.0, 0.02);
    EXPECT_NE(s.a(1), a2[i]);
  }
  // The paper's lambda = 0.999 for all three, and a random walk per mode.
  const std::vector<double> forgetting{0.999, 0.999, 0.999}, random_walks{5e-4, 0.0, 3e-4};
  for (std::size_t i = 0; i < 3; ++i) EXPECT_EQ(c.submodel_settings[i].forgetting, forgetting[i]) << i;
  EXPECT_EQ(c.estimator.forgetting, forgetting);
  EXPECT_EQ(c.estimator.random_walks, random_walks);
  EXPECT_EQ(c.estimator.random_walk, 0.0);
  // estimator: 50 s of warm-up at 20 Hz with the given theta(t0), P(t0) (no fit).
  modalwatch::EstimatorSettings expected = c.estimator;
  expected.fit_on_warmup = modalwatch::EstimatorSettings{}.fit_on_warmup;
  expect_estimator_defaults(expected, 1000);
  EXPECT_FALSE(c.estimator.fit_on_warmup);
  EXPECT_TRUE(c.estimator.closed_loop);
  EXPECT_DOUBLE_EQ(c.estimator.sample_time, 0.05);
  // P(t0): a std of 1 % of each a_i (scaled by the noise variance 0.01), the
  // paper's 1e-5 for each gain.
  ASSERT_EQ(c.estimator.initial_covariance.size(), 3u);
  for (int i = 0; i < 3; ++i) {
    const auto& p0 = c.estimator.initial_covariance[static_cast<std::size_t>(i)];
    ASSERT_EQ(p0.size(), 3);
    EXPECT_NEAR(p0(0), std::pow(0.01 * a1[i], 2) / 0.01, 1e-15) << i;
    EXPECT_NEAR(p0(1), std::pow(0.01 * a2[i], 2) / 0.01, 1e-15) << i;
    EXPECT_EQ(p0(2), 1e-5) << i;
  }
  ASSERT_FALSE(c.controller.empty());
  EXPECT_NEAR(c.controller.numerator()[1], -0.02058, 1e-15);
  ASSERT_TRUE(c.plant.has_value());
  ASSERT_EQ(c.plant->modes.size(), 3u);
  EXPECT_DOUBLE_EQ(c.plant->noise_variance, 0.01);
  const auto& p = c.plant->modes;
  EXPECT_EQ(p[0].wn.points, (std::vector<std::pair<double, double>>{{100, 2.0}, {300, 1.6}}));
  EXPECT_EQ(p[1].zeta.points, (std::vector<std::pair<double, double>>{{100, 0.025}, {300, 0.0125}}));
  EXPECT_EQ(p[2].wn.points, (std::vector<std::pair<double, double>>{{500, 20.0}, {800, 16.0}}));
  EXPECT_EQ(p[2].zeta.points, (std::vector<std::pair<double, double>>{{500, 0.1}, {800, 0.07}}));
  ASSERT_TRUE(c.experiment.has_value());
  EXPECT_DOUBLE_EQ(c.experiment->duration, 1000.0);
  EXPECT_EQ(c.experiment->seed, 1u);
  EXPECT_EQ(c.experiment->excitation.amplitudes, (std::vector<double>{3, 1, 1, 1}));
  EXPECT_EQ(c.experiment->excitation.frequencies_rad_s, (std::vector<double>{0.005, 2, 5, 17.5}));
}

TEST(Config, ShippedEstimatorSections) {
  const Config beam = modalwatch::load_config(MODALWATCH_SOURCE_DIR "/config/flexible-beam.yaml");
  expect_estimator_defaults(beam.estimator, 20480);  // 5 s at 4096 Hz
  EXPECT_EQ(beam.estimator.forgetting, (std::vector<double>{0.9999, 0.999}));
  EXPECT_TRUE(beam.estimator.closed_loop);
  const Config stage = modalwatch::load_config(MODALWATCH_SOURCE_DIR "/config/motion-stage.yaml");
  expect_estimator_defaults(stage.estimator, 10000);  // 1 s at 10 kHz
  EXPECT_EQ(stage.estimator.forgetting, (std::vector<double>{0.9999, 0.999, 0.999}));
  EXPECT_TRUE(stage.estimator.closed_loop);
}

TEST(Config, EveryShippedConfigLoads) {
  int count = 0;
  for (const auto& entry : fs::directory_iterator(MODALWATCH_SOURCE_DIR "/config")) {
    if (entry.path().extension() != ".yaml") continue;
    ++count;
    try {
      modalwatch::load_config(entry.path().string());
    } catch (const InputError& e) {
      ADD_FAILURE() << e.what();
    }
  }
  EXPECT_GE(count, 1);
}

// ---------------------------------------------------------------- messages
// A missing key is reported at the line of its parent map: the line of the
// parent's key (`simulation:`), or of the first key for the top level and for
// list items.

TEST(ConfigErrors, MessageFormatIsFileLineKeyWhatGot) {
  EXPECT_EQ(parse_error(edit(kBase, "zeta: 0.1", "zeta: -0.1")),
            "test.yaml:13: key 'model.submodels[1].zeta': must be > 0 (got -0.1)");
}

TEST(ConfigErrors, SampleRate) {
  EXPECT_EQ(parse_error(edit(kBase, "sample_rate_hz: 20", "sample_rate_hz: 0")),
            "test.yaml:1: key 'sample_rate_hz': must be > 0 (got 0)");
  EXPECT_EQ(parse_error(edit(kBase, "sample_rate_hz: 20", "sample_rate_hz: fast")),
            "test.yaml:1: key 'sample_rate_hz': expected a number (got fast)");
  EXPECT_EQ(parse_error(edit(kBase, "sample_rate_hz: 20", "sample_rate_hz: \"20\"")),
            "test.yaml:1: key 'sample_rate_hz': expected a number (got \"20\")");
  EXPECT_EQ(parse_error(edit(kBase, "sample_rate_hz: 20", "sample_rate_hz: [20]")),
            "test.yaml:1: key 'sample_rate_hz': expected a number (got [20])");
  EXPECT_EQ(parse_error(edit(kBase, "sample_rate_hz: 20", "sample_rate_hz: .inf")),
            "test.yaml:1: key 'sample_rate_hz': expected a number (got .inf)");
  // Missing: reported at the line of the enclosing (top-level) map.
  EXPECT_EQ(parse_error(edit(kBase, "sample_rate_hz: 20\n", "# no rate\n")),
            "test.yaml:2: key 'sample_rate_hz': missing required key");
}

TEST(ConfigErrors, UnknownKeys) {
  const auto top = parse_error(edit(kBase, "sample_rate_hz: 20", "sample_rate_hz: 20\nsample_rate: 20"));
  EXPECT_CONTAINS(top, "test.yaml:2: key 'sample_rate': unknown key");
  const auto sub = parse_error(edit(kBase, "      zeta: 0.25", "      zeta: 0.25\n      damping: 0.1"));
  EXPECT_CONTAINS(sub, "test.yaml:9: key 'model.submodels[0].damping': unknown key for kind mode");
  EXPECT_CONTAINS(sub, "allowed: name, kind, wn");
  const auto model = parse_error(edit(kBase, "  loop: open", "  loop: open\n  order: 2"));
  EXPECT_CONTAINS(model, "test.yaml:4: key 'model.order': unknown key");
  const auto est = parse_error(kBase + "estimator:\n  type: rsrivc\n");
  EXPECT_CONTAINS(est, "test.yaml:16: key 'estimator.type': unknown key for estimator (allowed: block_iterations, ");
}

TEST(ConfigErrors, DuplicateKey) {
  EXPECT_EQ(parse_error(edit(kBase, "      zeta: 0.25", "      zeta: 0.25\n      zeta: 0.3")),
            "test.yaml:9: key 'model.submodels[0].zeta': duplicate key (first at line 8)");
}

TEST(ConfigErrors, WrongTypes) {
  EXPECT_EQ(parse_error("sample_rate_hz: 20\nmodel:\n  submodels: 3\n"),
            "test.yaml:3: key 'model.submodels': expected a list (got 3)");
  EXPECT_EQ(parse_error("sample_rate_hz: 20\nmodel: open\n"),
            "test.yaml:2: key 'model': expected a map of keys (got open)");
  EXPECT_EQ(parse_error("sample_rate_hz: 20\nmodel:\n  submodels:\n    - name: m\n      wn: {value: 2}\n"),
            "test.yaml:5: key 'model.submodels[0].wn': expected a number (got {value: 2})");
  EXPECT_EQ(parse_error(edit(kBase, "  loop: open", "  loop: maybe")),
            "test.yaml:3: key 'model.loop': must be one of open, closed (got maybe)");
  EXPECT_EQ(parse_error(edit(kBase, "      kind: mode", "      kind: spring")),
            "test.yaml:6: key 'model.submodels[0].kind': must be one of mode, rigid_body, "
            "transfer_function (got spring)");
  EXPECT_EQ(parse_error(edit(kBase, "      wn: 2.0", "      wn:")),
            "test.yaml:7: key 'model.submodels[0].wn': expected a number (got null)");
  EXPECT_EQ(parse_error(edit(kBase, "      wn: 2.0", "      wn: 2 rad/s")),
            "test.yaml:7: key 'model.submodels[0].wn': expected a number (got 2 rad/s)");
  EXPECT_EQ(parse_error(edit(kBase, "  loop: open", "  output_hold: linear")),
            "test.yaml:3: key 'model.output_hold': must be one of zoh, foh (got linear)");
}

TEST(ConfigErrors, ModeValues) {
  EXPECT_EQ(parse_error(edit(kBase, "      wn: 2.0", "      wn: -2.0")),
            "test.yaml:7: key 'model.submodels[0].wn': must be > 0 (got -2.0)");
  EXPECT_EQ(parse_error(edit(kBase, "      frequency_hz: 1.0", "      frequency_hz: 0")),
            "test.yaml:12: key 'model.submodels[1].frequency_hz': must be > 0 (got 0)");
  EXPECT_EQ(parse_error(edit(kBase, "      wn: 2.0", "      wn: 2.0\n      frequency_hz: 0.3")),
            "test.yaml:8: key 'model.submodels[0].frequency_hz': give wn or frequency_hz, not both");
  EXPECT_EQ(parse_error(edit(kBase, "      wn: 2.0\n", "")),
            "test.yaml:5: key 'model.submodels[0].wn': missing required key (kind mode needs wn or "
            "frequency_hz)");
  EXPECT_EQ(parse_error(edit(kBase, "      zeta: 0.25", "      zeta: 0")),
            "test.yaml:8: key 'model.submodels[0].zeta': must be > 0 (got 0)");
  EXPECT_EQ(parse_error(edit(kBase, "      gain: 3.0", "      gain: 0.0")),
            "test.yaml:9: key 'model.submodels[0].gain': must be != 0 (got 0.0)");
  EXPECT_EQ(parse_error(edit(kBase, "      gain: 1.0\n", "")),
            "test.yaml:11: key 'model.submodels[1].gain': missing required key (kind mode)");
  EXPECT_EQ(parse_error(edit(kBase, "      gain: 3.0", "      gain: 3.0\n      rigid_poles: 1")),
            "test.yaml:10: key 'model.submodels[0].rigid_poles': a mode has no poles at the origin; use "
            "kind transfer_function (got 1)");
}

TEST(ConfigErrors, Forgetting) {
  EXPECT_EQ(parse_error(edit(kBase, "forgetting: 0.99", "forgetting: 0")),
            "test.yaml:10: key 'model.submodels[0].forgetting': must be in (0, 1] (got 0)");
  EXPECT_EQ(parse_error(edit(kBase, "forgetting: 0.99", "forgetting: 1.001")),
            "test.yaml:10: key 'model.submodels[0].forgetting': must be in (0, 1] (got 1.001)");
  EXPECT_NO_THROW(parse_config(edit(kBase, "forgetting: 0.99", "forgetting: 1"), "test.yaml"));
}

TEST(ConfigErrors, EstimatorValues) {
  EXPECT_NO_THROW(parse_config(kBase + kEstimator, "test.yaml"));
  struct Case {
    std::string from, to, message;
  };
  const std::vector<Case> cases = {
      {"block_iterations: 3", "block_iterations: 0",
       "test.yaml:16: key 'estimator.block_iterations': must be >= 1 (got 0)"},
      {"block_iterations: 3", "block_iterations: 1.5",
       "test.yaml:16: key 'estimator.block_iterations': expected an integer (got 1.5)"},
      {"block_iterations: 3", "block_iterations: 3000000000",
       "test.yaml:16: key 'estimator.block_iterations': must be >= 1 (got 3000000000)"},
      {"refinements: 2", "refinements: -1", "test.yaml:17: key 'estimator.refinements': must be >= 0 (got -1)"},
      {"refinements: 2", "refinements: two",
       "test.yaml:17: key 'estimator.refinements': expected an integer (got two)"},
      {"update_divisor: 4", "update_divisor: 0",
       "test.yaml:18: key 'estimator.update_divisor': must be >= 1 (got 0)"},
      {"warmup: 12.5", "warmup: -1", "test.yaml:19: key 'estimator.warmup': must be >= 0 (got -1)"},
      {"warmup: 12.5", "warmup: 0.02",
       "test.yaml:19: key 'estimator.warmup': shorter than one sample period (use 0 for no warm-up) (got 0.02)"},
      {"warmup: 12.5", "warmup: 10 s", "test.yaml:19: key 'estimator.warmup': expected a number (got 10 s)"},
      {"warmup: 12.5", "warmup: 1.0e9",
       "test.yaml:19: key 'estimator.warmup': too long: more than 2147483647 samples (got 1.0e9)"},
      {"fit_on_warmup: false", "fit_on_warmup: yes",
       "test.yaml:20: key 'estimator.fit_on_warmup': expected true or false (got yes)"},
      {"fit_on_warmup: false", "fit_on_warmup: \"true\"",
       "test.yaml:20: key 'estimator.fit_on_warmup': expected true or false (got \"true\")"},
      {"fit_on_warmup: false", "fit_on_warmup: 1",
       "test.yaml:20: key 'estimator.fit_on_warmup': expected true or false (got 1)"},
      {"warmup_iterations: 20", "warmup_iterations: 0",
       "test.yaml:21: key 'estimator.warmup_iterations': must be >= 1 (got 0)"},
      {"initial_covariance_relative: 0.5", "initial_covariance_relative: 0",
       "test.yaml:22: key 'estimator.initial_covariance_relative': must be > 0 (got 0)"},
      {"random_walk: 1.0e-4", "random_walk: -1.0e-4",
       "test.yaml:23: key 'estimator.random_walk': must be >= 0 (got -1.0e-4)"},
      {"covariance_bound: 50", "covariance_bound: 1",
       "test.yaml:24: key 'estimator.covariance_bound': must be > 1 (got 1)"},
      {"divergence_ratio: 4", "divergence_ratio: 0.5",
       "test.yaml:25: key 'estimator.divergence_ratio': must be > 1 (got 0.5)"},
      {"gap_factor: 2.5", "gap_factor: 1", "test.yaml:26: key 'estimator.gap_factor': must be > 1 (got 1)"},
      {"outlier_sigma: 6", "outlier_sigma: 0", "test.yaml:27: key 'estimator.outlier_sigma': must be > 0 (got 0)"},
      {"outlier_sigma: 6", "outlier_sigma: .inf",
       "test.yaml:27: key 'estimator.outlier_sigma': expected a number (got .inf)"},
      {"residual_window: 30", "residual_window: -30",
       "test.yaml:28: key 'estimator.residual_window': must be >= 0 (got -30)"},
      {"low_excitation_ratio: 0.2", "low_excitation_ratio: 1",
       "test.yaml:29: key 'estimator.low_excitation_ratio': must be in [0, 1) (got 1)"},
      {"low_excitation_ratio: 0.2", "low_excitation_ratio: -0.1",
       "test.yaml:29: key 'estimator.low_excitation_ratio': must be in [0, 1) (got -0.1)"},
      {"low_excitation_window: 8", "low_excitation_window: -8",
       "test.yaml:30: key 'estimator.low_excitation_window': must be >= 0 (got -8)"},
  };
  for (const auto& c : cases) EXPECT_EQ(parse_error(kBase + edit(kEstimator, c.from, c.to)), c.message) << c.to;
}

TEST(ConfigErrors, EstimatorKeysAndShape) {
  const auto unknown = parse_error(kBase + kEstimator + "  forgetting: 0.99\n");
  EXPECT_EQ(unknown,
            "test.yaml:31: key 'estimator.forgetting': unknown key for estimator (allowed: block_iterations, "
            "refinements, update_divisor, warmup, fit_on_warmup, warmup_iterations, initial_covariance_relative, "
            "random_walk, covariance_bound, stabilisation, divergence_ratio, gap_factor, outlier_sigma, residual_window, "
            "low_excitation_ratio, low_excitation_window)");
  EXPECT_EQ(parse_error(kBase + kEstimator + "  warmup: 3\n"),
            "test.yaml:31: key 'estimator.warmup': duplicate key (first at line 19)");
  EXPECT_EQ(parse_error(kBase + "estimator: rsrivc\n"),
            "test.yaml:15: key 'estimator': expected a map of keys (got rsrivc)");
  EXPECT_EQ(parse_error(kBase + "estimator:\n"), "test.yaml:15: key 'estimator': expected a map of keys (got null)");
}

TEST(ConfigErrors, NamesRequiredUniqueAndSafe) {
  EXPECT_EQ(parse_error(edit(kBase, "name: m2", "name: m1")),
            "test.yaml:11: key 'model.submodels[1].name': duplicate name (first used at line 5) (got m1)");
  EXPECT_EQ(parse_error(edit(kBase, "    - name: m2\n", "    - kind: mode\n")),
            "test.yaml:11: key 'model.submodels[1].name': missing required key");
  EXPECT_EQ(parse_error(edit(kBase, "name: m2", "name: \"a,b\"")),
            "test.yaml:11: key 'model.submodels[1].name': names may contain only letters, digits, '_' and "
            "'-' (got \"a,b\")");
  EXPECT_EQ(parse_error(edit(kBase, "  submodels:\n", "  submodels: []\n  old:\n")),
            "test.yaml:5: key 'model.old': unknown key for model (allowed: loop, output_hold, submodels)");
}

TEST(ConfigErrors, EmptySubmodelList) {
  const std::string yaml = "sample_rate_hz: 20\nmodel:\n  submodels: []\n";
  EXPECT_EQ(parse_error(yaml), "test.yaml:3: key 'model.submodels': must list at least one submodel (got [])");
}

const std::string kTf =
    "sample_rate_hz: 20\n"                                                  // 1
    "model:\n"                                                              // 2
    "  submodels:\n"                                                        // 3
    "    - name: tf\n"                                                      // 4
    "      kind: transfer_function\n"                                       // 5
    "      a: [0.1, 0.01]\n"                                                // 6
    "      b: [1, 0.5]\n";                                                  // 7

TEST(ConfigErrors, TransferFunctionOrders) {
  EXPECT_NO_THROW(parse_config(kTf, "test.yaml"));
  const auto msg = parse_error(edit(kTf, "b: [1, 0.5]", "b: [1, 0.5, 0.2, 0.1]"));
  EXPECT_CONTAINS(msg, "test.yaml:7: key 'model.submodels[0].b': ");
  EXPECT_CONTAINS(msg, "m = 3");
  EXPECT_CONTAINS(msg, "n + l = 2 + 0");
  EXPECT_CONTAINS(msg, "(got [1, 0.5, 0.2, 0.1])");
  // Rigid poles allow a higher B.
  EXPECT_NO_THROW(parse_config(edit(kTf, "b: [1, 0.5]", "b: [1, 0.5, 0.2, 0.1]\n      rigid_poles: 1"),
                               "test.yaml"));
  EXPECT_EQ(parse_error(edit(kTf, "b: [1, 0.5]", "b: []")),
            "test.yaml:7: key 'model.submodels[0].b': must not be empty (got [])");
  EXPECT_EQ(parse_error(edit(kTf, "a: [0.1, 0.01]", "a: [0.1, 0]")),
            "test.yaml:6: key 'model.submodels[0].a': the last coefficient a_n must be != 0 (got [0.1, 0])");
  EXPECT_EQ(parse_error(edit(kTf, "a: [0.1, 0.01]", "a: [0.1, x]")),
            "test.yaml:6: key 'model.submodels[0].a[1]': expected a number (got x)");
  EXPECT_EQ(parse_error(edit(kTf, "a: [0.1, 0.01]", "a: 0.1")),
            "test.yaml:6: key 'model.submodels[0].a': expected a list (got 0.1)");
  EXPECT_EQ(parse_error(edit(kTf, "      a: [0.1, 0.01]\n", "")),
            "test.yaml:4: key 'model.submodels[0].a': missing required key (kind transfer_function)");
  EXPECT_EQ(parse_error(edit(kTf, "a: [0.1, 0.01]", "wn: 3")),
            "test.yaml:6: key 'model.submodels[0].wn': unknown key for kind transfer_function (allowed: name, "
            "kind, a, b, rigid_poles, forgetting, random_walk, stabilisation, initial_covariance)");
}

TEST(ConfigErrors, InitialCovariance) {
  const auto with = [](const std::string& value) {
    return edit(kBase, "      forgetting: 0.99", "      forgetting: 0.99\n      initial_covariance: " + value);
  };
  EXPECT_NO_THROW(parse_config(with("[1, 2, 3]"), "test.yaml"));
  EXPECT_EQ(parse_error(with("[1, 2]")),
            "test.yaml:11: key 'model.submodels[0].initial_covariance': must have n + m + 1 = 2 + 0 + 1 = 3 "
            "entries, one per parameter of theta = [a_1 .. a_n, b_0 .. b_m] (got [1, 2])");
  EXPECT_EQ(parse_error(with("[1, 0, 3]")),
            "test.yaml:11: key 'model.submodels[0].initial_covariance[1]': must be > 0 (got 0)");
  EXPECT_EQ(parse_error(with("[1, -2, 3]")),
            "test.yaml:11: key 'model.submodels[0].initial_covariance[1]': must be > 0 (got -2)");
  EXPECT_EQ(parse_error(with("[1, x, 3]")),
            "test.yaml:11: key 'model.submodels[0].initial_covariance[1]': expected a number (got x)");
  EXPECT_EQ(parse_error(with("0.1")),
            "test.yaml:11: key 'model.submodels[0].initial_covariance': expected a list (got 0.1)");
  EXPECT_EQ(parse_error(with("[]")),
            "test.yaml:11: key 'model.submodels[0].initial_covariance': must have n + m + 1 = 2 + 0 + 1 = 3 "
            "entries, one per parameter of theta = [a_1 .. a_n, b_0 .. b_m] (got [])");
  // A transfer function with n = 2, m = 1.
  const auto tf = parse_error(edit(kTf, "b: [1, 0.5]", "b: [1, 0.5]\n      initial_covariance: [1, 1, 1]"));
  EXPECT_CONTAINS(tf, "test.yaml:8: key 'model.submodels[0].initial_covariance': must have n + m + 1 = 2 + 1 + 1 = 4 "
                      "entries");
  // Not a key of the true plant.
  EXPECT_CONTAINS(parse_error(edit(kClosed, "      gain: 0.01", "      gain: 0.01\n      initial_covariance: [1]")),
                  "test.yaml:21: key 'plant.modes[1].initial_covariance': unknown key for kind rigid_body");
}

TEST(ConfigErrors, RigidPoles) {
  EXPECT_EQ(parse_error(edit(kTf, "b: [1, 0.5]", "b: [1, 0.5]\n      rigid_poles: 3")),
            "test.yaml:8: key 'model.submodels[0].rigid_poles': must be in 0..2 (got 3)");
  EXPECT_EQ(parse_error(edit(kTf, "b: [1, 0.5]", "b: [1, 0.5]\n      rigid_poles: 1.5")),
            "test.yaml:8: key 'model.submodels[0].rigid_poles': expected an integer (got 1.5)");
  const std::string rb = "sample_rate_hz: 20\nmodel:\n  submodels:\n    - {name: b, kind: rigid_body, gain: 2, "
                         "rigid_poles: -1}\n";
  EXPECT_EQ(parse_error(rb), "test.yaml:4: key 'model.submodels[0].rigid_poles': must be in 0..2 (got -1)");
  EXPECT_EQ(parse_error(edit(edit(rb, "gain: 2", "gain: 0"), "rigid_poles: -1", "rigid_poles: 1")),
            "test.yaml:4: key 'model.submodels[0].gain': must be != 0 (got 0)");
}

TEST(ConfigErrors, ClosedLoopNeedsController) {
  const std::string yaml = edit(kBase, "loop: open", "loop: closed");
  EXPECT_EQ(parse_error(yaml), "test.yaml:1: key 'controller': missing required key (model.loop is closed)");
}

TEST(ConfigErrors, Controller) {
  EXPECT_NO_THROW(parse_config(kClosed, "test.yaml"));
  const auto improper = parse_error(edit(kClosed, "numerator: [0.02329, -0.02058, 0.00454]", "numerator: [1, 2, 3, 4]"));
  EXPECT_CONTAINS(improper, "test.yaml:7: key 'controller.numerator': improper controller");
  EXPECT_CONTAINS(improper, "(got [1, 2, 3, 4])");
  EXPECT_EQ(parse_error(edit(kClosed, "denominator: [1, -1, 0]", "denominator: [0, 1, -1]")),
            "test.yaml:8: key 'controller.denominator': the leading coefficient must be != 0 (got [0, 1, -1])");
  EXPECT_EQ(parse_error(edit(kClosed, "  denominator: [1, -1, 0]\n", "")),
            "test.yaml:6: key 'controller.denominator': missing required key");
  EXPECT_EQ(parse_error(edit(kClosed, "denominator: [1, -1, 0]", "denominator: [1, -1, 0]\n  gain: 2")),
            "test.yaml:9: key 'controller.gain': unknown key for controller (allowed: numerator, denominator)");
}

TEST(ConfigErrors, PlantNoise) {
  EXPECT_EQ(parse_error(edit(kClosed, "noise_variance: 0.01", "noise_variance: -0.01")),
            "test.yaml:10: key 'plant.noise_variance': must be >= 0 (got -0.01)");
  EXPECT_EQ(parse_error(edit(kClosed, "noise_variance: 0.01", "noise_variance: 0.01\n  snr_db: 20")),
            "test.yaml:11: key 'plant.snr_db': give noise_variance or snr_db, not both");
  const Config c = parse_config(edit(kClosed, "noise_variance: 0.01", "snr_db: 30"), "test.yaml");
  ASSERT_TRUE(c.plant->snr_db.has_value());
  EXPECT_DOUBLE_EQ(*c.plant->snr_db, 30.0);
  EXPECT_EQ(parse_error(edit(kClosed, "    - name: body", "    - name: m1")),
            "test.yaml:18: key 'plant.modes[1].name': duplicate name (first used at line 12) (got m1)");
  EXPECT_EQ(parse_error(edit(kClosed, "      gain: 0.01", "      gain: 0.01\n      forgetting: 0.9")),
            "test.yaml:21: key 'plant.modes[1].forgetting': unknown key for kind rigid_body (allowed: name, "
            "kind, gain, rigid_poles)");
}

TEST(ConfigErrors, Trajectories) {
  EXPECT_EQ(parse_error(edit(kClosed, "[[100, 2.0], [300, 1.6]]", "[[100, 2.0], [100, 1.6]]")),
            "test.yaml:17: key 'plant.modes[0].trajectory.wn[1]': t must increase strictly from point to point "
            "(got [100, 1.6])");
  EXPECT_EQ(parse_error(edit(kClosed, "[[100, 2.0], [300, 1.6]]", "[[100, 2.0], [300, -1.6]]")),
            "test.yaml:17: key 'plant.modes[0].trajectory.wn[1][1]': must be > 0 (got -1.6)");
  EXPECT_EQ(parse_error(edit(kClosed, "[[100, 2.0], [300, 1.6]]", "[[100, 2.0, 3]]")),
            "test.yaml:17: key 'plant.modes[0].trajectory.wn[0]': expected a point [t, value] (got [100, 2.0, 3])");
  EXPECT_EQ(parse_error(edit(kClosed, "        wn: [[100, 2.0], [300, 1.6]]", "        zeta: [[1, 0.2], [2, 0]]")),
            "test.yaml:17: key 'plant.modes[0].trajectory.zeta[1][1]': must be > 0 (got 0)");
  EXPECT_EQ(parse_error(edit(kClosed, "        wn: [[100, 2.0], [300, 1.6]]", "        omega: [[1, 2]]")),
            "test.yaml:17: key 'plant.modes[0].trajectory.omega': unknown key for a trajectory (allowed: wn, "
            "frequency_hz, zeta, gain)");
  EXPECT_EQ(parse_error(edit(kClosed, "        wn: [[100, 2.0], [300, 1.6]]",
                             "        wn: [[1, 2]]\n        frequency_hz: [[1, 0.3]]")),
            "test.yaml:18: key 'plant.modes[0].trajectory.frequency_hz': give wn or frequency_hz, not both");
  EXPECT_EQ(parse_error(edit(kClosed, "      gain: 0.01", "      gain: 0.01\n      trajectory: {gain: [[1, 2]]}")),
            "test.yaml:21: key 'plant.modes[1].trajectory': a trajectory is only allowed for kind mode (this "
            "submodel is kind rigid_body)");
  EXPECT_EQ(parse_error(edit(kClosed, "        wn: [[100, 2.0], [300, 1.6]]", "        wn: 2.0")),
            "test.yaml:17: key 'plant.modes[0].trajectory.wn': expected a list (got 2.0)");
}

TEST(Config, TrajectoryInHertzBecomesRadPerSecond) {
  const Config c = parse_config(
      edit(kClosed, "        wn: [[100, 2.0], [300, 1.6]]", "        frequency_hz: [[100, 0.5], [300, 0.25]]"),
      "test.yaml");
  const auto& pts = c.plant->modes[0].wn.points;
  ASSERT_EQ(pts.size(), 2u);
  EXPECT_DOUBLE_EQ(pts[0].second, 0.5 * kTwoPi);
  EXPECT_DOUBLE_EQ(pts[1].second, 0.25 * kTwoPi);
}

TEST(ConfigErrors, Simulation) {
  EXPECT_EQ(parse_error(edit(kClosed, "duration: 10", "duration: 0")),
            "test.yaml:22: key 'simulation.duration': must be > 0 (got 0)");
  EXPECT_EQ(parse_error(edit(kClosed, "duration: 10", "duration: 0.01")),
            "test.yaml:22: key 'simulation.duration': shorter than one sample period (got 0.01)");
  EXPECT_EQ(parse_error(edit(kClosed, "seed: 7", "seed: -1")),
            "test.yaml:23: key 'simulation.seed': must be >= 0 (got -1)");
  // More samples than the record's index holds (fuzz_config found 7e59 s, whose
  // conversion to a sample count was undefined behaviour).
  for (const char* duration : {"duration: 2.0e8", "duration: 7.0e59"})
    EXPECT_CONTAINS(parse_error(edit(kClosed, "duration: 10", duration)),
                    "test.yaml:22: key 'simulation.duration': too long: ");
  EXPECT_NO_THROW(parse_config(edit(kClosed, "duration: 10", "duration: 1.0e8"), "test.yaml"));  // 2e9 samples
  EXPECT_EQ(parse_error(edit(kClosed, "  reference:", "  input:")),
            "test.yaml:24: key 'simulation.input': not used when model.loop is closed (the excitation is "
            "simulation.reference)");
  const std::string no_ref = kClosed.substr(0, kClosed.find("  reference:"));
  EXPECT_EQ(parse_error(no_ref),
            "test.yaml:21: key 'simulation.reference': missing required key (model.loop is closed)");
  // Open loop needs an input.
  const std::string open = kBase + "simulation:\n  duration: 5\n";  // simulation on line 15
  EXPECT_EQ(parse_error(open), "test.yaml:15: key 'simulation.input': missing required key (model.loop is open)");
  EXPECT_NO_THROW(parse_config(open + "  input: {type: square, frequency_hz: 1, amplitude: 2}\n", "test.yaml"));
}

// A signal section with `body` as its keys (lines 25 on).
std::string with_signal(const std::string& body) {
  return kClosed.substr(0, kClosed.find("    type: sum_of_sines")) + body;
}

TEST(ConfigErrors, SignalKeysPerType) {
  EXPECT_EQ(parse_error(with_signal("    type: prbs\n    register_bits: 10\n    clock_period: 1\n    amplitude: 1\n"
                                    "    frequency_hz: 2\n")),
            "test.yaml:29: key 'simulation.reference.frequency_hz': unknown key for type prbs (allowed: type, "
            "register_bits, clock_period, amplitude)");
  EXPECT_EQ(parse_error(with_signal("    type: chirp\n")),
            "test.yaml:25: key 'simulation.reference.type': must be one of sum_of_sines, multisine, prbs, square, "
            "csv (got chirp)");
  EXPECT_EQ(parse_error(with_signal("    amplitudes: [1]\n")),
            "test.yaml:24: key 'simulation.reference.type': missing required key");
  EXPECT_EQ(parse_error(with_signal("    type: square\n    amplitude: 1\n")),
            "test.yaml:24: key 'simulation.reference.frequency_hz': missing required key");
}

TEST(ConfigErrors, Prbs) {
  const std::string prbs = "    type: prbs\n    register_bits: 10\n    clock_period: 3\n    amplitude: 0.5\n";
  const Config c = parse_config(with_signal(prbs), "test.yaml");
  EXPECT_EQ(c.experiment->excitation.kind, modalwatch::SignalSpec::Kind::prbs);
  EXPECT_EQ(c.experiment->excitation.register_bits, 10);
  EXPECT_EQ(c.experiment->excitation.clock_period, 3);
  EXPECT_DOUBLE_EQ(c.experiment->excitation.amplitude, 0.5);
  EXPECT_EQ(parse_error(with_signal(edit(prbs, "register_bits: 10", "register_bits: 1"))),
            "test.yaml:26: key 'simulation.reference.register_bits': must be in 2..31 (got 1)");
  EXPECT_EQ(parse_error(with_signal(edit(prbs, "register_bits: 10", "register_bits: 32"))),
            "test.yaml:26: key 'simulation.reference.register_bits': must be in 2..31 (got 32)");
  EXPECT_EQ(parse_error(with_signal(edit(prbs, "clock_period: 3", "clock_period: 0"))),
            "test.yaml:27: key 'simulation.reference.clock_period': must be >= 1 (got 0)");
}

TEST(ConfigErrors, SumOfSinesAndMultisine) {
  EXPECT_EQ(parse_error(with_signal("    type: sum_of_sines\n    amplitudes: [1, 2]\n    frequencies_rad_s: [1]\n")),
            "test.yaml:27: key 'simulation.reference.frequencies_rad_s': must have as many entries as amplitudes "
            "(2) (got [1])");
  const Config hz = parse_config(
      with_signal("    type: sum_of_sines\n    amplitudes: [1]\n    frequencies_hz: [2]\n    phases: [0.5]\n"),
      "test.yaml");
  EXPECT_DOUBLE_EQ(hz.experiment->excitation.frequencies_rad_s[0], 2 * kTwoPi);
  EXPECT_EQ(hz.experiment->excitation.phases, std::vector<double>{0.5});
  const std::string ms = "    type: multisine\n    f_min_hz: 0.1\n    f_max_hz: 5\n    period_s: 100\n    rms: 1\n";
  const Config m = parse_config(with_signal(ms), "test.yaml");
  EXPECT_EQ(m.experiment->excitation.kind, modalwatch::SignalSpec::Kind::multisine);
  EXPECT_DOUBLE_EQ(m.experiment->excitation.period_s, 100.0);
  EXPECT_EQ(m.experiment->excitation.seed, 7u);
  EXPECT_EQ(parse_error(with_signal(edit(ms, "f_max_hz: 5", "f_max_hz: 11"))),
            "test.yaml:27: key 'simulation.reference.f_max_hz': must not exceed the Nyquist frequency 10 Hz (got 11)");
  EXPECT_EQ(parse_error(with_signal(edit(ms, "f_max_hz: 5", "f_max_hz: 0.05"))),
            "test.yaml:27: key 'simulation.reference.f_max_hz': must be > f_min_hz (got 0.05)");
  EXPECT_EQ(parse_error(with_signal(edit(ms, "    rms: 1\n", ""))),
            "test.yaml:24: key 'simulation.reference.rms': missing required key");
  // 4.9e7 lines of 0.1 mHz in [0.1, 5] Hz: each would be a sine per sample.
  EXPECT_CONTAINS(parse_error(with_signal(edit(ms, "period_s: 100", "period_s: 1.0e7"))),
                  "test.yaml:28: key 'simulation.reference.period_s': 49000001 frequency lines");
}

TEST(ConfigErrors, YamlSyntax) {
  const auto msg = parse_error(edit(kBase, "      zeta: 0.25", "      zeta: [0.25"));
  EXPECT_EQ(msg.rfind("test.yaml:", 0), 0u) << msg;
  EXPECT_CONTAINS(msg, "YAML syntax error");
  EXPECT_EQ(parse_error("sample_rate_hz: 20\nmodel:\n  loop: open\n submodels: []\n").rfind("test.yaml:4: ", 0), 0u);
}

TEST(ConfigErrors, EmptyOrNotAMap) {
  EXPECT_CONTAINS(parse_error(""), "test.yaml:1: ");
  EXPECT_CONTAINS(parse_error("# nothing\n"), "empty configuration");
  EXPECT_EQ(parse_error("- 1\n- 2\n"), "test.yaml:1: expected a map of keys (got [1, 2])");
}

TEST(ConfigErrors, MissingFile) {
  const auto msg = error_of([] { modalwatch::load_config("/nonexistent/dir/x.yaml"); });
  EXPECT_CONTAINS(msg, "/nonexistent/dir/x.yaml");
  EXPECT_CONTAINS(msg, "cannot open");
}

// ---------------------------------------------------------------- files

class ConfigFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    std::random_device rd;
    dir_ = fs::temp_directory_path() /
           ("modalwatch-config-" + std::to_string(::getpid()) + "-" + std::to_string(rd()));
    fs::create_directories(dir_ / "signals");
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) const {
    const auto p = (dir_ / name).string();
    std::ofstream(p) << text;
    return p;
  }
  fs::path dir_;
};

// Open loop at 10 Hz for 1 s: 10 samples t = 0 .. 0.9.
const std::string kCsvSignal =
    "sample_rate_hz: 10\n"                           // 1
    "model:\n"                                       // 2
    "  submodels: [{name: m, wn: 1, zeta: 0.1, gain: 1}]\n"  // 3
    "simulation:\n"                                  // 4
    "  duration: 1\n"                                // 5
    "  input:\n"                                     // 6
    "    type: csv\n"                                // 7
    "    path: signals/u.csv\n"                      // 8
    "    column: v\n";                               // 9

TEST_F(ConfigFiles, CsvSignalIsInterpolatedOntoTheGrid) {
  // v = 10 t on a coarser, offset grid: interpolation must give v(k T) = k.
  write("signals/u.csv", "t,v\n0,0\n0.25,2.5\n0.5,5\n0.75,7.5\n1,10\n");
  const Config c = modalwatch::load_config(write("sim.yaml", kCsvSignal));
  ASSERT_TRUE(c.experiment.has_value());
  const auto& e = *c.experiment;
  EXPECT_EQ(e.excitation.kind, modalwatch::SignalSpec::Kind::csv);
  EXPECT_EQ(e.excitation.csv_column, "v");
  EXPECT_TRUE(fs::path(e.excitation.csv_path).is_absolute());
  EXPECT_TRUE(fs::equivalent(e.excitation.csv_path, dir_ / "signals/u.csv"));
  ASSERT_EQ(e.excitation_samples.size(), 10);
  for (int k = 0; k < 10; ++k) EXPECT_NEAR(e.excitation_samples(k), k, 1e-12) << k;
}

TEST_F(ConfigFiles, CsvSignalErrors) {
  const auto yaml = write("sim.yaml", kCsvSignal);
  const auto missing = error_of([&] { modalwatch::load_config(yaml); });
  EXPECT_CONTAINS(missing, yaml + ":8: key 'simulation.input.path': ");
  EXPECT_CONTAINS(missing, "cannot open");
  write("signals/u.csv", "t,w\n0,0\n1,10\n");
  EXPECT_CONTAINS(error_of([&] { modalwatch::load_config(yaml); }),
                  yaml + ":9: key 'simulation.input.column': no such column");
  write("signals/u.csv", "t,v\n0,0\n0.5,10\n");
  EXPECT_CONTAINS(error_of([&] { modalwatch::load_config(yaml); }),
                  yaml + ":8: key 'simulation.input.path': the file covers t in [0, 0.5] s");
  write("signals/u.csv", "t,v\n0,0\n0.5,x\n");
  EXPECT_CONTAINS(error_of([&] { modalwatch::load_config(yaml); }), "row 3, column 'v'");
  write("signals/u.csv", "t,v\n0,0\n1,1\n0.5,1\n");
  EXPECT_CONTAINS(error_of([&] { modalwatch::load_config(yaml); }), "row 4, column 't': time does not increase");
}

// ---------------------------------------------------------------- round trip

void expect_same_submodel(const modalwatch::Submodel& a, const modalwatch::Submodel& b) {
  EXPECT_EQ(a.name, b.name);
  EXPECT_EQ(a.n, b.n);
  EXPECT_EQ(a.m, b.m);
  EXPECT_EQ(a.rigid_poles, b.rigid_poles);
  ASSERT_EQ(a.a.size(), b.a.size());
  ASSERT_EQ(a.b.size(), b.b.size());
  for (Eigen::Index i = 0; i < a.a.size(); ++i) EXPECT_NEAR(a.a(i), b.a(i), 1e-14 * std::abs(b.a(i))) << a.name;
  for (Eigen::Index i = 0; i < a.b.size(); ++i) EXPECT_NEAR(a.b(i), b.b(i), 1e-14 * std::abs(b.b(i))) << a.name;
}

void expect_same_config(const Config& a, const Config& b) {
  EXPECT_NEAR(a.sample_time, b.sample_time, 1e-15 * b.sample_time);
  EXPECT_EQ(a.closed_loop, b.closed_loop);
  EXPECT_EQ(a.output_hold, b.output_hold);
  ASSERT_EQ(a.model.submodels.size(), b.model.submodels.size());
  for (std::size_t i = 0; i < a.model.submodels.size(); ++i) {
    expect_same_submodel(a.model.submodels[i], b.model.submodels[i]);
    EXPECT_EQ(a.submodel_settings[i].forgetting, b.submodel_settings[i].forgetting);
  }
  EXPECT_EQ(a.controller.numerator(), b.controller.numerator());
  EXPECT_EQ(a.controller.denominator(), b.controller.denominator());
  const auto &sa = a.estimator, &sb = b.estimator;
  EXPECT_NEAR(sa.sample_time, sb.sample_time, 1e-15 * sb.sample_time);
  EXPECT_EQ(sa.closed_loop, sb.closed_loop);
  EXPECT_EQ(sa.output_hold, sb.output_hold);
  EXPECT_EQ(sa.controller.numerator(), sb.controller.numerator());
  EXPECT_EQ(sa.forgetting, sb.forgetting);
  EXPECT_EQ(sa.block_iterations, sb.block_iterations);
  EXPECT_EQ(sa.refinements, sb.refinements);
  EXPECT_EQ(sa.update_divisor, sb.update_divisor);
  EXPECT_EQ(sa.warmup_samples, sb.warmup_samples);
  EXPECT_EQ(sa.fit_on_warmup, sb.fit_on_warmup);
  EXPECT_EQ(sa.warmup_iterations, sb.warmup_iterations);
  EXPECT_EQ(sa.initial_covariance_relative, sb.initial_covariance_relative);
  EXPECT_EQ(sa.random_walk, sb.random_walk);
  EXPECT_EQ(sa.covariance_bound, sb.covariance_bound);
  EXPECT_EQ(sa.divergence_ratio, sb.divergence_ratio);
  EXPECT_EQ(sa.gap_factor, sb.gap_factor);
  EXPECT_EQ(sa.outlier_sigma, sb.outlier_sigma);
  EXPECT_EQ(sa.residual_window, sb.residual_window);
  EXPECT_EQ(sa.low_excitation_ratio, sb.low_excitation_ratio);
  EXPECT_EQ(sa.low_excitation_window, sb.low_excitation_window);
  ASSERT_EQ(sa.initial_covariance.size(), sb.initial_covariance.size());
  for (std::size_t i = 0; i < sa.initial_covariance.size(); ++i)
    EXPECT_EQ(sa.initial_covariance[i], sb.initial_covariance[i]) << i;
  ASSERT_EQ(a.plant.has_value(), b.plant.has_value());
  if (a.plant) {
    EXPECT_EQ(a.plant->noise_variance, b.plant->noise_variance);
    EXPECT_EQ(a.plant->snr_db, b.plant->snr_db);
    ASSERT_EQ(a.plant->modes.size(), b.plant->modes.size());
    for (std::size_t i = 0; i < a.plant->modes.size(); ++i) {
      const auto &pa = a.plant->modes[i], &pb = b.plant->modes[i];
      EXPECT_EQ(pa.resonant, pb.resonant);
      EXPECT_EQ(pa.modal.wn, pb.modal.wn);
      EXPECT_EQ(pa.modal.zeta, pb.modal.zeta);
      EXPECT_EQ(pa.modal.gain, pb.modal.gain);
      EXPECT_EQ(pa.wn.points, pb.wn.points);
      EXPECT_EQ(pa.zeta.points, pb.zeta.points);
      EXPECT_EQ(pa.gain.points, pb.gain.points);
      expect_same_submodel(pa.submodel, pb.submodel);
    }
  }
  ASSERT_EQ(a.experiment.has_value(), b.experiment.has_value());
  if (a.experiment) {
    const auto &ea = *a.experiment, &eb = *b.experiment;
    EXPECT_EQ(ea.duration, eb.duration);
    EXPECT_EQ(ea.seed, eb.seed);
    EXPECT_EQ(ea.closed_loop, eb.closed_loop);
    EXPECT_EQ(ea.excitation.kind, eb.excitation.kind);
    EXPECT_EQ(ea.excitation.amplitudes, eb.excitation.amplitudes);
    EXPECT_EQ(ea.excitation.frequencies_rad_s, eb.excitation.frequencies_rad_s);
    EXPECT_EQ(ea.excitation.phases, eb.excitation.phases);
    EXPECT_EQ(ea.excitation.register_bits, eb.excitation.register_bits);
    EXPECT_EQ(ea.excitation.csv_path, eb.excitation.csv_path);
    EXPECT_EQ(ea.excitation_samples, eb.excitation_samples);
  }
}

Config round_trip(const Config& c, const modalwatch::AdditiveModel& model) {
  const std::string yaml = modalwatch::config_to_yaml(c, model);
  try {
    return parse_config(yaml, "roundtrip.yaml");
  } catch (const InputError& e) {
    ADD_FAILURE() << e.what() << "\n" << yaml;
    throw;
  }
}

TEST(ConfigRoundTrip, PaperSim) {
  const Config c = modalwatch::load_config(MODALWATCH_SOURCE_DIR "/config/paper-sim.yaml");
  expect_same_config(round_trip(c, c.model), c);
}

// Every section the parser reads is written: parse(config_to_yaml(c)) == c.
TEST(ConfigRoundTrip, EveryShippedConfig) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(MODALWATCH_SOURCE_DIR "/config"))
    if (entry.path().extension() == ".yaml") files.push_back(entry.path());
  std::sort(files.begin(), files.end());
  ASSERT_GE(files.size(), 7u);
  std::vector<std::string> skipped;
  for (const fs::path& file : files) {
    SCOPED_TRACE(file.filename().string());
    Config c;
    try {
      c = modalwatch::load_config(file.string());
    } catch (const InputError& e) {
      // A signal file from the measured-data folder, which may be absent.
      if (std::string(e.what()).find(MODALWATCH_SHARED_DATA) == std::string::npos) throw;
      skipped.push_back(file.filename().string() + " (" + e.what() + ")");
      continue;
    }
    const std::string yaml = modalwatch::config_to_yaml(c, c.model);
    Config back = round_trip(c, c.model);
    expect_same_config(back, c);
    back.source = c.source;  // the file name, not a setting
    EXPECT_TRUE(back == c) << yaml;
  }
  if (!skipped.empty()) {
    std::string list;
    for (const auto& s : skipped) list += "\n  " + s;
    GTEST_SKIP() << "measured data not found for:" << list;
  }
}

TEST(ConfigRoundTrip, EstimatorSectionAndInitialCovariance) {
  const std::string yaml =
      edit(kBase, "      forgetting: 0.99",
           "      forgetting: 0.99\n      initial_covariance: [1.0e-4, 0.0020000000000000001, 0.3333333333333333]") +
      kEstimator;
  const Config c = parse_config(yaml, "test.yaml");
  const std::string written = modalwatch::config_to_yaml(c, c.model);
  EXPECT_CONTAINS(written, "\nestimator:\n  block_iterations: 3\n");
  EXPECT_CONTAINS(written, "\n  warmup: 12.5\n");
  EXPECT_CONTAINS(written, "\n  fit_on_warmup: false\n");
  // Only the submodel that has one.
  EXPECT_EQ(written.find("initial_covariance:"), written.rfind("initial_covariance:")) << written;
  const Config back = round_trip(c, c.model);
  expect_same_config(back, c);
  ASSERT_EQ(back.estimator.initial_covariance[0].size(), 3);
  EXPECT_EQ(back.estimator.initial_covariance[0](2), 1.0 / 3.0);
  // Defaults are written too, and read back as such.
  const Config d = parse_config(kBase, "test.yaml");
  EXPECT_CONTAINS(modalwatch::config_to_yaml(d, d.model), "\n  low_excitation_ratio: 0.050000000000000003\n");
  expect_estimator_defaults(round_trip(d, d.model).estimator, 0);
}

TEST(ConfigRoundTrip, InitialCovarianceFollowsTheSubmodelName) {
  const std::string yaml =
      edit(kBase, "      forgetting: 0.99", "      forgetting: 0.99\n      initial_covariance: [1, 2, 3]");
  const Config c = parse_config(yaml, "test.yaml");
  // A model written in another order keeps each submodel's covariance.
  modalwatch::AdditiveModel swapped = c.model;
  std::swap(swapped.submodels[0], swapped.submodels[1]);
  const Config back = round_trip(c, swapped);
  ASSERT_EQ(back.estimator.initial_covariance.size(), 2u);
  EXPECT_EQ(back.estimator.initial_covariance[0].size(), 0);
  EXPECT_EQ(back.estimator.initial_covariance[1], Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(back.submodel_settings[1].forgetting, 0.99);
  // A submodel written with another number of parameters drops a covariance that no longer fits.
  modalwatch::AdditiveModel other = c.model;
  other.submodels[0] = modalwatch::make_rigid_body("m1", 2.0);
  const Config dropped = round_trip(c, other);
  EXPECT_EQ(dropped.estimator.initial_covariance[0].size(), 0);
}

TEST(ConfigRoundTrip, ClosedLoopWithRigidBody) {
  const Config c = parse_config(kClosed, "test.yaml");
  expect_same_config(round_trip(c, c.model), c);
}

TEST(ConfigRoundTrip, AllKindsAndSignals) {
  const std::string yaml =
      "sample_rate_hz: 610.3515625\n"
      "model:\n"
      "  output_hold: foh\n"
      "  submodels:\n"
      "    - {name: tf, kind: transfer_function, a: [0.1, 0.01, 0.001], b: [1, 0.5], forgetting: 0.995}\n"
      "    - {name: rb, kind: rigid_body, gain: 0.5, rigid_poles: 1}\n"
      "    - {name: m, wn: 440.0, zeta: 0.01, gain: -2}\n"
      "plant:\n"
      "  snr_db: 25\n"
      "  modes:\n"
      "    - {name: m, frequency_hz: 70, zeta: 0.02, gain: 1, trajectory: {gain: [[0, 1], [5, 2]]}}\n"
      "    - {name: tf, kind: transfer_function, a: [0.1], b: [1], rigid_poles: 1}\n"
      "simulation:\n"
      "  duration: 2.5\n"
      "  input: {type: prbs, register_bits: 12, clock_period: 2, amplitude: 0.1}\n";
  const Config c = parse_config(yaml, "test.yaml");
  expect_same_config(round_trip(c, c.model), c);
  for (const std::string signal :
       {"{type: square, frequency_hz: 3, amplitude: 2, offset: 0.5}",
        "{type: multisine, f_min_hz: 1, f_max_hz: 100, period_s: 10, rms: 0.2}",
        "{type: sum_of_sines, amplitudes: [1, 2], frequencies_hz: [1, 2], phases: [0.1, 0.2]}"}) {
    const Config s = parse_config(edit(yaml, "{type: prbs, register_bits: 12, clock_period: 2, amplitude: 0.1}", signal),
                                  "test.yaml");
    const Config back = round_trip(s, s.model);
    expect_same_config(back, s);
    EXPECT_EQ(back.experiment->excitation.frequency_hz, s.experiment->excitation.frequency_hz);
    EXPECT_EQ(back.experiment->excitation.offset, s.experiment->excitation.offset);
    EXPECT_EQ(back.experiment->excitation.f_max_hz, s.experiment->excitation.f_max_hz);
    EXPECT_EQ(back.experiment->excitation.rms, s.experiment->excitation.rms);
  }
}

TEST(ConfigRoundTrip, WritesTheGivenModel) {
  // A "fitted" model: same names, other values, full precision kept.
  const Config c = modalwatch::load_config(MODALWATCH_SOURCE_DIR "/config/paper-sim.yaml");
  modalwatch::AdditiveModel fitted = c.model;
  fitted.submodels[0] = modalwatch::make_mode("mode1", {1.0 / 3.0, 0.123456789012345, 2.718281828459045});
  fitted.submodels[2].a(0) *= 1.0 + 1e-13;
  const Config back = round_trip(c, fitted);
  Config expected = c;
  expected.model = fitted;
  expect_same_config(back, expected);
}

TEST_F(ConfigFiles, CsvSignalRoundTrip) {
  write("signals/u.csv", "t,v\n0,0\n1,10\n");
  const Config c = modalwatch::load_config(write("sim.yaml", kCsvSignal));
  // Written elsewhere, the absolute path still finds the file.
  fs::create_directories(dir_ / "out");
  const auto out = write("out/fitted.yaml", modalwatch::config_to_yaml(c, c.model));
  expect_same_config(modalwatch::load_config(out), c);
}

}  // namespace

TEST(Config, LcmDefaultsStayOnTheHost) {
  const Config c = parse_config(kBase, "test.yaml");
  EXPECT_EQ(c.lcm.url, "udpm://239.255.76.67:7667?ttl=0");
  EXPECT_EQ(c.lcm.samples_channel, "MODALWATCH_SAMPLES");
  EXPECT_EQ(c.lcm.heartbeat_channel, "MODALWATCH_HEARTBEAT");
}

TEST(Config, LcmSectionAndRoundTrip) {
  const std::string lcm =
      "lcm:\n"                                   // 15
      "  url: memq://\n"                         // 16
      "  channels:\n"                            // 17
      "    samples: X_SAMPLES\n"                 // 18
      "    fault_status: \"X'S STATUS\"\n";    // 19
  const Config c = parse_config(kBase + lcm, "test.yaml");
  EXPECT_EQ(c.lcm.url, "memq://");
  EXPECT_EQ(c.lcm.samples_channel, "X_SAMPLES");
  EXPECT_EQ(c.lcm.batches_channel, "MODALWATCH_BATCHES");
  EXPECT_EQ(c.lcm.fault_status_channel, "X'S STATUS");
  const Config back = parse_config(config_to_yaml(c, c.model), "back.yaml");
  EXPECT_EQ(back.lcm.url, c.lcm.url);
  EXPECT_EQ(back.lcm.samples_channel, c.lcm.samples_channel);
  EXPECT_EQ(back.lcm.fault_status_channel, c.lcm.fault_status_channel);
}

TEST(ConfigErrors, Lcm) {
  EXPECT_EQ(parse_error(kBase + "lcm:\n  url: localhost\n"),
            "test.yaml:16: key 'lcm.url': expected an LCM URL such as udpm://239.255.76.67:7667?ttl=0 or "
            "memq:// (got localhost)");
  EXPECT_EQ(parse_error(kBase + "lcm:\n  channel: X\n"),
            "test.yaml:16: key 'lcm.channel': unknown key for lcm (allowed: url, channels)");
  EXPECT_EQ(parse_error(kBase + "lcm:\n  channels:\n    estimates: MODALWATCH_SAMPLES\n"),
            "test.yaml:17: key 'lcm.channels.estimates': channel 'MODALWATCH_SAMPLES' is also "
            "lcm.channels.samples (got MODALWATCH_SAMPLES)");
  EXPECT_EQ(parse_error(kBase + "lcm:\n  channels:\n    samples: \"\"\n"),
            "test.yaml:17: key 'lcm.channels.samples': expected a non-empty string (got \"\")");
}

TEST(Config, DaemonAndFaultDefaults) {
  const Config c = parse_config(kBase, "test.yaml");
  EXPECT_DOUBLE_EQ(c.daemon.loop_rate_hz, 1000.0);
  EXPECT_DOUBLE_EQ(c.daemon.publish_period, 0.1);
  EXPECT_EQ(c.daemon.sample_ring, 65536);
  EXPECT_DOUBLE_EQ(c.daemon.warmup_backlog, 30.0);
  EXPECT_EQ(c.daemon.realtime_priority, 0);
  EXPECT_TRUE(c.daemon.checkpoint_path.empty());
  EXPECT_EQ(c.daemon.log_level, "info");
  EXPECT_DOUBLE_EQ(c.faults.learn_window, 30.0);
  ASSERT_EQ(c.faults.baselines.size(), 2u);
  EXPECT_FALSE(c.faults.baselines[0]);
  EXPECT_DOUBLE_EQ(c.faults.thresholds[0].sigma_threshold, 4.0);
}

TEST(Config, DaemonAndFaultSectionsAndRoundTrip) {
  const std::string extra =
      "daemon:\n"                                           // 15
      "  loop_rate_hz: 2000\n"                              // 16
      "  publish_period: 0.5\n"                             // 17
      "  heartbeat_period: 2\n"                             // 18
      "  gap_time: 0.25\n"                                  // 19
      "  stale_time: 3\n"                                   // 20
      "  sample_ring: 1024\n"                               // 21
      "  snapshot_ring: 16\n"                               // 22
      "  warmup_backlog: 12.5\n"                            // 23
      "  realtime_priority: 40\n"                           // 24
      "  checkpoint: {path: state/x.ckpt, period: 7}\n"     // 25
      "  log_level: debug\n"                                // 26
      "faults:\n"                                           // 27
      "  learn_window: 12\n"                                // 28
      "  wn: {sigma: 3, relative: 0.02, hold: 1.5}\n"       // 29
      "  zeta: {clear_fraction: 0.25, clear_time: 4}\n"     // 30
      "  baselines:\n"                                      // 31
      "    m2: {frequency_hz: 1.5, zeta: 0.2, gain: 2}\n";  // 32
  const Config c = parse_config(kBase + extra, "/cfg/test.yaml");
  EXPECT_DOUBLE_EQ(c.daemon.loop_rate_hz, 2000.0);
  EXPECT_DOUBLE_EQ(c.daemon.publish_period, 0.5);
  EXPECT_DOUBLE_EQ(c.daemon.heartbeat_period, 2.0);
  EXPECT_DOUBLE_EQ(c.estimator.gap_factor, 5.0);  // 0.25 s at 20 Hz
  EXPECT_DOUBLE_EQ(c.daemon.stale_time, 3.0);
  EXPECT_EQ(c.daemon.sample_ring, 1024);
  EXPECT_EQ(c.daemon.snapshot_ring, 16);
  EXPECT_DOUBLE_EQ(c.daemon.warmup_backlog, 12.5);
  EXPECT_EQ(c.daemon.realtime_priority, 40);
  EXPECT_EQ(c.daemon.checkpoint_path, "/cfg/state/x.ckpt");
  EXPECT_DOUBLE_EQ(c.daemon.checkpoint_period, 7.0);
  EXPECT_EQ(c.daemon.log_level, "debug");
  EXPECT_DOUBLE_EQ(c.faults.learn_window, 12.0);
  EXPECT_DOUBLE_EQ(c.faults.thresholds[0].sigma_threshold, 3.0);
  EXPECT_DOUBLE_EQ(c.faults.thresholds[0].relative_threshold, 0.02);
  EXPECT_DOUBLE_EQ(c.faults.thresholds[0].hold_time, 1.5);
  EXPECT_DOUBLE_EQ(c.faults.thresholds[1].clear_fraction, 0.25);
  EXPECT_DOUBLE_EQ(c.faults.thresholds[1].clear_time, 4.0);
  EXPECT_DOUBLE_EQ(c.faults.thresholds[2].sigma_threshold, 4.0);  // default kept
  ASSERT_FALSE(c.faults.baselines[0]);
  ASSERT_TRUE(c.faults.baselines[1]);
  EXPECT_DOUBLE_EQ(c.faults.baselines[1]->wn, 1.5 * kTwoPi);
  EXPECT_DOUBLE_EQ(c.faults.baselines[1]->gain, 2.0);

  const Config back = parse_config(config_to_yaml(c, c.model), "back.yaml");
  EXPECT_DOUBLE_EQ(back.daemon.loop_rate_hz, c.daemon.loop_rate_hz);
  EXPECT_DOUBLE_EQ(back.daemon.publish_period, c.daemon.publish_period);
  EXPECT_DOUBLE_EQ(back.daemon.heartbeat_period, c.daemon.heartbeat_period);
  EXPECT_DOUBLE_EQ(back.estimator.gap_factor, c.estimator.gap_factor);
  EXPECT_DOUBLE_EQ(back.daemon.stale_time, c.daemon.stale_time);
  EXPECT_EQ(back.daemon.sample_ring, c.daemon.sample_ring);
  EXPECT_EQ(back.daemon.snapshot_ring, c.daemon.snapshot_ring);
  EXPECT_DOUBLE_EQ(back.daemon.warmup_backlog, c.daemon.warmup_backlog);
  EXPECT_EQ(back.daemon.realtime_priority, c.daemon.realtime_priority);
  EXPECT_EQ(back.daemon.checkpoint_path, c.daemon.checkpoint_path);
  EXPECT_DOUBLE_EQ(back.daemon.checkpoint_period, c.daemon.checkpoint_period);
  EXPECT_EQ(back.daemon.log_level, c.daemon.log_level);
  EXPECT_DOUBLE_EQ(back.faults.learn_window, c.faults.learn_window);
  for (int q = 0; q < 3; ++q) {
    EXPECT_DOUBLE_EQ(back.faults.thresholds[q].sigma_threshold, c.faults.thresholds[q].sigma_threshold);
    EXPECT_DOUBLE_EQ(back.faults.thresholds[q].relative_threshold, c.faults.thresholds[q].relative_threshold);
    EXPECT_DOUBLE_EQ(back.faults.thresholds[q].hold_time, c.faults.thresholds[q].hold_time);
    EXPECT_DOUBLE_EQ(back.faults.thresholds[q].clear_fraction, c.faults.thresholds[q].clear_fraction);
    EXPECT_DOUBLE_EQ(back.faults.thresholds[q].clear_time, c.faults.thresholds[q].clear_time);
  }
  ASSERT_FALSE(back.faults.baselines[0]);
  ASSERT_TRUE(back.faults.baselines[1]);
  EXPECT_DOUBLE_EQ(back.faults.baselines[1]->wn, c.faults.baselines[1]->wn);
  EXPECT_DOUBLE_EQ(back.faults.baselines[1]->zeta, c.faults.baselines[1]->zeta);
}

TEST(ConfigErrors, DaemonAndFaults) {
  EXPECT_EQ(parse_error(kBase + "daemon:\n  loop_rate: 5\n"),
            "test.yaml:16: key 'daemon.loop_rate': unknown key for daemon (allowed: loop_rate_hz, publish_period, "
            "heartbeat_period, gap_time, stale_time, sample_ring, snapshot_ring, warmup_backlog, realtime_priority, "
            "checkpoint, log_level)");
  EXPECT_EQ(parse_error(kBase + "daemon:\n  loop_rate_hz: 0\n"),
            "test.yaml:16: key 'daemon.loop_rate_hz': must be > 0 (got 0)");
  EXPECT_EQ(parse_error(kBase + "daemon:\n  publish_period: 0.01\n"),
            "test.yaml:16: key 'daemon.publish_period': must be at least one sample period (got 0.01)");
  EXPECT_EQ(parse_error(kBase + "daemon:\n  gap_time: 0.05\n"),
            "test.yaml:16: key 'daemon.gap_time': must exceed the sample period 0.050000000000000003 s (got 0.05)");
  EXPECT_EQ(parse_error(kBase + "estimator:\n  gap_factor: 2\ndaemon:\n  gap_time: 1\n"),
            "test.yaml:18: key 'daemon.gap_time': give daemon.gap_time or estimator.gap_factor, not both");
  EXPECT_EQ(parse_error(kBase + "daemon:\n  sample_ring: 8\n"),
            "test.yaml:16: key 'daemon.sample_ring': must be in 16..16777216 (got 8)");
  EXPECT_EQ(parse_error(kBase + "daemon:\n  warmup_backlog: 0\n"),
            "test.yaml:16: key 'daemon.warmup_backlog': must be > 0 (got 0)");
  EXPECT_EQ(parse_error(kBase + "daemon:\n  warmup_backlog: 1e6\n"),  // 2e7 samples at 20 Hz
            "test.yaml:16: key 'daemon.warmup_backlog': must hold at most 16777216 samples (838860 s at this "
            "sample rate) (got 1e6)");
  EXPECT_EQ(parse_error(kBase + "daemon:\n  realtime_priority: 100\n"),
            "test.yaml:16: key 'daemon.realtime_priority': must be in 0..99 (got 100)");
  EXPECT_EQ(parse_error(kBase + "daemon:\n  realtime_priority: high\n"),
            "test.yaml:16: key 'daemon.realtime_priority': expected an integer (got high)");
  EXPECT_EQ(parse_error(kBase + "daemon:\n  checkpoint: {period: 5}\n"),
            "test.yaml:16: key 'daemon.checkpoint.path': missing required key");
  EXPECT_EQ(parse_error(kBase + "daemon:\n  log_level: verbose\n"),
            "test.yaml:16: key 'daemon.log_level': must be one of trace, debug, info, warn, error, critical, off "
            "(got verbose)");
  EXPECT_EQ(parse_error(kBase + "faults:\n  wn: {sigma: -1}\n"),
            "test.yaml:16: key 'faults.wn.sigma': must be > 0 (got -1)");
  EXPECT_EQ(parse_error(kBase + "faults:\n  zeta: {clear_fraction: 1}\n"),
            "test.yaml:16: key 'faults.zeta.clear_fraction': must be in (0, 1) (got 1)");
  EXPECT_EQ(parse_error(kBase + "faults:\n  baselines:\n    m3: {wn: 1, zeta: 0.1, gain: 1}\n"),
            "test.yaml:17: key 'faults.baselines.m3': unknown key for faults.baselines (the model's modes) "
            "(allowed: m1, m2)");
  EXPECT_EQ(parse_error(kBase + "faults:\n  baselines:\n    m1: {wn: 1, gain: 1}\n"),
            "test.yaml:17: key 'faults.baselines.m1.zeta': missing required key (kind mode)");
}
