// The YAML configuration's errors: every validation of config/README.md with
// the exact file:line and key path of its message.
#include "config_support.hpp"

namespace {

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
            "feedthrough, transfer_function (got spring)");
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
      {"update_divisor: 4", "update_divisor: 0", "test.yaml:18: key 'estimator.update_divisor': must be >= 1 (got 0)"},
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
      {"change_ratio: 3", "change_ratio: 1",
       "test.yaml:31: key 'estimator.change_ratio': must be 0 (off) or > 1 (got 1)"},
      {"change_threshold: 12", "change_threshold: 0",
       "test.yaml:32: key 'estimator.change_threshold': must be > 0 (got 0)"},
      {"change_hold: 0.5", "change_hold: -1", "test.yaml:33: key 'estimator.change_hold': must be >= 0 (got -1)"},
  };
  for (const auto& c : cases) EXPECT_EQ(parse_error(kBase + edit(kEstimator, c.from, c.to)), c.message) << c.to;
}

TEST(ConfigErrors, EstimatorKeysAndShape) {
  const auto unknown = parse_error(kBase + kEstimator + "  forgetting: 0.99\n");
  EXPECT_EQ(
      unknown,
      "test.yaml:34: key 'estimator.forgetting': unknown key for estimator (allowed: block_iterations, "
      "refinements, update_divisor, warmup, fit_on_warmup, warmup_iterations, initial_covariance_relative, "
      "random_walk, covariance_bound, stabilisation, min_memory, settled_memory, damping_deadband, divergence_ratio, "
      "change_ratio, "
      "change_threshold, change_hold, "
      "gap_factor, "
      "outlier_sigma, residual_window, "
      "low_excitation_ratio, low_excitation_window)");
  EXPECT_EQ(parse_error(kBase + kEstimator + "  warmup: 3\n"),
            "test.yaml:34: key 'estimator.warmup': duplicate key (first at line 19)");
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
  EXPECT_EQ(
      parse_error(edit(kBase, "  submodels:\n", "  submodels: []\n  old:\n")),
      "test.yaml:5: key 'model.old': unknown key for model (allowed: loop, output, output_hold, inputs, submodels, modes)");
}

TEST(ConfigErrors, EmptySubmodelList) {
  const std::string yaml = "sample_rate_hz: 20\nmodel:\n  submodels: []\n";
  EXPECT_EQ(parse_error(yaml), "test.yaml:3: key 'model.submodels': must list at least one submodel (got [])");
}

const std::string kTf =
    "sample_rate_hz: 20\n"             // 1
    "model:\n"                         // 2
    "  submodels:\n"                   // 3
    "    - name: tf\n"                 // 4
    "      kind: transfer_function\n"  // 5
    "      a: [0.1, 0.01]\n"           // 6
    "      b: [1, 0.5]\n";             // 7

TEST(ConfigErrors, TransferFunctionOrders) {
  EXPECT_NO_THROW(parse_config(kTf, "test.yaml"));
  const auto msg = parse_error(edit(kTf, "b: [1, 0.5]", "b: [1, 0.5, 0.2, 0.1]"));
  EXPECT_CONTAINS(msg, "test.yaml:7: key 'model.submodels[0].b': ");
  EXPECT_CONTAINS(msg, "m = 3");
  EXPECT_CONTAINS(msg, "n + l = 2 + 0");
  EXPECT_CONTAINS(msg, "(got [1, 0.5, 0.2, 0.1])");
  // Rigid poles allow a higher B.
  EXPECT_NO_THROW(parse_config(edit(kTf, "b: [1, 0.5]", "b: [1, 0.5, 0.2, 0.1]\n      rigid_poles: 1"), "test.yaml"));
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
            "kind, a, b, rigid_poles, input, poles_of, forgetting, random_walk, stabilisation, min_memory, "
            "initial_covariance)");
}

TEST(ConfigErrors, UnstableTransferFunction) {
  // A(p) = 1 - 0.1 p + 0.01 p^2: zeta = -0.5, rejected like zeta <= 0 for a mode.
  EXPECT_EQ(parse_error(edit(kTf, "a: [0.1, 0.01]", "a: [-0.1, 0.01]")),
            "test.yaml:6: key 'model.submodels[0].a': A(p) = 1 + a_1 p + ... + a_n p^n has a root in the right "
            "half plane (unstable) (got [-0.1, 0.01])");
  // a_2 < 0: a real root in the right half plane.
  EXPECT_CONTAINS(parse_error(edit(kTf, "a: [0.1, 0.01]", "a: [0.1, -0.01]")),
                  "test.yaml:6: key 'model.submodels[0].a': A(p) = 1 + a_1 p + ... + a_n p^n has a root in the right "
                  "half plane (unstable)");
  // Third order, Routh fails: 1 + 0.1 p + 0.01 p^2 + 0.01 p^3.
  EXPECT_CONTAINS(parse_error(edit(kTf, "a: [0.1, 0.01]", "a: [0.1, 0.01, 0.01]")),
                  "test.yaml:6: key 'model.submodels[0].a': A(p) = 1 + a_1 p + ... + a_n p^n has a root in the right "
                  "half plane (unstable)");
  // Roots on the imaginary axis, (1 + 0.1 p)(1 + 0.01 p^2), are a lossless model, not an unstable one.
  EXPECT_NO_THROW(parse_config(edit(kTf, "a: [0.1, 0.01]", "a: [0.1, 0.01, 0.001]"), "test.yaml"));
}

TEST(ConfigErrors, ModesInsteadOfSubmodels) {
  const Config c = parse_config("sample_rate_hz: 20\nmodel:\n  modes: 3\n", "test.yaml");
  EXPECT_EQ(c.model_modes, 3);
  EXPECT_TRUE(c.model.submodels.empty());
  EXPECT_EQ(parse_error("sample_rate_hz: 20\nmodel:\n  modes: 0\n"),
            "test.yaml:3: key 'model.modes': must be in 1..64 (got 0)");
  EXPECT_EQ(parse_error(edit(kBase, "  submodels:\n", "  modes: 2\n  submodels:\n")),
            "test.yaml:4: key 'model.modes': give submodels (initial modes) or modes (a count to start from the "
            "data), not both (got 2)");
  EXPECT_EQ(parse_error("sample_rate_hz: 20\nmodel:\n  loop: open\n"),
            "test.yaml:2: key 'model.submodels': missing required key (or modes: N to start N modes from the data)");
}

TEST(ConfigErrors, Feedthrough) {
  const Config c = parse_config(edit(kTf, "      kind: transfer_function\n      a: [0.1, 0.01]\n      b: [1, 0.5]\n",
                                     "      kind: feedthrough\n      gain: 0.25\n"),
                                "test.yaml");
  ASSERT_EQ(c.model.submodels.size(), 1u);
  EXPECT_TRUE(c.model.submodels[0].is_feedthrough());
  EXPECT_EQ(c.model.submodels[0].b(0), 0.25);
  EXPECT_EQ(parse_error(edit(kTf, "      kind: transfer_function\n      a: [0.1, 0.01]\n      b: [1, 0.5]\n",
                             "      kind: feedthrough\n      gain: 0.25\n      rigid_poles: 1\n")),
            "test.yaml:7: key 'model.submodels[0].rigid_poles': unknown key for kind feedthrough (allowed: name, "
            "kind, gain, input, poles_of, forgetting, random_walk, stabilisation, min_memory, initial_covariance)");
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
  EXPECT_CONTAINS(tf,
                  "test.yaml:8: key 'model.submodels[0].initial_covariance': must have n + m + 1 = 2 + 1 + 1 = 4 "
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
  const std::string rb =
      "sample_rate_hz: 20\nmodel:\n  submodels:\n    - {name: b, kind: rigid_body, gain: 2, "
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
  const auto improper =
      parse_error(edit(kClosed, "numerator: [0.02329, -0.02058, 0.00454]", "numerator: [1, 2, 3, 4]"));
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
            "kind, gain, rigid_poles, input)");
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

}  // namespace
