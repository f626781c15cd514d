// The YAML configuration: valid files parse to the values config/README.md
// states, the shipped configs load, and the lcm, daemon and faults sections.
#include "config_support.hpp"

namespace {

// ---------------------------------------------------------------- valid files

TEST(Config, ParsesBase) {
  const Config c = parse_config(kBase, "test.yaml");
  EXPECT_EQ(c.source, "test.yaml");
  EXPECT_DOUBLE_EQ(c.sample_time, 0.05);
  EXPECT_FALSE(c.closed_loop);
  // No output_hold given: default_output_hold of the modes, zoh for modes at 0.016 and 0.05 fs.
  EXPECT_FALSE(c.output_hold.has_value());
  EXPECT_EQ(c.estimator.output_hold, modalwatch::Hold::zoh);
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

TEST(Config, WithoutAnOutputHoldAModeAtAFifthOfTheSamplingRateGetsFoh) {
  // m2 at 1 Hz sampled at 5 Hz: its sampled output is far from held.
  const Config c = parse_config(edit(kBase, "sample_rate_hz: 20", "sample_rate_hz: 5"), "test.yaml");
  EXPECT_FALSE(c.output_hold.has_value());
  EXPECT_EQ(c.estimator.output_hold, modalwatch::Hold::foh);
  // Given, it is kept.
  const Config z = parse_config(
      edit(edit(kBase, "sample_rate_hz: 20", "sample_rate_hz: 5"), "  loop: open", "  loop: open\n  output_hold: zoh"),
      "test.yaml");
  EXPECT_EQ(z.estimator.output_hold, modalwatch::Hold::zoh);
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
  EXPECT_EQ(c.estimator.output_hold, modalwatch::Hold::zoh);
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
  EXPECT_DOUBLE_EQ(e.change_ratio, 3.0);
  EXPECT_DOUBLE_EQ(e.change_threshold, 12.0);
  EXPECT_DOUBLE_EQ(e.change_hold, 0.5);
  // Still completed from the other sections.
  EXPECT_DOUBLE_EQ(e.sample_time, 0.05);
  EXPECT_EQ(e.forgetting, (std::vector<double>{0.99, 1.0}));
  EXPECT_EQ(e.random_walks, (std::vector<double>{1e-4, 1e-4}));  // estimator.random_walk for each
  // A submodel's own random walk overrides the section's, and survives the round trip.
  const Config own = parse_config(
      edit(kBase, "      forgetting: 0.99", "      forgetting: 0.99\n      random_walk: 3.0e-4") + kEstimator,
      "test.yaml");
  EXPECT_EQ(own.estimator.random_walks, (std::vector<double>{3e-4, 1e-4}));
  EXPECT_EQ(parse_config(modalwatch::config_to_yaml(own, own.model), "again.yaml").estimator.random_walks,
            own.estimator.random_walks);
  EXPECT_EQ(parse_error(edit(kBase, "      forgetting: 0.99", "      forgetting: 0.99\n      random_walk: -1")),
            "test.yaml:11: key 'model.submodels[0].random_walk': must be >= 0 (got -1)");
  // Boundary values that are allowed.
  const std::string edge =
      edit(edit(edit(edit(edit(edit(kEstimator, "refinements: 2", "refinements: 0"), "warmup: 12.5", "warmup: 0"),
                          "random_walk: 1.0e-4", "random_walk: 0"),
                     "low_excitation_ratio: 0.2", "low_excitation_ratio: 0"),
                "residual_window: 30", "residual_window: 0"),
           "change_ratio: 3", "change_ratio: 0");
  const Config z = parse_config(kBase + edge, "test.yaml");
  EXPECT_EQ(z.estimator.refinements, 0);
  EXPECT_EQ(z.estimator.warmup_samples, 0);
  EXPECT_EQ(z.estimator.change_ratio, 0.0);
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
  EXPECT_EQ(samples("0.03"), 1);    // 0.6 samples
  EXPECT_EQ(samples("1.024"), 20);  // 20.48 samples
  EXPECT_EQ(samples("1.026"), 21);  // 20.52 samples
  const Config beam = parse_config(
      edit(kBase, "sample_rate_hz: 20", "sample_rate_hz: 4096") + "estimator:\n  warmup: 5\n", "test.yaml");
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
  EXPECT_EQ(c.estimator.output_hold, modalwatch::Hold::foh);
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

}  // namespace

TEST(Config, LcmDefaultsStayOnTheHost) {
  const Config c = parse_config(kBase, "test.yaml");
  EXPECT_EQ(c.lcm.url, "udpm://239.255.76.67:7667?ttl=0");
  EXPECT_EQ(c.lcm.samples_channel, "MODALWATCH_SAMPLES");
  EXPECT_EQ(c.lcm.heartbeat_channel, "MODALWATCH_HEARTBEAT");
}

TEST(Config, LcmSectionAndRoundTrip) {
  const std::string lcm =
      "lcm:\n"                               // 15
      "  url: memq://\n"                     // 16
      "  channels:\n"                        // 17
      "    samples: X_SAMPLES\n"             // 18
      "    fault_status: \"X'S STATUS\"\n";  // 19
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

// A resonance with a complex residue ((b0 + b1 p) / (1 + a1 p + a2 p^2), as
// diagnose's complex modes write it) is watched as a mode is: its baseline is
// (wn, zeta, DC gain b0). A rigid body has none.
TEST(Config, AComplexResidueResonanceTakesABaselineARigidBodyDoesNot) {
  const std::string model =
      "sample_rate_hz: 20\n"                                                       // 1
      "model:\n"                                                                   // 2
      "  loop: open\n"                                                             // 3
      "  submodels:\n"                                                             // 4
      "    - {name: c1, kind: transfer_function, a: [0.05, 0.25], b: [2, 0.1]}\n"  // 5
      "    - {name: r1, kind: rigid_body, gain: 0.5}\n"                            // 6
      "faults:\n"                                                                  // 7
      "  baselines:\n";                                                            // 8
  const Config c = parse_config(model + "    c1: {wn: 2, zeta: 0.05, gain: 2}\n", "test.yaml");
  ASSERT_TRUE(c.faults.baselines[0]);
  EXPECT_DOUBLE_EQ(c.faults.baselines[0]->wn, 2.0);
  EXPECT_FALSE(c.faults.baselines[1]);
  EXPECT_EQ(parse_error(model + "    r1: {wn: 2, zeta: 0.05, gain: 2}\n"),
            "test.yaml:9: key 'faults.baselines.r1': unknown key for faults.baselines (the model's modes) "
            "(allowed: c1)");
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
            "checkpoint, log_level, metrics)");
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
  EXPECT_EQ(parse_error(kBase + "faults:\n  false_alarm_interval: 0\n"),
            "test.yaml:16: key 'faults.false_alarm_interval': must be > 0 (got 0)");
  EXPECT_EQ(parse_error(kBase + "faults:\n  cusum_shift: -1\n"),
            "test.yaml:16: key 'faults.cusum_shift': must be > 0 (got -1)");
  EXPECT_EQ(parse_error(kBase + "faults:\n  settle_std_fraction: x\n"),
            "test.yaml:16: key 'faults.settle_std_fraction': expected a number (got x)");
  EXPECT_EQ(parse_error(kBase + "faults:\n  settle_change_fraction: 0\n"),
            "test.yaml:16: key 'faults.settle_change_fraction': must be > 0 (got 0)");
  EXPECT_EQ(parse_error(kBase + "faults:\n  memory_time: 2\n"),
            "test.yaml:16: key 'faults.memory_time': unknown key for faults (allowed: learn_window, "
            "false_alarm_interval, cusum_shift, settle_std_fraction, settle_change_fraction, wn, zeta, gain, "
            "baselines)");
  EXPECT_EQ(parse_error(kBase + "faults:\n  baselines:\n    m1: {wn: 1, zeta: 0.1, gain: 1, std: {zeta: -0.1}}\n"),
            "test.yaml:17: key 'faults.baselines.m1.std.zeta': must be >= 0 (got -0.1)");
  EXPECT_EQ(
      parse_error(kBase + "faults:\n  baselines:\n    m1: {wn: 1, zeta: 0.1, gain: 1, std: {frequency_hz: -1}}\n"),
      "test.yaml:17: key 'faults.baselines.m1.std.frequency_hz': must be >= 0 (got -1)");
  EXPECT_EQ(parse_error(kBase + "faults:\n  baselines:\n    m1: {wn: 1, zeta: 0.1, gain: 1, std: {q: 1}}\n"),
            "test.yaml:17: key 'faults.baselines.m1.std.q': unknown key for a baseline's std (allowed: wn, "
            "frequency_hz, zeta, gain)");
  EXPECT_EQ(parse_error(kBase + "daemon:\n  metrics: {listen: 9464}\n"),
            "test.yaml:16: key 'daemon.metrics.listen': expected host:port, e.g. 127.0.0.1:9464 (port 1..65535) "
            "(got 9464)");
  EXPECT_EQ(parse_error(kBase + "daemon:\n  metrics: {listen: \"localhost:70000\"}\n"),
            "test.yaml:16: key 'daemon.metrics.listen': expected host:port, e.g. 127.0.0.1:9464 (port 1..65535) "
            "(got \"localhost:70000\")");
  EXPECT_EQ(parse_error(kBase + "daemon:\n  metrics: {port: 1}\n"),
            "test.yaml:16: key 'daemon.metrics.port': unknown key for daemon.metrics (allowed: listen)");
  EXPECT_EQ(parse_error("axis: [x]\n" + kBase), "test.yaml:1: key 'axis': expected a non-empty string (got [x])");
}

// The new detector keys, a baseline's std, axis and daemon.metrics: parsed,
// defaulted and written back.
TEST(Config, DetectorKeysAxisAndMetricsRoundTrip) {
  const Config d = parse_config(kBase, "/etc/modalwatch/axis-x.yaml");
  EXPECT_EQ(d.axis, "axis-x");
  EXPECT_TRUE(d.daemon.metrics_listen.empty());
  EXPECT_DOUBLE_EQ(d.faults.false_alarm_interval, 1000.0);
  EXPECT_DOUBLE_EQ(d.faults.cusum_shift, 1.0);
  EXPECT_DOUBLE_EQ(d.faults.settle_std_fraction, 0.5);
  EXPECT_DOUBLE_EQ(d.faults.settle_change_fraction, 0.1);
  ASSERT_EQ(d.faults.baseline_std.size(), 2u);
  EXPECT_FALSE(d.faults.baseline_std[1]);
  EXPECT_EQ(parse_config(kBase + "daemon:\n  metrics: {listen: \"\"}\n", "t.yaml").daemon.metrics_listen, "");

  const std::string extra =
      "daemon:\n"
      "  publish_period: 0.25\n"
      "  metrics: {listen: \"127.0.0.1:9464\"}\n"
      "faults:\n"
      "  learn_window: 12\n"
      "  false_alarm_interval: 5000\n"
      "  cusum_shift: 1.5\n"
      "  settle_std_fraction: 0.25\n"
      "  settle_change_fraction: 0.2\n"
      "  baselines:\n"
      "    m1: {wn: 2, zeta: 0.25, gain: 3}\n"
      "    m2: {frequency_hz: 1.5, zeta: 0.2, gain: 2, std: {frequency_hz: 0.01, gain: 0.1}}\n";
  const Config c = parse_config("axis: \"stage y\"\n" + kBase + extra, "/cfg/test.yaml");
  EXPECT_EQ(c.axis, "stage y");
  EXPECT_EQ(c.daemon.metrics_listen, "127.0.0.1:9464");
  EXPECT_DOUBLE_EQ(c.faults.false_alarm_interval, 5000.0);
  EXPECT_DOUBLE_EQ(c.faults.cusum_shift, 1.5);
  EXPECT_DOUBLE_EQ(c.faults.settle_std_fraction, 0.25);
  EXPECT_DOUBLE_EQ(c.faults.settle_change_fraction, 0.2);
  EXPECT_FALSE(c.faults.baseline_std[0]);
  ASSERT_TRUE(c.faults.baseline_std[1]);
  EXPECT_DOUBLE_EQ(c.faults.baseline_std[1]->wn, 0.01 * kTwoPi);
  EXPECT_EQ(c.faults.baseline_std[1]->zeta, 0.0);
  EXPECT_DOUBLE_EQ(c.faults.baseline_std[1]->gain, 0.1);
  Config back = parse_config(config_to_yaml(c, c.model), "/cfg/test.yaml");
  back.source = c.source;
  EXPECT_EQ(back.axis, c.axis);
  EXPECT_EQ(back.daemon, c.daemon);
  EXPECT_EQ(back.faults, c.faults);

  // The detector's settings: the section, memory Ts / (1 - lambda) (m1: 0.05 /
  // 0.01 = 5 s; m2 does not forget: the learning window), update period =
  // publish period, the std as the configured baselines' (0 where not given).
  const FaultDetectorSettings s = modalwatch::fault_detector_settings(c);
  EXPECT_EQ(s.mode_names, (std::vector<std::string>{"m1", "m2"}));
  ASSERT_EQ(s.memory_time.size(), 2u);
  EXPECT_NEAR(s.memory_time[0], 5.0, 1e-12);
  EXPECT_EQ(s.memory_time[1], 12.0);
  EXPECT_EQ(s.update_period, 0.25);
  EXPECT_EQ(s.false_alarm_interval, 5000.0);
  EXPECT_EQ(s.cusum_shift, 1.5);
  EXPECT_EQ(s.settle_std_fraction, 0.25);
  EXPECT_EQ(s.settle_change_fraction, 0.2);
  EXPECT_EQ(s.learn_window, 12.0);
  ASSERT_EQ(s.baselines.size(), 2u);
  EXPECT_EQ(s.baselines[0]->wn, 2.0);
  ASSERT_EQ(s.baseline_std.size(), 2u);
  EXPECT_EQ(s.baseline_std[0].wn, 0.0);
  EXPECT_EQ(s.baseline_std[1].gain, 0.1);
  EXPECT_NO_THROW(FaultDetector{s});
  // Without any std the detector takes every configured baseline as exact.
  EXPECT_TRUE(modalwatch::fault_detector_settings(d).baseline_std.empty());
}
