// The modalwatch command line as a user meets it: real files, the real binary,
// exit codes, and messages that say where the problem is.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "support.hpp"

#include "modalwatch/fault_detector.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/io/csv.hpp"
#include "modalwatch/io/records.hpp"

namespace fs = std::filesystem;

namespace modalwatch {
namespace {

using test_support::Outcome;
Outcome run(const std::string& args) { return test_support::run_cli(args); }

class Cli : public test_support::ScratchDir {
 public:
  static std::string config(const std::string& name) { return test_support::source_file("config/" + name); }
};

bool contains(const std::string& text, const std::string& what) { return text.find(what) != std::string::npos; }

TEST_F(Cli, SimulateThenFitPrintsTheModalTableAndWritesAReusableModel) {
  const Outcome sim = run("simulate --config " + config("paper-sim.yaml") + " --out " + path("d.csv") + " --truth " +
                          path("truth.csv") + " --duration 200");
  ASSERT_EQ(sim.code, 0) << sim.output;
  const Record r = read_record(path("d.csv"));
  EXPECT_EQ(r.size(), 4000);
  EXPECT_TRUE(r.has_reference());
  const Table truth = read_table(path("truth.csv"));
  EXPECT_EQ(truth.column("mode3_wn"), 7);

  const Outcome fit = run("fit --config " + config("paper-sim.yaml") + " --data " + path("d.csv") + " --to 90 --out " +
                          path("fitted.yaml"));
  ASSERT_EQ(fit.code, 0) << fit.output;
  for (const char* s : {"mode1", "mode2", "mode3", "f [Hz]", "zeta", "fit on the data"})
    EXPECT_TRUE(contains(fit.output, s)) << s << "\n" << fit.output;
  // The written model seeds the next command.
  const Config fitted = load_config(path("fitted.yaml"));
  ASSERT_EQ(fitted.model.submodels.size(), 3u);
  EXPECT_NEAR(modal_parameters(fitted.model.submodels[1]).wn, 5.0, 0.05);
  const Outcome again = run("fit --config " + path("fitted.yaml") + " --data " + path("d.csv") + " --to 90");
  EXPECT_EQ(again.code, 0) << again.output;
}

// Commissioning: `fit --baselines` writes the fitted modes with their standard
// deviations as the fault detector's baselines, so the daemon and `track
// --faults` test against them from the first update instead of learning.
TEST_F(Cli, FitWithBaselinesWritesTheFittedModesAsTheDetectorsConfiguredBaselines) {
  ASSERT_EQ(run("simulate --config " + config("paper-sim.yaml") + " --out " + path("d.csv") + " --duration 100").code,
            0);
  const Outcome fit = run("fit --config " + config("paper-sim.yaml") + " --data " + path("d.csv") + " --to 90 --out " +
                          path("fitted.yaml") + " --baselines");
  ASSERT_EQ(fit.code, 0) << fit.output;
  EXPECT_TRUE(contains(fit.output, "baselines: 3 modes")) << fit.output;
  const Config fitted = load_config(path("fitted.yaml"));
  ASSERT_EQ(fitted.faults.baselines.size(), 3u);
  const double truth_wn[3] = {2.0, 5.0, 20.0};  // rad/s: the plant over the first 90 s
  for (std::size_t i = 0; i < 3; ++i) {
    ASSERT_TRUE(fitted.faults.baselines[i].has_value()) << "mode " << i + 1;
    ASSERT_TRUE(fitted.faults.baseline_std[i].has_value()) << "mode " << i + 1;
    const ModalParameters fitted_mode = modal_parameters(fitted.model.submodels[i]);
    // The baseline is the fitted model's mode, its std the fit's.
    EXPECT_DOUBLE_EQ(fitted.faults.baselines[i]->wn, fitted_mode.wn);
    EXPECT_DOUBLE_EQ(fitted.faults.baselines[i]->gain, fitted_mode.gain);
    const ModalParameters& sd = *fitted.faults.baseline_std[i];
    for (double s : {sd.wn, sd.zeta, sd.gain}) {
      EXPECT_GT(s, 0.0) << "mode " << i + 1;
      EXPECT_TRUE(std::isfinite(s)) << "mode " << i + 1;
    }
    // The std says how far the baseline may be from the truth: mode 3, at one
    // radian per sample, is the least certain (about 1 %).
    EXPECT_LT(std::abs(fitted.faults.baselines[i]->wn - truth_wn[i]), 5.0 * sd.wn) << "mode " << i + 1;
    EXPECT_LT(sd.wn, 0.02 * fitted_mode.wn) << "mode " << i + 1;
  }
  FaultDetector detector(fault_detector_settings(fitted));
  for (const ModeStatus& m : detector.status()) {
    EXPECT_EQ(m.state, BaselineState::configured);
    EXPECT_TRUE(m.baseline_ready);
  }
  // Without --out there is nothing to write them to.
  const Outcome alone = run("fit --config " + config("paper-sim.yaml") + " --data " + path("d.csv") + " --baselines");
  EXPECT_NE(alone.code, 0);
  EXPECT_TRUE(contains(alone.output, "--baselines requires --out")) << alone.output;
}

// --from keeps the samples before it for the filters, and the seed's four-sine
// setpoint in steady state (after the ramps, t > 800 s) cannot determine nine
// parameters: the fit says so and names the parameters left open.
TEST_F(Cli, FitOfASteadyFourSineWindowSettlesOnItsPastAndWarnsOfTheOpenDirection) {
  ASSERT_EQ(run("simulate --config " + config("paper-sim.yaml") + " --out " + path("d.csv")).code, 0);
  const Outcome fit = run("fit --config " + config("paper-sim.yaml") + " --data " + path("d.csv") + " --from 900");
  ASSERT_EQ(fit.code, 0) << fit.output;
  for (const char* s : {"modalwatch fit: 2000 samples", "(the 18000 samples before --from run the filters",
                        "WARNING: the record does not determine every parameter", "mode2        b_0"})
    EXPECT_TRUE(contains(fit.output, s)) << s << "\n" << fit.output;
  // The noise std is 0.1: the window fits to it (cut from rest it would not).
  const auto at = fit.output.find("output-error std: ");
  ASSERT_NE(at, std::string::npos);
  EXPECT_NEAR(std::stod(fit.output.substr(at + 18)), 0.1, 0.01) << fit.output;
}

// Bad records: exit code 2, a message naming row and column, nothing written.
void expect_rejected(const Cli& t, const std::string& csv_text, const std::string& must_say1,
                     const std::string& must_say2) {
  const std::string data = t.write("bad.csv", csv_text);
  const std::string out = t.path("out.yaml");
  const Outcome r = run("fit --config " + Cli::config("paper-sim.yaml") + " --data " + data + " --out " + out);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_TRUE(contains(r.output, must_say1)) << r.output;
  EXPECT_TRUE(contains(r.output, must_say2)) << r.output;
  EXPECT_FALSE(fs::exists(out));
}

std::string good_rows(int n) {
  std::ostringstream s;
  for (int k = 0; k < n; ++k) s << k * 0.05 << ",0.1," << (k % 3) * 0.2 << "," << (k % 5) * 0.1 << "\n";
  return s.str();
}

// Three modes, and a config that names only their count: `fit` starts them
// from the data and writes a model that seeds the next command.
const std::string kThreeModes =
    "sample_rate_hz: 100\n"
    "model:\n"
    "  modes: 3\n"
    "plant:\n"
    "  snr_db: 30\n"
    "  modes:\n"
    "    - {name: a, frequency_hz: 3.2, zeta: 0.02, gain: 0.08}\n"
    "    - {name: b, frequency_hz: 5.6, zeta: 0.06, gain: 0.22}\n"
    "    - {name: c, frequency_hz: 9.9, zeta: 0.024, gain: -0.1}\n"
    "simulation:\n"
    "  duration: 120\n"
    "  seed: 3\n"
    "  input: {type: prbs, register_bits: 14, clock_period: 1, amplitude: 1}\n";

// A record of kThreeModes' plant in d.csv, its config in plant.yaml.
class CliThreeModes : public Cli {
 protected:
  void SetUp() override {
    Cli::SetUp();
    write("plant.yaml", kThreeModes);
    ASSERT_EQ(run("simulate --config " + path("plant.yaml") + " --out " + path("d.csv")).code, 0);
  }
};

// The model fitted on kThreeModes' record: each mode within 1 % in frequency and 20 % in damping.
void expect_three_modes(const AdditiveModel& m) {
  ASSERT_EQ(m.submodels.size(), 3u);
  const double hz[] = {3.2, 5.6, 9.9}, zeta[] = {0.02, 0.06, 0.024};
  for (int i = 0; i < 3; ++i) {
    const ModalParameters p = modal_parameters(m.submodels[static_cast<std::size_t>(i)]);
    EXPECT_NEAR(p.hz(), hz[i], 0.01 * hz[i]) << i;
    EXPECT_NEAR(p.zeta, zeta[i], 0.2 * zeta[i]) << i;
  }
}

TEST_F(CliThreeModes, FitWithModesOnlyStartsFromTheData) {
  const Outcome fit = run("fit --config " + path("plant.yaml") + " --data " + path("d.csv") + " --out " +
                          path("fitted.yaml"));
  ASSERT_EQ(fit.code, 0) << fit.output;
  EXPECT_TRUE(contains(fit.output, "initial modes from the data (peaks of H1 = S_yu/S_uu)")) << fit.output;
  EXPECT_FALSE(contains(fit.output, "WARNING")) << fit.output;
  const Config fitted = load_config(path("fitted.yaml"));
  expect_three_modes(fitted.model);
  // --modes overrides the file: one mode asked, one fitted.
  const Outcome one = run("fit --config " + path("fitted.yaml") + " --data " + path("d.csv") + " --modes 1");
  ASSERT_EQ(one.code, 0) << one.output;
  EXPECT_TRUE(contains(one.output, "1 submodels")) << one.output;
  // The recursive estimator needs the submodels themselves.
  const Outcome track = run("track --config " + path("plant.yaml") + " --data " + path("d.csv") + " --out " +
                            path("est.csv"));
  EXPECT_EQ(track.code, 2) << track.output;
  EXPECT_TRUE(contains(track.output, "track needs the submodels")) << track.output;
}

// --max-modes chooses the number of modes by BIC and writes the stabilisation
// diagram's tables; it cannot go with --modes.
TEST_F(CliThreeModes, FitWithMaxModesChoosesThreeAndWritesTheStabilisationDiagram) {
  const std::string dir = path("stab");
  const Outcome fit = run("fit --config " + path("plant.yaml") + " --data " + path("d.csv") +
                          " --max-modes 5 --stabilisation " + dir + " --out " + path("fitted.yaml"));
  ASSERT_EQ(fit.code, 0) << fit.output;
  EXPECT_TRUE(contains(fit.output, "<- chosen")) << fit.output;
  expect_three_modes(load_config(path("fitted.yaml")).model);
  std::ifstream json(dir + "/summary.json");
  std::stringstream summary;
  summary << json.rdbuf();
  EXPECT_TRUE(contains(summary.str(), "\"chosen\": 3")) << summary.str();
  const Table st = read_table(dir + "/stabilisation.csv");
  EXPECT_GE(st.data.rows(), 6);  // 1 + 2 + 3 modes found at least
  EXPECT_GT(read_table(dir + "/frf.csv").data.rows(), 100);
  const Outcome both = run("fit --config " + path("plant.yaml") + " --data " + path("d.csv") +
                           " --max-modes 5 --modes 2");
  EXPECT_EQ(both.code, 2) << both.output;
  EXPECT_TRUE(contains(both.output, "excludes")) << both.output;
}

TEST_F(CliThreeModes, DiagnoseWithModesOnlyStartsFromTheData) {
  const Outcome diag = run("diagnose --config " + path("plant.yaml") + " --data " + path("d.csv") + " --report " +
                           path("report"));
  ASSERT_EQ(diag.code, 0) << diag.output;
  EXPECT_TRUE(contains(diag.output, "initial modes from the data")) << diag.output;
  const Config model = load_config(path("report/model.yaml"));
  expect_three_modes(model.model);
}

// A positioning axis under position feedback (a rigid body with viscous
// friction, b0 / (p (1 + a1 p)), and a PID law): the loop's own resonance is
// the only peak of S_yr/S_ur. Fitted as a mode it makes the loop diverge
// (a mode of negative gain, fit -111 %); `fit --modes 1` says so and starts
// again from the non-resonant structure of least BIC, the rigid body with its
// lag, which comes back at the truth.
TEST_F(Cli, FitOfOneModeOverAClosedLoopPeakThatIsNoResonanceReturnsTheRigidBodyBehindIt) {
  const std::string body = "      kind: transfer_function\n      rigid_poles: 1\n      a: [0.467]\n      b: [0.1727]\n";
  std::ofstream(path("axis.yaml")) << "sample_rate_hz: 1000\n"
                                      "model:\n  loop: closed\n  modes: 1\n"
                                      "controller:\n  numerator: [160720.8, 0, -121725]\n  denominator: [1, 0, 0]\n"
                                      "plant:\n  snr_db: 60\n  modes:\n    - name: body\n"
                                   << body
                                   << "simulation:\n  duration: 25\n  seed: 3\n  reference:\n"
                                      "    type: sum_of_sines\n    amplitudes: [0.1, 0.02]\n"
                                      "    frequencies_hz: [0.1, 1.0]\n";
  const Outcome sim = run("simulate --config " + path("axis.yaml") + " --out " + path("d.csv"));
  ASSERT_EQ(sim.code, 0) << sim.output;
  const Outcome fit =
      run("fit --config " + path("axis.yaml") + " --data " + path("d.csv") + " --modes 1 --out " + path("fitted.yaml"));
  ASSERT_EQ(fit.code, 0) << fit.output;
  EXPECT_TRUE(contains(fit.output,
                       "fitted as a mode, makes the loop with the controller diverge: starting again from "
                       "a rigid body with a lag"))
      << fit.output;
  EXPECT_FALSE(contains(fit.output, "diverges on the record")) << fit.output;
  const Config fitted = load_config(path("fitted.yaml"));
  ASSERT_EQ(fitted.model.submodels.size(), 1u);
  const Submodel& s = fitted.model.submodels.front();
  EXPECT_EQ(s.rigid_poles, 1);
  ASSERT_EQ(s.n, 1);
  EXPECT_NEAR(s.a(0), 0.467, 0.01 * 0.467);
  EXPECT_NEAR(s.b(0), 0.1727, 0.01 * 0.1727);
}

// A mode at 0.33 fs: its sampled output is far from held. With no
// output_hold configured, a starting mode above a tenth of the sampling rate
// makes `fit` assume foh, the cycles converge, and both modes come out within
// 1 % and 20 %. The written model keeps the hold unset (the same rule then
// gives foh again).
TEST_F(Cli, FitWithoutAnOutputHoldFindsAModeAtAThirdOfTheSamplingRate) {
  const std::string plant =
      "sample_rate_hz: 100\n"
      "model:\n"
      "  modes: 2\n"
      "plant:\n"
      "  snr_db: 30\n"
      "  modes:\n"
      "    - {name: a, frequency_hz: 12, zeta: 0.03, gain: 0.06}\n"
      "    - {name: b, frequency_hz: 33, zeta: 0.05, gain: -0.1}\n"
      "simulation:\n"
      "  duration: 120\n"
      "  seed: 5\n"
      "  input: {type: prbs, register_bits: 14, clock_period: 1, amplitude: 1}\n";
  write("plant.yaml", plant);
  write("zoh.yaml", "model:\n  output_hold: zoh\n  modes: 2\nsample_rate_hz: 100\n");
  ASSERT_EQ(run("simulate --config " + path("plant.yaml") + " --out " + path("d.csv")).code, 0);
  const double hz[] = {12, 33}, zeta[] = {0.03, 0.05};

  const Outcome fit = run("fit --config " + path("plant.yaml") + " --data " + path("d.csv") + " --modes 2 --out " +
                          path("fitted.yaml"));
  ASSERT_EQ(fit.code, 0) << fit.output;
  EXPECT_TRUE(contains(fit.output, "output hold foh: a starting mode above 0.1 fs")) << fit.output;
  const Config fitted = load_config(path("fitted.yaml"));
  EXPECT_FALSE(fitted.output_hold.has_value());
  ASSERT_EQ(fitted.model.submodels.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    const ModalParameters p = modal_parameters(fitted.model.submodels[i]);
    EXPECT_NEAR(p.hz(), hz[i], 0.01 * hz[i]) << i;
    EXPECT_NEAR(p.zeta, zeta[i], 0.2 * zeta[i]) << i;
  }

  const Outcome zoh = run("fit --config " + path("zoh.yaml") + " --data " + path("d.csv") + " --modes 2 --out " +
                          path("fitted-zoh.yaml"));
  ASSERT_EQ(zoh.code, 0) << zoh.output;
  const Config held = load_config(path("fitted-zoh.yaml"));
  EXPECT_EQ(held.output_hold, Hold::zoh);
  ASSERT_EQ(held.model.submodels.size(), 2u);
  // Read as held, the 33 Hz mode's output has no fixed point of the SRIVC
  // cycles near the truth: they do not converge, and the fit returns the cycle
  // of least output error, which it says. Under foh the cycles converge.
  EXPECT_TRUE(contains(fit.output, "converged after")) << fit.output;
  EXPECT_FALSE(contains(fit.output, "NOT converged")) << fit.output;
  EXPECT_TRUE(contains(zoh.output, "NOT converged after")) << zoh.output;
  EXPECT_TRUE(contains(zoh.output, "the one of least output error")) << zoh.output;
}

// A configured mode far above the Nyquist frequency comes out as a named
// feedthrough, in the warning and in the written model, with either output
// hold (the default is foh here: m3 lies at 0.1 fs). It is one before the fit
// starts: under foh a fit would move it down onto m3.
TEST_F(CliThreeModes, FitWarnsOfAModeAboveNyquistAndWritesAFeedthrough) {
  for (const std::string hold : {"", "  output_hold: zoh\n"}) {
    std::ofstream(path("model.yaml")) << "sample_rate_hz: 100\n"
                                         "model:\n" +
                                             hold +
                                             "  submodels:\n"
                                             "    - {name: m1, frequency_hz: 3.1, zeta: 0.03, gain: 0.1}\n"
                                             "    - {name: m2, frequency_hz: 5.5, zeta: 0.05, gain: 0.2}\n"
                                             "    - {name: m3, frequency_hz: 10, zeta: 0.03, gain: -0.1}\n"
                                             "    - {name: fast, frequency_hz: 1.0e5, zeta: 0.1, gain: 0.01}\n";
    const Outcome fit =
        run("fit --config " + path("model.yaml") + " --data " + path("d.csv") + " --out " + path("fitted.yaml"));
    const std::string which = hold.empty() ? "default hold" : "zoh";
    ASSERT_EQ(fit.code, 0) << which << "\n" << fit.output;
    EXPECT_TRUE(contains(fit.output,
                         "WARNING: submodel fast is not a physical mode (feedthrough): its start: 1e+05 Hz "
                         "is above the Nyquist frequency 50 Hz"))
        << which << "\n"
        << fit.output;
    std::ifstream in(path("fitted.yaml"));
    std::stringstream text;
    text << in.rdbuf();
    EXPECT_TRUE(contains(text.str(), "kind: feedthrough")) << which << "\n" << text.str();
    const Config fitted = load_config(path("fitted.yaml"));
    ASSERT_EQ(fitted.model.submodels.size(), 4u) << which;
    EXPECT_TRUE(fitted.model.submodels[3].is_feedthrough()) << which;
    // The three modes are the record's (feedthrough aside).
    AdditiveModel modes = fitted.model;
    modes.submodels.pop_back();
    expect_three_modes(modes);
  }
}

TEST_F(Cli, RecordWithNaNIsRejectedNamingRowAndColumn) {
  expect_rejected(*this, "t,r,u,y\n" + good_rows(3) + "0.15,0.1,0.2,nan\n", "row 5", "'y'");
}

TEST_F(Cli, RecordWithNonNumericFieldIsRejectedNamingRowAndColumn) {
  expect_rejected(*this, "t,r,u,y\n0,0,0,0\n0.05,0,abc,0\n", "row 3", "'u'");
}

TEST_F(Cli, RecordWithMissingColumnIsRejectedNamingIt) {
  expect_rejected(*this, "t,r,y\n0,0,0\n0.05,0,0\n", "'u'", "missing");
}

// A measured record names its columns its own way: fit and diagnose read the
// ones --t-column, --u-column and --y-column name, and a missing one is named
// with the option that picks another.
TEST_F(Cli, FitAndDiagnoseReadTheNamedColumnsAndNameTheOptionForAMissingOne) {
  ASSERT_EQ(run("simulate --config " + config("paper-sim.yaml") + " --out " + path("d.csv") + " --duration 100").code,
            0);
  const Record r = read_record(path("d.csv"));
  Eigen::MatrixXd table(r.size(), 5);
  table << r.t, r.r, r.u, r.u, r.y;  // y1: a decoy, y2: the output
  write_table(path("run.csv"), {"time", "r", "u", "y1", "y2"}, table);

  const Outcome plain = run("fit --config " + config("paper-sim.yaml") + " --data " + path("d.csv") + " --to 90");
  ASSERT_EQ(plain.code, 0) << plain.output;
  const Outcome named = run("fit --config " + config("paper-sim.yaml") + " --data " + path("run.csv") +
                            " --to 90 --t-column time --y-column y2");
  ASSERT_EQ(named.code, 0) << named.output;
  EXPECT_EQ(named.output, plain.output);  // the same samples, the same fit

  const Outcome no_y = run("fit --config " + config("paper-sim.yaml") + " --data " + path("run.csv") +
                           " --t-column time");
  EXPECT_EQ(no_y.code, 2) << no_y.output;
  for (const char* s : {"run.csv", "missing column 'y'", "time, r, u, y1, y2", "pick one with --y-column"})
    EXPECT_TRUE(contains(no_y.output, s)) << s << "\n" << no_y.output;
  const Outcome no_t = run("diagnose --config " + config("paper-sim.yaml") + " --data " + path("run.csv") +
                           " --y-column y2 --report " + path("report"));
  EXPECT_EQ(no_t.code, 2) << no_t.output;
  for (const char* s : {"run.csv", "missing column 't'", "pick one with --t-column"})
    EXPECT_TRUE(contains(no_t.output, s)) << s << "\n" << no_t.output;
  const Outcome no_y_diagnose = run("diagnose --config " + config("paper-sim.yaml") + " --data " + path("d.csv") +
                                    " --validate " + path("run.csv") + " --report " + path("report"));
  EXPECT_EQ(no_y_diagnose.code, 2) << no_y_diagnose.output;
  EXPECT_TRUE(contains(no_y_diagnose.output, "run.csv: missing column 't'")) << no_y_diagnose.output;
  EXPECT_FALSE(fs::exists(path("report/report.md")));
  // The input column too: a record whose input is u1 (of a shaker pair, say).
  write_table(path("no_u.csv"), {"t", "r", "y"}, table.leftCols(3));
  const Outcome no_u = run("fit --config " + config("paper-sim.yaml") + " --data " + path("no_u.csv"));
  EXPECT_EQ(no_u.code, 2) << no_u.output;
  EXPECT_TRUE(contains(no_u.output, "missing column 'u'")) << no_u.output;
  EXPECT_TRUE(contains(no_u.output, "pick one with --u-column")) << no_u.output;
  write_table(path("u1.csv"), {"time", "r", "u1", "y1", "y2"}, table);
  const Outcome u1 = run("fit --config " + config("paper-sim.yaml") + " --data " + path("u1.csv") +
                         " --to 90 --t-column time --u-column u1 --y-column y2");
  ASSERT_EQ(u1.code, 0) << u1.output;
  EXPECT_EQ(u1.output, plain.output);
}

// A record without a sample rate: its time column n counts samples, the config
// says sample_rate_hz: 1 (modes in rad/sample). The report says so, and the
// plots' axes are in samples and cycles/sample, and so are the frequencies fit
// prints; a record in seconds keeps s and Hz.
TEST_F(Cli, FitAndDiagnoseOfASampleIndexRecordLabelTimeInSamples) {
  const std::string cfg = write("plant.yaml", R"(sample_rate_hz: 1
model:
  submodels:
    - {name: m1, kind: mode, wn: 0.053, zeta: 0.08, gain: 0.8}
plant:
  noise_variance: 1.0e-6
  modes:
    - {name: m1, kind: mode, wn: 0.05, zeta: 0.05, gain: 1}
simulation:
  duration: 3000
  input: {type: multisine, f_min_hz: 0.001, f_max_hz: 0.1, period_s: 1000, rms: 1}
)");
  ASSERT_EQ(run("simulate --config " + cfg + " --out " + path("t.csv")).code, 0);
  const Table t = read_table(path("t.csv"));
  write_table(path("n.csv"), {"n", "u", "y"}, t.data(Eigen::all, std::vector<int>{0, t.column("u"), t.column("y")}));
  const std::string script = test_support::source_file("scripts/plot/plot_diagnose.py");
  const bool plots = fs::exists("/usr/bin/python3") &&
                     std::system("/usr/bin/python3 -c 'import matplotlib, numpy' 2>/dev/null") == 0;
  auto labels = [&](const std::string& report) {
    const std::string cmd = "/usr/bin/python3 -c 'import sys; sys.path.insert(0, sys.argv[1]); import plot_diagnose; "
                            "print(\"|\".join(plot_diagnose.axis_labels(sys.argv[2])))' " +
                            fs::path(script).parent_path().string() + " " + report;
    FILE* pipe = popen(cmd.c_str(), "r");
    char line[256] = {};
    const bool read = pipe && std::fgets(line, sizeof line, pipe);
    if (pipe) pclose(pipe);
    return read ? std::string(line) : std::string();
  };
  for (const bool samples : {true, false}) {
    const Outcome f = run("fit --config " + cfg + " --data " + path(samples ? "n.csv" : "t.csv") +
                          (samples ? " --t-column n" : ""));
    ASSERT_EQ(f.code, 0) << f.output;
    EXPECT_EQ(contains(f.output, " Hz, open loop"), !samples) << f.output;
    EXPECT_EQ(contains(f.output, "f [1/sample]"), samples) << f.output;
    EXPECT_EQ(contains(f.output, "f [Hz]"), !samples) << f.output;
    const std::string report = path(samples ? "samples" : "seconds");
    const Outcome d = run("diagnose --config " + cfg + " --data " + path(samples ? "n.csv" : "t.csv") +
                          (samples ? " --t-column n" : "") + " --max-steps 0 --report " + report +
                          (plots ? " --plot-script " + script : ""));
    ASSERT_EQ(d.code, 0) << d.output;
    std::ifstream json(report + "/summary.json"), md(report + "/report.md");
    std::stringstream summary, markdown;
    summary << json.rdbuf();
    markdown << md.rdbuf();
    EXPECT_TRUE(contains(summary.str(), samples ? "\"time_unit\": \"samples\"" : "\"time_unit\": \"s\""))
        << summary.str();
    EXPECT_EQ(contains(markdown.str(), "`n` is a sample index (no sample rate)"), samples) << markdown.str();
    if (!plots) continue;  // the labels need the script's imports
    EXPECT_EQ(labels(report), samples ? "t [samples]|frequency [cycles/sample]\n" : "t [s]|frequency [Hz]\n");
    for (const char* png : {"bode.png", "validation.png", "residual_spectrum.png"})
      EXPECT_TRUE(fs::exists(report + "/" + png)) << png << "\n" << d.output;
  }
}

TEST_F(Cli, RecordWithNonIncreasingTimeIsRejectedNamingRow) {
  expect_rejected(*this, "t,r,u,y\n0,0,0,0\n0.05,0,0,0\n0.05,0,0,0\n", "row 4", "'t'");
}

TEST_F(Cli, RecordWithFewerSamplesThanParametersIsRejected) {
  expect_rejected(*this, "t,r,u,y\n" + good_rows(8), "8 samples", "9 parameters");
}

// Bad configurations: exit code 2, the key and its line.
void expect_config_rejected(const Cli& t, const std::string& from, const std::string& to, const std::string& key,
                            int line) {
  std::ifstream in(Cli::config("paper-sim.yaml"));
  std::stringstream ss;
  ss << in.rdbuf();
  std::string text = ss.str();
  const auto pos = text.find(from);
  ASSERT_NE(pos, std::string::npos) << from;
  text.replace(pos, from.size(), to);
  const std::string cfg = t.write("bad.yaml", text);
  const std::string out = t.path("sim.csv");
  const Outcome r = run("simulate --config " + cfg + " --out " + out);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_TRUE(contains(r.output, "key '" + key + "'")) << r.output;
  EXPECT_TRUE(contains(r.output, "bad.yaml:" + std::to_string(line) + ":")) << r.output;
  EXPECT_FALSE(fs::exists(out));
}

int line_of(const std::string& needle) {
  std::ifstream in(Cli::config("paper-sim.yaml"));
  std::string line;
  for (int n = 1; std::getline(in, line); ++n)
    if (line.find(needle) != std::string::npos) return n;
  return -1;
}

TEST_F(Cli, ConfigWithUnknownKeyNamesKeyAndLine) {
  const int line = line_of("sample_rate_hz");
  expect_config_rejected(*this, "sample_rate_hz:", "sample_rate_hz: 20\nsampel_rate:", "sampel_rate", line + 1);
}

TEST_F(Cli, ConfigWithWrongTypeNamesKeyAndLine) {
  expect_config_rejected(*this, "sample_rate_hz: 20", "sample_rate_hz: fast", "sample_rate_hz",
                         line_of("sample_rate_hz"));
}

TEST_F(Cli, ConfigWithForgettingOutsideUnitIntervalNamesKeyAndLine) {
  const int line = line_of("      forgetting: ");  // the first submodel's
  ASSERT_GT(line, 0);
  expect_config_rejected(*this, "forgetting: 0.999", "forgetting: 1.5", "model.submodels[0].forgetting", line);
}

TEST_F(Cli, ConfigWithNonPositiveFrequencyNamesKeyAndLine) {
  const int line = line_of("wn: 1.98625");
  ASSERT_GT(line, 0);
  expect_config_rejected(*this, "wn: 1.98625", "wn: -2", "model.submodels[0].wn", line);
}

TEST_F(Cli, UnknownOptionIsBadInput) {
  const Outcome r = run("fit --config x.yaml --data y.csv --bogus");
  EXPECT_EQ(r.code, 2) << r.output;
}

}  // namespace
}  // namespace modalwatch
