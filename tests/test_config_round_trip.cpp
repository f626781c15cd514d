// The configuration written back: csv signals and the round trip through
// config_to_yaml, every shipped config and every section.
#include "config_support.hpp"

namespace {

// ---------------------------------------------------------------- files

class ConfigFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    std::random_device rd;
    dir_ = fs::temp_directory_path() / ("modalwatch-config-" + std::to_string(::getpid()) + "-" + std::to_string(rd()));
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
    "sample_rate_hz: 10\n"                                   // 1
    "model:\n"                                               // 2
    "  submodels: [{name: m, wn: 1, zeta: 0.1, gain: 1}]\n"  // 3
    "simulation:\n"                                          // 4
    "  duration: 1\n"                                        // 5
    "  input:\n"                                             // 6
    "    type: csv\n"                                        // 7
    "    path: signals/u.csv\n"                              // 8
    "    column: v\n";                                       // 9

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
  EXPECT_EQ(sa.change_ratio, sb.change_ratio);
  EXPECT_EQ(sa.change_threshold, sb.change_threshold);
  EXPECT_EQ(sa.change_hold, sb.change_hold);
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

TEST(ConfigRoundTrip, FeedthroughAndModesOnly) {
  const std::string yaml =
      "sample_rate_hz: 100\n"
      "model:\n"
      "  submodels:\n"
      "    - {name: m, wn: 40.0, zeta: 0.02, gain: 1}\n"
      "    - {name: direct, kind: feedthrough, gain: -0.3}\n";
  const Config c = parse_config(yaml, "test.yaml");
  const std::string written = modalwatch::config_to_yaml(c, c.model);
  EXPECT_CONTAINS(written, "kind: feedthrough");
  expect_same_config(round_trip(c, c.model), c);
  const Config modes = parse_config("sample_rate_hz: 100\nmodel:\n  modes: 4\n", "test.yaml");
  expect_same_config(round_trip(modes, modes.model), modes);
}

TEST(ConfigRoundTrip, UnstableSubmodelIsNotWritten) {
  const Config c = parse_config("sample_rate_hz: 100\nmodel:\n  submodels: [{name: m, wn: 40.0, zeta: 0.02, gain: 1}]\n",
                                "test.yaml");
  modalwatch::AdditiveModel fitted = c.model;
  fitted.submodels[0].a(0) = -fitted.submodels[0].a(0);  // zeta = -0.02: written as a transfer_function before
  try {
    modalwatch::config_to_yaml(c, fitted);
    ADD_FAILURE() << "an unstable submodel was written";
  } catch (const std::invalid_argument& e) {
    EXPECT_CONTAINS(std::string(e.what()),
                    "submodel m: A(p) has a root in the right half plane; an unstable model is not written");
  }
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
    const Config s = parse_config(
        edit(yaml, "{type: prbs, register_bits: 12, clock_period: 2, amplitude: 0.1}", signal), "test.yaml");
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
