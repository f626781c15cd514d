// Several measured inputs (MISO): each submodel names the input that drives
// it. The configuration (model.inputs, a submodel's input), the record
// (the further input columns), the batch fit and the start from the data.
#include <cstdio>
#include <filesystem>
#include <limits>
#include <sstream>

#include "config_support.hpp"
#include "simulation_support.hpp"

#include "modalwatch/estimator.hpp"
#include "modalwatch/initial_modes.hpp"
#include "modalwatch/io/checkpoint.hpp"
#include "modalwatch/io/csv.hpp"
#include "modalwatch/io/records.hpp"
#include "modalwatch/model_order.hpp"
#include "modalwatch/physical.hpp"
#include "modalwatch/simulator.hpp"
#include "modalwatch/spectra.hpp"
#include "modalwatch/srivc.hpp"

namespace {

// ---------------------------------------------------------------- configuration

const std::string kTwoInputs =
    "sample_rate_hz: 20\n"       // 1
    "model:\n"                   // 2
    "  loop: open\n"             // 3
    "  inputs: [u1, u2]\n"       // 4
    "  submodels:\n"             // 5
    "    - name: m1\n"           // 6
    "      wn: 2.0\n"            // 7
    "      zeta: 0.25\n"         // 8
    "      gain: 3.0\n"          // 9
    "    - name: m2\n"           // 10
    "      input: u2\n"          // 11
    "      frequency_hz: 1.0\n"  // 12
    "      zeta: 0.1\n"          // 13
    "      gain: 1.0\n";         // 14

TEST(SeveralInputsConfig, InputsAreNamedAndEachSubmodelIndexesOne) {
  const Config c = parse_config(kTwoInputs, "test.yaml");
  EXPECT_EQ(c.model.inputs, (std::vector<std::string>{"u1", "u2"}));
  EXPECT_EQ(c.model.n_inputs(), 2);
  ASSERT_EQ(c.model.submodels.size(), 2u);
  EXPECT_EQ(c.model.submodels[0].input, 0);  // absent: the first input
  EXPECT_EQ(c.model.submodels[1].input, 1);
}

TEST(SeveralInputsConfig, SingleInputConfigHasNoInputNames) {
  const Config c = parse_config(kBase, "test.yaml");
  EXPECT_TRUE(c.model.inputs.empty());
  EXPECT_EQ(c.model.n_inputs(), 1);
  for (const auto& s : c.model.submodels) EXPECT_EQ(s.input, 0);
  // The written file has no input keys at all: as before several inputs existed.
  const std::string yaml = modalwatch::config_to_yaml(c, c.model);
  EXPECT_EQ(yaml.find("input"), std::string::npos) << yaml;
}

TEST(SeveralInputsConfig, RoundTripsThroughTheWriter) {
  const Config c = parse_config(kTwoInputs, "test.yaml");
  const std::string yaml = modalwatch::config_to_yaml(c, c.model);
  EXPECT_CONTAINS(yaml, "inputs: [\"u1\", \"u2\"]");
  Config back = parse_config(yaml, "test.yaml");
  back.source = c.source;
  EXPECT_TRUE(back == c) << yaml;
  EXPECT_EQ(back.model.submodels[1].input, 1);
}

TEST(SeveralInputsConfig, ErrorsNameTheKeyAndLine) {
  EXPECT_EQ(parse_error(edit(kTwoInputs, "      input: u2", "      input: u3")),
            "test.yaml:11: key 'model.submodels[1].input': must be one of model.inputs (u1, u2) (got u3)");
  EXPECT_EQ(parse_error(edit(kBase, "      frequency_hz: 1.0", "      input: u2\n      frequency_hz: 1.0")),
            "test.yaml:12: key 'model.submodels[1].input': names an input, but model.inputs does not list the "
            "input columns (got u2)");
  EXPECT_EQ(parse_error(edit(kTwoInputs, "  inputs: [u1, u2]", "  inputs: [u1, u1]")),
            "test.yaml:4: key 'model.inputs[1]': duplicate input name (got u1)");
  EXPECT_EQ(parse_error(edit(kTwoInputs, "  inputs: [u1, u2]", "  inputs: []")),
            "test.yaml:4: key 'model.inputs': must list at least one input column (got [])");
  EXPECT_EQ(parse_error(edit(kTwoInputs, "  inputs: [u1, u2]", "  inputs: u1")),
            "test.yaml:4: key 'model.inputs': expected a list (got u1)");
  const std::string closed =
      edit(kTwoInputs, "  loop: open", "  loop: closed") + "controller:\n  numerator: [1]\n  denominator: [1]\n";
  EXPECT_EQ(parse_error(closed),
            "test.yaml:4: key 'model.inputs': a closed loop has one input (the controller's u); "
            "several inputs need loop: open (got [u1, u2])");
}

// The same model, simulated: each plant mode on its input, one signal per input.
const std::string kTwoInputSimulation = kTwoInputs +
                                        "plant:\n"                    // 15
                                        "  noise_variance: 0.0001\n"  // 16
                                        "  modes:\n"                  // 17
                                        "    - name: m1\n"            // 18
                                        "      wn: 2.0\n"             // 19
                                        "      zeta: 0.25\n"          // 20
                                        "      gain: 3.0\n"           // 21
                                        "    - name: m2\n"            // 22
                                        "      input: u2\n"           // 23
                                        "      frequency_hz: 1.0\n"   // 24
                                        "      zeta: 0.1\n"           // 25
                                        "      gain: 1.0\n"           // 26
                                        "simulation:\n"               // 27
                                        "  duration: 400\n"           // 28
                                        "  seed: 3\n"                 // 29
                                        "  input:\n"                  // 30
                                        "    - type: prbs\n"          // 31
                                        "      register_bits: 10\n"   // 32
                                        "      clock_period: 1\n"     // 33
                                        "      amplitude: 1\n"        // 34
                                        "    - type: prbs\n"          // 35
                                        "      register_bits: 10\n"   // 36
                                        "      clock_period: 1\n"     // 37
                                        "      amplitude: 1\n";       // 38

TEST(SeveralInputsConfig, TheSimulationHasOneSignalPerInputAndEachPlantModeItsInput) {
  const Config c = parse_config(kTwoInputSimulation, "test.yaml");
  ASSERT_TRUE(c.plant && c.experiment);
  EXPECT_EQ(c.plant->modes[0].submodel.input, 0);
  EXPECT_EQ(c.plant->modes[1].submodel.input, 1);
  ASSERT_EQ(c.experiment->further_excitations.size(), 1u);
  // Two PRBS of one kind are two shifted copies (by half the 1023-step period
  // here), and input j's random signals take the record's seed + j.
  EXPECT_EQ(c.experiment->excitation.prbs_shift, 0);
  EXPECT_EQ(c.experiment->further_excitations[0].prbs_shift, 511);
  EXPECT_EQ(c.experiment->excitation.seed, 3u);
  EXPECT_EQ(c.experiment->further_excitations[0].seed, 4u);
  const std::string yaml = modalwatch::config_to_yaml(c, c.model);
  Config back = parse_config(yaml, "test.yaml");
  back.source = c.source;
  EXPECT_TRUE(back == c) << yaml;
}

TEST(SeveralInputsConfig, ASimulationWithoutASignalPerInputIsNamed) {
  const std::string head = kTwoInputSimulation.substr(0, kTwoInputSimulation.find("    - type: prbs"));
  const std::string one_signal =
      head + "    type: prbs\n    register_bits: 10\n    clock_period: 1\n    amplitude: 1\n";
  EXPECT_EQ(parse_error(one_signal),
            "test.yaml:30: key 'simulation.input': model.inputs names 2 inputs: give a list of 2 signals, one per "
            "input in that order");
  const std::string three = kTwoInputSimulation + "    - type: square\n      frequency_hz: 0.5\n";
  EXPECT_EQ(parse_error(three), "test.yaml:30: key 'simulation.input': lists 3 signals; model.inputs names 2 inputs");
  EXPECT_EQ(parse_error(edit(kTwoInputSimulation,
                             "      input: u2\n      frequency_hz: 1.0\n      zeta: 0.1\n"
                             "      gain: 1.0\nsimulation",
                             "      input: u3\n      frequency_hz: 1.0\n      zeta: 0.1\n      gain: 1.0\nsimulation")),
            "test.yaml:23: key 'plant.modes[1].input': must be one of model.inputs (u1, u2) (got u3)");
}

// ---------------------------------------------------------------- record

class SeveralInputsRecord : public modalwatch::test_support::ScratchDir {
 protected:
  std::string file(const std::string& name, const std::string& text) { return write(name, text); }
};

TEST_F(SeveralInputsRecord, ReadsEveryNamedInputColumnAndSegmentKeepsThem) {
  modalwatch::RecordColumns cols;
  cols.u = "u1";
  cols.y = "y5";
  cols.further_u = {"u2"};
  const auto rec = modalwatch::read_record({file("m.csv", "t,u1,u2,y5\n0,1,10,5\n1,2,20,6\n2,3,30,7\n"), cols});
  ASSERT_EQ(rec.inputs(), 2);
  EXPECT_EQ(rec.u, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(rec.input(1), Eigen::Vector3d(10, 20, 30));
  EXPECT_EQ(rec.y(2), 7.0);
  const modalwatch::Record part = rec.segment(1, 2);
  ASSERT_EQ(part.inputs(), 2);
  EXPECT_EQ(part.input(1), Eigen::Vector2d(20, 30));
  EXPECT_EQ(part.input(0), Eigen::Vector2d(2, 3));
}

TEST_F(SeveralInputsRecord, AMissingInputColumnIsNamed) {
  modalwatch::RecordColumns cols;
  cols.further_u = {"u2"};
  try {
    modalwatch::read_record({file("m.csv", "t,u,y\n0,1,5\n1,2,6\n"), cols});
    FAIL() << "no error";
  } catch (const modalwatch::MissingColumnError& e) {
    EXPECT_EQ(e.column(), "u2");
  }
}

TEST_F(SeveralInputsRecord, OneInputByDefault) {
  const auto rec = modalwatch::read_record({file("s.csv", "t,u,y,u2\n0,1,5,9\n1,2,6,9\n")});
  EXPECT_EQ(rec.inputs(), 1);
  EXPECT_TRUE(rec.further_u.empty());
}

// ---------------------------------------------------------------- two-input plant

using modalwatch::AdditiveModel;
using modalwatch::ModalParameters;
using modalwatch::PlantSpec;
using modalwatch::Record;

constexpr double kT = 0.01;  // 100 Hz

// Three modes seen from two shakers: 3 Hz from both (residues of opposite
// sign), 11 Hz from the first only, 7 Hz from the second only.
struct Truth {
  std::string name;
  int input;
  ModalParameters modal;
};
const std::vector<Truth> kTruth = {
    {"a1", 0, {kTwoPi * 3.0, 0.05, 1.0}},
    {"a2", 1, {kTwoPi * 3.0, 0.05, -0.6}},
    {"b1", 0, {kTwoPi * 11.0, 0.03, 0.5}},
    {"c2", 1, {kTwoPi * 7.0, 0.04, 0.8}},
};

PlantSpec plant_of(const std::vector<Truth>& truth) {
  PlantSpec p;
  for (const Truth& t : truth) {
    modalwatch::PlantMode pm;
    pm.modal = t.modal;
    pm.submodel = modalwatch::make_mode(t.name, t.modal);
    pm.submodel.input = t.input;
    p.modes.push_back(pm);
  }
  p.snr_db = 30.0;
  return p;
}

// u1 a PRBS, u2 white Gaussian plus `coupling` times u1 (two shakers on one
// structure see each other: their inputs correlate).
Record two_input_record(const std::vector<Truth>& truth, double coupling, std::uint64_t seed = 3,
                        double duration = 120.0) {
  modalwatch::ExperimentSpec e = modalwatch::test_support::open_loop_prbs(kT, duration, seed);
  const Eigen::Index n = std::llround(e.duration / e.sample_time);
  const Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(n, 0.0, static_cast<double>(n - 1)) * kT;
  const Eigen::VectorXd u1 = modalwatch::generate(e.excitation, t);
  e.further_input_samples = {modalwatch::test_support::white_noise(n, seed + 100) + coupling * u1};
  return modalwatch::simulate(plant_of(truth), e).record;
}
Record two_input_record(double coupling, std::uint64_t seed = 3) { return two_input_record(kTruth, coupling, seed); }

// The fitted submodel of each true one (same name), within 1 % in wn, 10 % in
// zeta and 5 % in gain, on the same input.
void expect_truth(const AdditiveModel& fitted, const std::vector<std::string>& names) {
  ASSERT_EQ(fitted.submodels.size(), kTruth.size());
  for (std::size_t i = 0; i < kTruth.size(); ++i) {
    const Truth& t = kTruth[i];
    const auto& s = fitted.submodels[i];
    SCOPED_TRACE(names[i]);
    EXPECT_EQ(s.input, t.input);
    ASSERT_TRUE(s.is_mode());
    const ModalParameters p = modalwatch::modal_parameters(s);
    EXPECT_NEAR(p.wn / t.modal.wn, 1.0, 0.01);
    EXPECT_NEAR(p.zeta / t.modal.zeta, 1.0, 0.10);
    EXPECT_NEAR(p.gain / t.modal.gain, 1.0, 0.05);
  }
}

// The true submodels started 10 % off in frequency, damping and gain.
AdditiveModel start_off_the_truth() {
  AdditiveModel start;
  start.inputs = {"u1", "u2"};
  for (const Truth& t : kTruth) {
    ModalParameters p = t.modal;
    p.wn *= 1.1;
    p.zeta *= 0.8;
    p.gain *= 1.1;
    start.submodels.push_back(modalwatch::make_mode(t.name, p));
    start.submodels.back().input = t.input;
  }
  return start;
}

TEST(SeveralInputsFit, EachSubmodelIsFittedFromItsOwnInput) {
  const Record data = two_input_record(0.0);
  ASSERT_EQ(data.inputs(), 2);
  AdditiveModel start = start_off_the_truth();
  const modalwatch::FitResult fit = modalwatch::fit_srivc(data, start, {});
  EXPECT_TRUE(fit.converged);
  EXPECT_EQ(fit.model.inputs, start.inputs);
  expect_truth(fit.model, {"a1", "a2", "b1", "c2"});
  // 30 dB: the output error is the noise, 1 - 10^(-30/20) of the output.
  EXPECT_GT(fit.fit_percent, 95.0);
  EXPECT_NEAR((fit.simulated - modalwatch::simulate_model(fit.model, data)).norm(), 0.0, 1e-9 * fit.simulated.norm());
}

// a1 and a2 are one resonance seen from two shakers: with a2.poles_of = a1 the
// fit estimates one A from both inputs, and its frequency is better determined
// than either submodel's alone.
TEST(SeveralInputsFit, OneResonanceOnTwoInputsSharesItsPolesAndIsBetterDetermined) {
  const Record data = two_input_record(0.0);
  AdditiveModel start = start_off_the_truth();
  const modalwatch::FitResult own = modalwatch::fit_srivc(data, start, {});
  start.submodels[1].a(0) *= 1.05;  // a member starts from its leader's A, whatever it holds
  start.submodels[1].poles_of = "a1";
  const modalwatch::FitResult shared = modalwatch::fit_srivc(data, start, {});
  EXPECT_TRUE(shared.converged);
  expect_truth(shared.model, {"a1", "a2", "b1", "c2"});
  EXPECT_EQ(shared.model.submodels[1].poles_of, "a1");
  EXPECT_EQ(shared.model.submodels[0].a, shared.model.submodels[1].a);
  // One A: the members' (a1, a2) covariances are one block, repeated.
  const Eigen::MatrixXd c0 = shared.theta_covariance(0), c1 = shared.theta_covariance(1);
  EXPECT_LT((c0.topLeftCorner(2, 2) - c1.topLeftCorner(2, 2)).norm(), 1e-12 * c0.topLeftCorner(2, 2).norm());
  const double wn_std_shared = modalwatch::modal_std(shared.model.submodels[0], c0).wn;
  const double wn_std_own = std::min(modalwatch::modal_std(own.model.submodels[0], own.theta_covariance(0)).wn,
                                     modalwatch::modal_std(own.model.submodels[1], own.theta_covariance(1)).wn);
  std::printf("3 Hz resonance on two inputs: wn std %.3g rad/s shared, %.3g on the better input alone\n", wn_std_shared,
              wn_std_own);
  EXPECT_LT(wn_std_shared, wn_std_own);
  // The shared A counts once in the noise variance's degrees of freedom: the
  // same residual as the two separate fits' to within the noise.
  EXPECT_NEAR(shared.fit_percent, own.fit_percent, 0.5);
}

TEST(SeveralInputsConfig, PolesOfNamesTheSubmodelWhoseAItShares) {
  const std::string shared = edit(kTwoInputs, "      input: u2\n", "      input: u2\n      poles_of: m1\n");
  const Config c = parse_config(shared, "test.yaml");
  EXPECT_EQ(c.model.submodels[1].poles_of, "m1");
  EXPECT_EQ(modalwatch::pole_groups(c.model), (std::vector<std::vector<int>>{{0, 1}}));
  const std::string yaml = modalwatch::config_to_yaml(c, c.model);
  EXPECT_CONTAINS(yaml, "poles_of: \"m1\"");
  Config back = parse_config(yaml, "test.yaml");
  back.source = c.source;
  EXPECT_TRUE(back == c) << yaml;
  EXPECT_EQ(parse_error(edit(shared, "poles_of: m1", "poles_of: m3")),
            "test.yaml:12: key 'model.submodels[1].poles_of': m2: poles_of names m3, which is no submodel of the "
            "model (got m3)");
  EXPECT_EQ(parse_error(edit(shared, "      input: u2\n", "")),
            "test.yaml:11: key 'model.submodels[1].poles_of': m2: shares the poles of m1 on the same input as m1; "
            "one resonance has one submodel per input (got m1)");
}

TEST(SeveralInputsFit, OneInputModelOfATwoInputRecordLeavesTheSecondAsNoise) {
  const Record data = two_input_record(0.0);
  AdditiveModel start;
  for (const Truth& t : kTruth)
    if (t.input == 0) start.submodels.push_back(modalwatch::make_mode(t.name, t.modal));
  const modalwatch::FitResult fit = modalwatch::fit_srivc(data, start, {});
  EXPECT_LT(fit.fit_percent, 80.0);  // u2's response is unexplained
}

TEST(SeveralInputsFit, RefusesAnInputTheRecordLacksAndSeveralInputsInClosedLoop) {
  Record data = two_input_record(0.0);
  AdditiveModel start;
  start.submodels.push_back(modalwatch::make_mode("m", kTruth[0].modal));
  start.submodels.back().input = 2;
  EXPECT_THROW(modalwatch::fit_srivc(data, start, {}), std::invalid_argument);
  start.submodels.back().input = 0;
  start.submodels.push_back(modalwatch::make_mode("n", kTruth[3].modal));
  start.submodels.back().input = 1;
  modalwatch::SrivcOptions closed;
  closed.closed_loop = true;
  closed.controller = modalwatch::DiscreteTransferFunction({0.1}, {1.0});
  data.r = data.u;
  try {
    modalwatch::fit_srivc(data, start, closed);
    FAIL() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_CONTAINS(std::string(e.what()), "open loop only");
  }
}

// ---------------------------------------------------------------- start from the data

// Without a starting guess: the peaks of |H| = sqrt(|H_1|^2 + |H_2|^2) give
// 3, 7 and 11 Hz; each becomes one submodel per input, and the fit keeps the
// true ones and sends the others (7 Hz from u1, 11 Hz from u2) to small gains.
void expect_from_data(double coupling) {
  const Record data = two_input_record(coupling);
  const modalwatch::FrequencyResponse h = modalwatch::frequency_response(data, false);
  ASSERT_EQ(h.inputs(), 2);
  const AdditiveModel start = modalwatch::initial_modes(h, 3, {}, {"u1", "u2"});
  ASSERT_EQ(start.submodels.size(), 6u);
  EXPECT_EQ(start.inputs, (std::vector<std::string>{"u1", "u2"}));
  const double peaks_hz[] = {3.0, 7.0, 11.0};
  for (std::size_t i = 0; i < 6; ++i) {
    const auto& s = start.submodels[i];
    EXPECT_EQ(s.input, static_cast<int>(i % 2));
    EXPECT_EQ(s.name, "mode" + std::to_string(i / 2 + 1) + (i % 2 ? "_u2" : "_u1"));
    EXPECT_NEAR(modalwatch::modal_parameters(s).hz(), peaks_hz[i / 2], 0.2);  // within a bin or two
  }
  const modalwatch::FitResult fit = modalwatch::fit_srivc(data, start, {});
  // The true submodels: mode1_u1, mode1_u2, mode3_u1 (11 Hz), mode2_u2 (7 Hz).
  AdditiveModel found;
  for (const char* name : {"mode1_u1", "mode1_u2", "mode3_u1", "mode2_u2"})
    for (const auto& s : fit.model.submodels)
      if (s.name == name) found.submodels.push_back(s);
  expect_truth(found, {"mode1_u1", "mode1_u2", "mode3_u1", "mode2_u2"});
  // The two that are not there: gains below 2 % of the smallest true one.
  for (const char* name : {"mode2_u1", "mode3_u2"})
    for (const auto& s : fit.model.submodels)
      if (s.name == name) {
        EXPECT_LT(std::abs(modalwatch::modal_parameters(s).gain), 0.02 * 0.5) << name;
      }
  EXPECT_GT(fit.fit_percent, 95.0);
}

TEST(SeveralInputsStart, IndependentInputsFromTheDataAlone) { expect_from_data(0.0); }

// u2 = n + 0.7 u1: H1 of each input alone would mix the other's response in;
// the cross-spectral matrix separates them.
TEST(SeveralInputsStart, CorrelatedInputsFromTheDataAlone) { expect_from_data(0.7); }

TEST(SeveralInputsStart, PerInputResponseIsTheTruth) {
  const Record data = two_input_record(0.7);
  const modalwatch::FrequencyResponse h = modalwatch::frequency_response(data, false);
  AdditiveModel on1, on2;
  for (const Truth& t : kTruth) (t.input == 0 ? on1 : on2).submodels.push_back(modalwatch::make_mode(t.name, t.modal));
  // Over the band of the modes, H_j follows G_j: the RMS of the error is below
  // 10 % of G_j's RMS (bin by bin the estimate scatters at the peaks, where
  // K = 10 averaged segments leave a few percent of the other input's
  // response). S_yu1 / S_u1u1 alone takes in 0.7 G_2: an error of tens of percent.
  const modalwatch::Spectra single = modalwatch::welch_spectra(data.y, data.u, kT, 2048);
  double g1 = 0.0, g2 = 0.0, e1 = 0.0, e2 = 0.0, e_single = 0.0;
  for (Eigen::Index k = 1; k < h.frequency_hz.size(); ++k) {
    const double f = h.frequency_hz(k);
    if (f < 0.5 || f > 20.0) continue;
    const double w = kTwoPi * f;
    g1 += std::norm(on1.response(w));
    g2 += std::norm(on2.response(w));
    e1 += std::norm(h.response(k) - on1.response(w));
    e2 += std::norm(h.further_responses[0](k) - on2.response(w));
    const std::complex<double> advance = std::polar(1.0, 0.5 * w * kT);  // the held input's half sample
    e_single += std::norm(single.cross(k) * advance - on1.response(w));
  }
  EXPECT_LT(std::sqrt(e1 / g1), 0.10);
  EXPECT_LT(std::sqrt(e2 / g2), 0.10);
  EXPECT_GT(std::sqrt(e_single / g1), 0.3);
}

// ---------------------------------------------------------------- the recursive estimator

// A config for the recursive estimator of `truth` on the inputs u1, u2, each
// mode's start `off` (relative) from the truth in frequency, damping and gain,
// a 10 s memory (lambda 0.999 at 100 Hz) and a 20 s warm-up fitted by the
// additive SRIVC from both inputs.
std::string recursive_config(const std::vector<Truth>& truth, double off) {
  std::ostringstream y;
  y.precision(17);
  y << "sample_rate_hz: 100\nmodel:\n  inputs: [u1, u2]\n  submodels:\n";
  for (const Truth& t : truth) {
    y << "    - name: " << t.name << "\n"
      << "      input: " << (t.input == 0 ? "u1" : "u2") << "\n"
      << "      wn: " << t.modal.wn * (1.0 + off) << "\n"
      << "      zeta: " << t.modal.zeta * (1.0 - off) << "\n"
      << "      gain: " << t.modal.gain * (1.0 + off) << "\n"
      << "      forgetting: 0.999\n";
  }
  y << "estimator:\n  warmup: 20\n";
  return y.str();
}

// The estimator over the record, sample by sample as `track` gives them, and
// what each submodel's estimate did over the second half (after the warm-up
// and five memories): its wn's mean, its RMS error against the truth, and
// the standard deviation the estimator reported for it (mean over the half).
struct TrackedMode {
  double wn_mean = 0.0, wn_rms_error = 0.0, wn_std = 0.0, gain_mean = 0.0;
};
struct Tracked {
  std::vector<TrackedMode> modes;
  modalwatch::EstimatorStatus status;
};

Tracked track_two_inputs(const Config& c, const Record& r, const std::vector<Truth>& truth) {
  modalwatch::RecursiveEstimator est(c.model, c.estimator);
  Tracked out;
  out.modes.resize(truth.size());
  modalwatch::Sample s;
  s.further_inputs = r.inputs() - 1;
  Eigen::Index counted = 0;
  for (Eigen::Index k = 0; k < r.size(); ++k) {
    s.t = r.t(k);
    s.u = r.u(k);
    s.y = r.y(k);
    for (int j = 1; j < r.inputs(); ++j) s.further_u[static_cast<std::size_t>(j - 1)] = r.input(j)(k);
    est.step(s);
    if (2 * k < r.size()) continue;
    ++counted;
    for (std::size_t i = 0; i < truth.size(); ++i) {
      const modalwatch::ModeEstimate m = est.mode(static_cast<int>(i));
      TrackedMode& o = out.modes[i];
      o.wn_mean += m.value.wn;
      o.wn_rms_error += (m.value.wn - truth[i].modal.wn) * (m.value.wn - truth[i].modal.wn);
      o.wn_std += m.std.wn;
      o.gain_mean += m.value.gain;
    }
  }
  for (TrackedMode& o : out.modes) {
    o.wn_mean /= static_cast<double>(counted);
    o.wn_rms_error = std::sqrt(o.wn_rms_error / static_cast<double>(counted));
    o.wn_std /= static_cast<double>(counted);
    o.gain_mean /= static_cast<double>(counted);
  }
  out.status = est.status();
  return out;
}

// Each submodel's wn over the second half against the standard deviation the
// estimator reports for it (sigma^2 P: the 30 dB output noise seen through
// that submodel's own input over its 10 s memory): its RMS error and the
// error of its mean within 1.5 of them (a block on the wrong input is biased
// by far more: it sees the other input's response, or none), and the mean
// within 0.1 % of the truth (the start was 10 % off); the gain's mean within
// 1 %, its sign that of the input's residue. Measured: RMS errors 0.54 to
// 0.80 std, means within 0.55 std and 0.009 %.
void expect_tracks(const Tracked& tracked, const std::vector<Truth>& truth) {
  ASSERT_EQ(tracked.modes.size(), truth.size());
  EXPECT_TRUE(tracked.status.warmup_fit_used) << "the warm-up fit from both inputs was refused";
  EXPECT_EQ(tracked.status.resets, 0u);
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const TrackedMode& m = tracked.modes[i];
    const Truth& t = truth[i];
    std::printf(
        "  %s on u%d: wn %.6g (truth %.6g, %+.4f %%), RMS error %.3g, reported std %.3g (%.2f std); "
        "gain %.4g (truth %.4g)\n",
        t.name.c_str(), t.input + 1, m.wn_mean, t.modal.wn, 100.0 * (m.wn_mean / t.modal.wn - 1.0), m.wn_rms_error,
        m.wn_std, m.wn_rms_error / m.wn_std, m.gain_mean, t.modal.gain);
    SCOPED_TRACE(t.name);
    EXPECT_LT(m.wn_rms_error, 1.5 * m.wn_std);
    EXPECT_LT(std::abs(m.wn_mean - t.modal.wn), 1.5 * m.wn_std);
    EXPECT_NEAR(m.wn_mean / t.modal.wn, 1.0, 0.001);
    EXPECT_NEAR(m.gain_mean / t.modal.gain, 1.0, 0.01);
  }
}

// Two modes, each driven by its own independent input: 3 Hz by u1 (a PRBS),
// 7 Hz by u2 (white noise).
TEST(SeveralInputsRecursive, TwoModesEachOnItsOwnInputAreTrackedFromTheirOwnInputs) {
  const std::vector<Truth> truth = {kTruth[0], kTruth[3]};
  const Config c = parse_config(recursive_config(truth, 0.1), "two.yaml");
  const Record r = two_input_record(truth, 0.0, 5);
  expect_tracks(track_two_inputs(c, r, truth), truth);
}

// The four submodels of kTruth: the 3 Hz mode from both inputs (residues of
// opposite sign), 11 Hz from u1 only, 7 Hz from u2 only; the inputs correlate
// (u2 = n + 0.5 u1), so a block that took the other input would see part of
// the right response and be biased, not merely noisy.
TEST(SeveralInputsRecursive, AModeOnBothInputsAndOneOnEachAreTrackedWithCorrelatedInputs) {
  const Config c = parse_config(recursive_config(kTruth, 0.1), "four.yaml");
  const Record r = two_input_record(kTruth, 0.5, 7);
  expect_tracks(track_two_inputs(c, r, kTruth), kTruth);
}

// A model of two inputs whose only mode input 2 drives: u1 is in every sample
// and drives nothing. The block must take u2.
TEST(SeveralInputsRecursive, AModeDrivenByTheSecondInputOnlyIsTrackedFromIt) {
  const std::vector<Truth> truth = {kTruth[3]};
  const Config c = parse_config(recursive_config(truth, 0.1), "second.yaml");
  const Record r = two_input_record(truth, 0.0, 9);
  expect_tracks(track_two_inputs(c, r, truth), truth);
}

// A two-input estimator's state goes through the daemon's checkpoint exactly,
// and restores into an estimator of the same config, which goes on with each
// submodel on its own input (the state carries the estimate; which input
// drives which submodel is the config's, and is in the checkpoint's
// fingerprint, which a single-input model's leaves as it is).
TEST(SeveralInputsRecursive, StateRoundTripsThroughACheckpointAndRestoresWithTheInputs) {
  const Config c = parse_config(recursive_config(kTruth, 0.1), "four.yaml");
  const Record r = two_input_record(kTruth, 0.0, 7);
  const auto sample = [&](Eigen::Index k) {
    modalwatch::Sample s;
    s.t = r.t(k);
    s.u = r.u(k);
    s.y = r.y(k);
    s.further_inputs = 1;
    s.further_u[0] = r.input(1)(k);
    return s;
  };
  const Eigen::Index half = r.size() / 2;
  modalwatch::RecursiveEstimator first(c.model, c.estimator), whole(c.model, c.estimator);
  for (Eigen::Index k = 0; k < half; ++k) {
    first.step(sample(k));
    whole.step(sample(k));
  }
  modalwatch::Checkpoint written;
  written.config_fingerprint = modalwatch::checkpoint_fingerprint(c);
  written.estimator = first.state();
  written.baselines.assign(kTruth.size(), std::nullopt);
  const auto bytes = modalwatch::encode_checkpoint(written);
  const modalwatch::Checkpoint read = modalwatch::decode_checkpoint(bytes, "mem");
  EXPECT_EQ(read.estimator, written.estimator);
  EXPECT_EQ(modalwatch::encode_checkpoint(read), bytes);
  modalwatch::RecursiveEstimator resumed(c.model, c.estimator);
  resumed.restore(read.estimator);
  EXPECT_EQ(resumed.model().inputs, c.model.inputs);
  for (std::size_t i = 0; i < kTruth.size(); ++i) EXPECT_EQ(resumed.model().submodels[i].input, kTruth[i].input);
  // The resumed estimator restarts its prefilters as after a gap: the one that
  // ran on follows the same samples after one, to the restart's transient.
  whole.step(sample(half));
  modalwatch::Sample later = sample(half + 1);
  later.t += 1.0;
  whole.step(later);
  resumed.step(later);
  for (Eigen::Index k = half + 2; k < r.size(); ++k) {
    modalwatch::Sample s = sample(k);
    s.t += 1.0;
    whole.step(s);
    resumed.step(s);
  }
  for (std::size_t i = 0; i < kTruth.size(); ++i) {
    SCOPED_TRACE(kTruth[i].name);
    EXPECT_NEAR(resumed.mode(static_cast<int>(i)).value.wn / kTruth[i].modal.wn, 1.0, 0.01);
    EXPECT_NEAR(resumed.mode(static_cast<int>(i)).value.wn / whole.mode(static_cast<int>(i)).value.wn, 1.0, 0.002);
  }
  // The fingerprint: which input drives a submodel is part of it.
  Config swapped = c;
  swapped.model.submodels[0].input = 1;
  EXPECT_NE(modalwatch::checkpoint_fingerprint(swapped), modalwatch::checkpoint_fingerprint(c));
  // A single-input model's fingerprint has no input in it: the paper's config
  // keeps the one its checkpoints were written with.
  const Config paper = modalwatch::load_config(modalwatch::test_support::source_file("config/paper-sim.yaml"));
  EXPECT_EQ(modalwatch::checkpoint_fingerprint(paper), 0xd912ba8a93c4fd0dull);
}

// A sample whose further input is NaN, or that carries fewer inputs than the
// model has, is a non-finite sample: counted, no update on it, the filters
// restart after it as after a NaN in u.
TEST(SeveralInputsRecursive, ANonFiniteOrMissingFurtherInputIsANonFiniteSample) {
  const Config c = parse_config(recursive_config(kTruth, 0.1), "four.yaml");
  const Record r = two_input_record(kTruth, 0.0, 7);
  modalwatch::RecursiveEstimator est(c.model, c.estimator);
  modalwatch::Sample s;
  s.further_inputs = 1;
  std::uint64_t nonfinite = 0;
  for (Eigen::Index k = 0; k < r.size(); ++k) {
    s.t = r.t(k);
    s.u = r.u(k);
    s.y = r.y(k);
    s.further_u[0] = r.input(1)(k);
    s.further_inputs = 1;
    if (k == 5000) s.further_u[0] = std::numeric_limits<double>::quiet_NaN();
    if (k == 7000) s.further_inputs = 0;
    const unsigned flags = est.step(s);
    if (flags & modalwatch::kRejectedNonFinite) {
      ++nonfinite;
      EXPECT_FALSE(flags & modalwatch::kUpdated) << k;
      EXPECT_TRUE(k == 5000 || k == 7000) << k;
    }
  }
  EXPECT_EQ(nonfinite, 2u);
  EXPECT_EQ(est.status().rejected_nonfinite, 2u);
  EXPECT_EQ(est.status().resets, 0u);
  for (std::size_t i = 0; i < kTruth.size(); ++i)
    EXPECT_NEAR(est.mode(static_cast<int>(i)).value.wn / kTruth[i].modal.wn, 1.0, 0.01) << kTruth[i].name;
}

// More inputs than a sample carries: a clear error, at the config (naming the
// key and line) and at the estimator.
TEST(SeveralInputsRecursive, MoreInputsThanASampleCarriesAreRefused) {
  std::string names = "[u1";
  for (int j = 2; j <= modalwatch::kMaxInputs + 1; ++j) names += ", u" + std::to_string(j);
  names += "]";
  EXPECT_EQ(parse_error(edit(kTwoInputs, "  inputs: [u1, u2]", "  inputs: " + names)),
            "test.yaml:4: key 'model.inputs': at most 8 inputs (what a sample of track and the daemon carries) (got " +
                names + ")");
  AdditiveModel m;
  for (int j = 0; j <= modalwatch::kMaxInputs; ++j) m.inputs.push_back("u" + std::to_string(j + 1));
  m.submodels.push_back(modalwatch::make_mode("m", kTruth[0].modal));
  modalwatch::EstimatorSettings s;
  s.sample_time = kT;
  try {
    modalwatch::RecursiveEstimator est(m, s);
    FAIL() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_CONTAINS(std::string(e.what()), "model.inputs names 9 inputs, at most 8");
  }
}

// ---------------------------------------------------------------- command line

class SeveralInputsCli : public modalwatch::test_support::ScratchDir {
 protected:
  static bool contains(const std::string& text, const std::string& what) {
    return text.find(what) != std::string::npos;
  }
  // The two-input record with its own column names: shakers f_a, f_b, output acc.
  std::string record() const {
    const Record r = two_input_record(0.0);
    Eigen::MatrixXd table(r.size(), 4);
    table << r.t, r.u, r.input(1), r.y;
    modalwatch::write_table(path("shakers.csv"), {"t", "f_a", "f_b", "acc"}, table);
    return path("shakers.csv");
  }
};

// model.inputs names the record's input columns; `modes: 3` starts from the
// data, one submodel per input and resonance, and the table names each input.
TEST_F(SeveralInputsCli, FitNamesTheInputsInTheConfigAndWritesThemBack) {
  const std::string data = record();
  const std::string cfg = write("two.yaml", "sample_rate_hz: 100\nmodel:\n  inputs: [f_a, f_b]\n  modes: 3\n");
  const auto fit = modalwatch::test_support::run_cli("fit --config " + cfg + " --data " + data +
                                                     " --y-column acc --out " + path("fitted.yaml"));
  ASSERT_EQ(fit.code, 0) << fit.output;
  for (const char* s : {"peaks of |H|, H = S_yu S_uu^-1", "each mode is one submodel per input (2 inputs)", "  input",
                        "mode1_f_a", "mode1_f_b", "mode3_f_b"})
    EXPECT_TRUE(contains(fit.output, s)) << s << "\n" << fit.output;
  const Config fitted = modalwatch::load_config(path("fitted.yaml"));
  EXPECT_EQ(fitted.model.inputs, (std::vector<std::string>{"f_a", "f_b"}));
  ASSERT_EQ(fitted.model.submodels.size(), 6u);
  for (std::size_t i = 0; i < 6; ++i) EXPECT_EQ(fitted.model.submodels[i].input, static_cast<int>(i % 2));
  // The 11 Hz mode from f_a as the fit found it, and the written model seeds the next fit.
  EXPECT_NEAR(modalwatch::modal_parameters(fitted.model.submodels[4]).wn / kTruth[2].modal.wn, 1.0, 0.01);
  const auto again =
      modalwatch::test_support::run_cli("fit --config " + path("fitted.yaml") + " --data " + data + " --y-column acc");
  ASSERT_EQ(again.code, 0) << again.output;
  EXPECT_TRUE(contains(again.output, "6 submodels")) << again.output;
}

// --u-column, repeated, names the inputs without model.inputs; a missing one is
// named with the option, a closed loop refuses several.
TEST_F(SeveralInputsCli, RepeatedUColumnNamesTheInputs) {
  const std::string data = record();
  const std::string cfg = write("modes.yaml", "sample_rate_hz: 100\nmodel:\n  modes: 3\n");
  const auto fit = modalwatch::test_support::run_cli("fit --config " + cfg + " --data " + data +
                                                     " --u-column f_a --u-column f_b --y-column acc");
  ASSERT_EQ(fit.code, 0) << fit.output;
  EXPECT_TRUE(contains(fit.output, "mode2_f_b")) << fit.output;
  // Three resonances, each one A (a1, a2) and a residue b0 per input: 12 free
  // parameters of the 6 submodels' 18 coefficients.
  EXPECT_TRUE(contains(fit.output, "6 submodels, 12 parameters")) << fit.output;
  const auto missing = modalwatch::test_support::run_cli("fit --config " + cfg + " --data " + data +
                                                         " --u-column f_a --u-column f_c --y-column acc");
  EXPECT_EQ(missing.code, 2) << missing.output;
  EXPECT_TRUE(contains(missing.output, "missing column 'f_c'")) << missing.output;
  EXPECT_TRUE(contains(missing.output, "pick one with --u-column")) << missing.output;
  const std::string closed = write("closed.yaml",
                                   "sample_rate_hz: 100\nmodel:\n  loop: closed\n  modes: 3\n"
                                   "controller:\n  numerator: [1]\n  denominator: [1]\n");
  const auto refused = modalwatch::test_support::run_cli("fit --config " + closed + " --data " + data +
                                                         " --u-column f_a --u-column f_b --y-column acc");
  EXPECT_EQ(refused.code, 2) << refused.output;
  EXPECT_TRUE(contains(refused.output, "a closed loop has one input")) << refused.output;
}

// track reads the inputs model.inputs names (f_a, f_b) from the CSV, streamed,
// and its estimates are the recursive estimator's on the same samples; each
// submodel follows its own input's mode. The 3 Hz mode starts at one
// frequency on both inputs, and the warm-up fit puts its two submodels a hair
// apart: not a mode moving past another (only those of one input have an order).
TEST_F(SeveralInputsCli, TrackFollowsEachSubmodelFromItsOwnInputColumn) {
  const std::string data = record();
  std::string yaml = recursive_config(kTruth, 0.1);
  yaml.replace(yaml.find("inputs: [u1, u2]"), 16, "inputs: [f_a, f_b]");
  for (const char* from : {"input: u1", "input: u2"})
    for (std::size_t at = yaml.find(from); at != std::string::npos; at = yaml.find(from))
      yaml.replace(at, 9, from[8] == '1' ? "input: f_a" : "input: f_b");
  const std::string cfg = write("two.yaml", yaml);
  const auto track = modalwatch::test_support::run_cli("track --no-progress --config " + cfg + " --data " + data +
                                                       " --y-column acc --out " + path("est.csv"));
  ASSERT_EQ(track.code, 0) << track.output;
  EXPECT_TRUE(contains(track.output, "4 submodels, inputs f_a f_b")) << track.output;
  EXPECT_TRUE(contains(track.output, "warm-up fit: used")) << track.output;
  const modalwatch::Table est = modalwatch::read_table(path("est.csv"));
  const Config c = modalwatch::load_config(cfg);
  modalwatch::RecordColumns cols;
  cols.u = "f_a";
  cols.further_u = {"f_b"};
  cols.y = "acc";
  const Record r = modalwatch::read_record({data, cols});
  modalwatch::RecursiveEstimator lib(c.model, c.estimator);
  modalwatch::Sample s;
  s.further_inputs = 1;
  for (Eigen::Index k = 0; k < r.size(); ++k) {
    s.t = r.t(k);
    s.u = r.u(k);
    s.y = r.y(k);
    s.further_u[0] = r.input(1)(k);
    lib.step(s);
  }
  ASSERT_EQ(est.data.rows(), r.size());
  for (std::size_t i = 0; i < kTruth.size(); ++i) {
    const double wn = est.data(r.size() - 1, est.column(kTruth[i].name + "_wn"));
    EXPECT_EQ(wn, lib.mode(static_cast<int>(i)).value.wn) << kTruth[i].name;  // the same samples, the same estimate
    EXPECT_NEAR(wn / kTruth[i].modal.wn, 1.0, 0.01) << kTruth[i].name;
  }
}

// simulate writes one column per input under model.inputs' names, and track
// follows each mode from its own input in what simulate wrote.
TEST_F(SeveralInputsCli, SimulateWritesEachInputUnderItsNameAndTrackFollowsBoth) {
  const std::string cfg = write("sim.yaml", kTwoInputSimulation);
  const auto sim = modalwatch::test_support::run_cli("simulate --config " + cfg + " --out " + path("run.csv"));
  ASSERT_EQ(sim.code, 0) << sim.output;
  const modalwatch::Table run = modalwatch::read_table(path("run.csv"));
  EXPECT_EQ(run.columns, (std::vector<std::string>{"t", "u1", "u2", "y"}));
  const Eigen::VectorXd u1 = run.data.col(1), u2 = run.data.col(2);
  // Two independent PRBS: correlation of a few 1/sqrt(N) at most.
  EXPECT_LT(std::abs(u1.dot(u2)) / std::sqrt(u1.squaredNorm() * u2.squaredNorm()), 0.05);
  const auto track = modalwatch::test_support::run_cli("track --no-progress --config " + cfg + " --data " +
                                                       path("run.csv") + " --out " + path("est.csv"));
  ASSERT_EQ(track.code, 0) << track.output;
  const modalwatch::Table est = modalwatch::read_table(path("est.csv"));
  const Eigen::Index last = est.data.rows() - 1;
  EXPECT_NEAR(est.data(last, est.column("m1_wn")) / 2.0, 1.0, 0.01);
  EXPECT_NEAR(est.data(last, est.column("m2_wn")) / (2.0 * M_PI), 1.0, 0.01);
  EXPECT_NEAR(est.data(last, est.column("m2_zeta")) / 0.1, 1.0, 0.1);
}

// --u-column names the input columns when the record's are not the model's
// names: as many as the model has inputs, each one the record has.
TEST_F(SeveralInputsCli, TrackTakesRepeatedUColumnAndNamesWhatIsWrong) {
  const std::string data = record();
  const std::string cfg = write("two.yaml", recursive_config(kTruth, 0.1));
  const std::string run =
      "track --no-progress --config " + cfg + " --data " + data + " --y-column acc --out " + path("est.csv");
  const auto ok = modalwatch::test_support::run_cli(run + " --u-column f_a --u-column f_b");
  ASSERT_EQ(ok.code, 0) << ok.output;
  const auto missing = modalwatch::test_support::run_cli(run + " --u-column f_a --u-column f_c");
  EXPECT_EQ(missing.code, 2) << missing.output;
  EXPECT_TRUE(contains(missing.output, "missing column 'f_c'")) << missing.output;
  EXPECT_TRUE(contains(missing.output, "pick one with --u-column")) << missing.output;
  const auto one = modalwatch::test_support::run_cli(run + " --u-column f_a");
  EXPECT_EQ(one.code, 2) << one.output;
  EXPECT_TRUE(contains(one.output, "--u-column: the model has 2 inputs (model.inputs); name as many input columns"))
      << one.output;
}

// The controller gives one u: several inputs in closed loop are refused by the
// config (naming the key and line) and by the estimator itself.
TEST_F(SeveralInputsCli, TrackAndTheEstimatorRefuseSeveralInputsInClosedLoop) {
  const std::string data = record();
  std::string yaml = recursive_config(kTruth, 0.1);
  yaml.replace(yaml.find("model:\n"), 7, "model:\n  loop: closed\n");
  yaml += "controller:\n  numerator: [1]\n  denominator: [1]\n";
  const std::string cfg = write("closed.yaml", yaml);
  const auto track = modalwatch::test_support::run_cli("track --no-progress --config " + cfg + " --data " + data +
                                                       " --y-column acc --out " + path("est.csv"));
  EXPECT_EQ(track.code, 2) << track.output;
  EXPECT_TRUE(contains(track.output, cfg + ":4: key 'model.inputs': a closed loop has one input")) << track.output;
  EXPECT_FALSE(std::filesystem::exists(path("est.csv")));
  const Config open = parse_config(recursive_config(kTruth, 0.1), "open.yaml");
  modalwatch::EstimatorSettings closed = open.estimator;
  closed.closed_loop = true;
  closed.controller = modalwatch::DiscreteTransferFunction({0.1}, {1.0});
  try {
    modalwatch::RecursiveEstimator est(open.model, closed);
    FAIL() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_CONTAINS(std::string(e.what()), "a closed loop has one input (the controller's u)");
  }
}

// diagnose simulates each submodel from its input; its model tables and
// summary name the inputs.
TEST_F(SeveralInputsCli, DiagnoseReportNamesEachSubmodelsInput) {
  const std::string data = record();
  const std::string cfg = write("two.yaml", "sample_rate_hz: 100\nmodel:\n  inputs: [f_a, f_b]\n  modes: 3\n");
  const auto run = modalwatch::test_support::run_cli("diagnose --config " + cfg + " --data " + data +
                                                     " --y-column acc --max-steps 0 --report " + path("report"));
  ASSERT_EQ(run.code, 0) << run.output;
  std::ifstream md(path("report/report.md"));
  const std::string report((std::istreambuf_iterator<char>(md)), std::istreambuf_iterator<char>());
  EXPECT_TRUE(contains(report, "| gain / coefficients | input |")) << report;
  EXPECT_TRUE(contains(report, "| mode3_f_a | mode | ")) << report;
  std::ifstream js(path("report/summary.json"));
  const std::string summary((std::istreambuf_iterator<char>(js)), std::istreambuf_iterator<char>());
  EXPECT_TRUE(contains(summary, "\"name\": \"mode2_f_b\", \"input\": \"f_b\"")) << summary;
  const Config written = modalwatch::load_config(path("report/model.yaml"));
  EXPECT_EQ(written.model.inputs, (std::vector<std::string>{"f_a", "f_b"}));
}

// ---------------------------------------------------------------- measured: flexible structure

// DaISy's flexible structure (a steel subframe, two white-noise shakers u1, u2,
// 28 accelerometers, fs = 1024 Hz), read in place from MODALWATCH_SHARED_DATA:
// u1, u2 -> y5 with no starting guess. The path of `fit --max-modes 14 --output
// acceleration --input-hold foh`: fits of 1..14 modes from the largest peaks of
// |H|, one submodel per input sharing one A per resonance, the batch output
// hold, the physical check, and the order of lowest BIC. Estimation on the
// first 70 % (diagnose's default split), validation on the rest.
const std::string kFlexible = modalwatch::test_support::shared_file("daisy_flexible_structure.csv");

struct FlexibleFit {
  AdditiveModel start;
  modalwatch::FitResult fit;
  double validation_percent = 0.0;
};

// modes 0: the number of modes by BIC, up to 14; else that many from the peaks.
FlexibleFit fit_flexible(const std::vector<std::string>& inputs, modalwatch::Hold input_hold, int modes) {
  modalwatch::RecordColumns cols;
  cols.u = inputs.front();
  cols.further_u.assign(inputs.begin() + 1, inputs.end());
  cols.y = "y5";
  const Record full = modalwatch::read_record({kFlexible, cols});
  const auto n = static_cast<Eigen::Index>(0.7 * static_cast<double>(full.size()));
  const Record est = full.segment(0, n);
  const std::vector<std::string> names = inputs.size() > 1 ? inputs : std::vector<std::string>{};
  constexpr int kAcceleration = 2;
  modalwatch::SrivcOptions options;
  options.input_hold = input_hold;
  options.best_cycle = true;  // as `fit` asks
  FlexibleFit out;
  if (modes == 0) {
    modalwatch::OrderOptions order;
    order.max_modes = 14;
    order.inputs = names;
    order.output_derivatives = kAcceleration;
    // `fit` takes the output hold of the largest start for every order.
    options.output_hold = modalwatch::default_output_hold(
        modalwatch::initial_modes(modalwatch::resolving_response(est, false, input_hold), order.max_modes, {}, names,
                                  kAcceleration),
        est.sample_time());
    modalwatch::OrderSelection selection = modalwatch::select_order(est, options, order);
    EXPECT_GE(selection.chosen, 0);
    if (selection.chosen < 0) return out;
    out.fit = std::move(selection.orders[static_cast<std::size_t>(selection.chosen)].fit);
  } else {
    out.start = modalwatch::initial_modes(modalwatch::resolving_response(est, false, input_hold), modes, {}, names,
                                          kAcceleration);
    options.output_hold = modalwatch::default_output_hold(out.start, est.sample_time());
    std::vector<modalwatch::ModeFinding> findings;
    out.fit = modalwatch::fit_physical(est, out.start, options, findings);
  }
  // The model runs from the record's start; the samples after the split are scored.
  const Eigen::VectorXd y_sim = modalwatch::simulate_model(out.fit.model, full, input_hold);
  out.validation_percent = modalwatch::fit_percent(full.y.tail(full.size() - n), y_sim.tail(full.size() - n));
  return out;
}

int resonances(const AdditiveModel& model) {
  int count = 0;
  for (const auto& s : model.submodels) count += s.is_mode() && s.input == 0;
  return count;
}

TEST(SeveralInputsMeasured, FlexibleStructureTwoShakersWithoutAStartingGuess) {
  if (!fs::exists(kFlexible))
    GTEST_SKIP() << "measured record not found: " << kFlexible
                 << " (configure with -DMODALWATCH_SHARED_DATA=<folder of the benchmark records>)";
  using modalwatch::Hold;
  const FlexibleFit both = fit_flexible({"u1", "u2"}, Hold::foh, 0);
  const int chosen = resonances(both.fit.model);
  const FlexibleFit one = fit_flexible({"u1"}, Hold::foh, chosen);
  const FlexibleFit held = fit_flexible({"u1", "u2"}, Hold::zoh, chosen);
  // The peaks of the Welch H1 estimates from u1 to y1/y5 in the record's
  // description, in bins of 1 Hz.
  const std::vector<double> welch_hz = {119, 192, 215, 230, 333, 397, 417, 467};
  // How many of them have a mode of `model` within 1 Hz (printed).
  const auto within_1hz = [&](const AdditiveModel& model, const char* what) {
    int within = 0;
    std::printf("  %s:", what);
    for (const double f : welch_hz) {
      double nearest = 1e9;
      for (const auto& s : model.submodels)
        if (s.is_mode()) nearest = std::min(nearest, std::abs(modalwatch::modal_parameters(s).hz() - f));
      within += nearest <= 1.0;
      std::printf(" %.0f Hz: %.2f", f, nearest);
    }
    std::printf(" (Hz to the nearest mode): %d of 8 within 1 Hz\n", within);
    return within;
  };
  std::printf("flexible structure u1,u2 -> y5, %d modes chosen by BIC:\n", chosen);
  for (const auto& s : both.fit.model.submodels) {
    if (!s.is_mode()) {
      std::printf("  %-10s not a mode (n=%d m=%d l=%d) on %s\n", s.name.c_str(), s.n, s.m, s.rigid_poles,
                  both.fit.model.input_name(s.input).c_str());
      continue;
    }
    const ModalParameters p = modalwatch::modal_parameters(s);
    std::printf("  %-10s %8.2f Hz  zeta %.4f  gain %+.4g  on %s\n", s.name.c_str(), p.hz(), p.zeta, p.gain,
                both.fit.model.input_name(s.input).c_str());
  }
  const int fit_within = within_1hz(both.fit.model, "fitted");
  within_1hz(held.fit.model, "fitted with a held input (zoh)");
  std::printf("  validation fit with a held input: %.2f %%\n", held.validation_percent);
  std::printf("  validation fit: u1+u2 %.2f %%, u1 only %.2f %% (estimation part %.2f / %.2f %%)\n",
              both.validation_percent, one.validation_percent, both.fit.fit_percent, one.fit.fit_percent);
  // Every input's view of a resonance has its resonance's A, to the last bit.
  for (const auto& group : modalwatch::pole_groups(both.fit.model)) {
    EXPECT_EQ(group.size(), 2u);
    for (const int i : group) EXPECT_EQ(both.fit.model.submodels[i].a, both.fit.model.submodels[group.front()].a);
  }
  // The record has more resonances than the 8 listed: u2 -> y5 peaks at 239,
  // 321 and 352 Hz too. BIC keeps 11 modes; 7 of the listed peaks have a mode
  // within 1 Hz, and the eighth lies at 398.0 Hz, where H1 peaks in bins of
  // 0.5 Hz (the listed 397 Hz is a bin of 1 Hz).
  EXPECT_GE(chosen, 10);
  EXPECT_GE(fit_within, 7);
  // u2 drives y5 as much as u1: with both, one A per resonance and the input
  // read as band-limited, the validation fit is 83 % (ARX(16) 17.9 %, output
  // error of order 16 58.7 %, moen4 19.5 % on the same split); without u2 its
  // response is noise to a u1-only model, and near Nyquist a held input is
  // half a sample off the band-limited force.
  EXPECT_GT(both.validation_percent, 80.0);
  EXPECT_GT(both.validation_percent, held.validation_percent + 20.0);
  EXPECT_LT(one.validation_percent, 25.0);
}

}  // namespace
