// modalwatch diagnose on records with one undeclared effect each, made by the
// simulator from a 2-mode plant plus the effect, diagnosed with the 2-mode
// model; an effect's credit over the refit without it; the residual tests
// themselves; and the measured records. The command and its report:
// test_diagnose_report.cpp.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <ostream>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "simulation_support.hpp"
#include "support.hpp"

#include "modalwatch/diagnose.hpp"
#include "modalwatch/initial_modes.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/io/records.hpp"
#include "modalwatch/model_order.hpp"
#include "modalwatch/simulator.hpp"

namespace modalwatch {
namespace {

constexpr double kT = 0.01;  // s: 100 Hz

// The true plant's two declared modes.
std::vector<PlantMode> base_modes() {
  std::vector<PlantMode> modes;
  for (const ModalParameters& p : {ModalParameters{5.0, 0.05, 1.0}, ModalParameters{20.0, 0.03, 0.5}}) {
    PlantMode m;
    m.modal = p;
    m.submodel = make_mode("m" + std::to_string(modes.size() + 1), p);
    modes.push_back(m);
  }
  return modes;
}

// The configured 2-mode model: the true modes, off by 5-20 %.
AdditiveModel configured_model() {
  AdditiveModel m;
  m.submodels.push_back(make_mode("m1", {5.3, 0.08, 0.8}));
  m.submodels.push_back(make_mode("m2", {19.0, 0.05, 0.6}));
  return m;
}

// PD controller u = Kp e + Kd (e_k - e_{k-1}) / T.
DiscreteTransferFunction pd_controller() {
  const double kp = 0.5, kd = 0.04;  // stable with every plant below
  return DiscreteTransferFunction({kp + kd / kT, -kd / kT}, {1.0, 0.0});
}

Record make_record(const PlantSpec& plant, bool closed, std::uint64_t seed, double duration) {
  ExperimentSpec ex = test_support::open_loop_multisine(kT, duration, seed, 0.1, 10.0, 10.0, 1.0);
  ex.closed_loop = closed;
  if (closed) ex.controller = pd_controller();
  return simulate(plant, ex).record;
}

struct Diagnosed {
  DiagnoseResult result;
  double before = 0.0, after = 0.0;  // validation RMS
};

Diagnosed run(const PlantSpec& plant, bool closed) {
  const Record est = make_record(plant, closed, 11, 30.0);
  const Record val = make_record(plant, closed, 12, 15.0);
  LoopSpec loop;
  loop.closed = closed;
  if (closed) loop.controller = pd_controller();
  Diagnosed d;
  d.result = diagnose(est, val, configured_model(), loop, DiagnoseOptions{});
  d.before = d.result.steps.front().validation_rms;
  d.after = d.result.steps.back().validation_rms;
  for (const DiagnoseStep& s : d.result.steps) {
    std::printf("  step %-10s val rms %.4g  fit %.2f %%  bic %.1f  white %s (%.3f/%.3f)", s.effect.c_str(),
                s.validation_rms, s.fit_percent, s.bic, s.residual.whiteness.pass ? "pass" : "fail",
                s.residual.whiteness.statistic, s.residual.whiteness.threshold);
    for (const auto& [k, v] : s.params) std::printf(" %s=%.5g", k.c_str(), v);
    std::printf("\n");
    for (const Candidate& c : s.ranking) {
      std::printf("      cand %-10s val %.4g bic %.1f %s", effect_name(c.kind), c.validation_rms, c.bic,
                  c.note.c_str());
      for (const auto& [k, v] : c.params) std::printf(" %s=%.5g", k.c_str(), v);
      std::printf("\n");
    }
  }
  std::printf("  stop: %s\n", d.result.stop_reason.c_str());
  // Every added step, as made physical, lowers the validation RMS of the
  // refit without it by more than min_improvement, and its credit says by how much.
  for (std::size_t k = 1; k < d.result.steps.size(); ++k) {
    const DiagnoseStep& s = d.result.steps[k];
    EXPECT_LT(s.validation_rms, (1.0 - DiagnoseOptions{}.min_improvement) * s.refit_validation_rms) << s.effect;
    EXPECT_DOUBLE_EQ(s.credit, s.refit_validation_rms - s.validation_rms) << s.effect;
  }
  return d;
}

double param(const DiagnoseStep& s, const std::string& key) {
  for (const auto& [k, v] : s.params)
    if (k == key) return v;
  ADD_FAILURE() << "no parameter " << key << " in step " << s.effect;
  return std::nan("");
}

struct EffectCase {
  std::string name;  // expected effect
  bool closed;
};

void PrintTo(const EffectCase& c, std::ostream* os) { *os << c.name << (c.closed ? ", closed loop" : ", open loop"); }

class DiagnoseEffect : public ::testing::TestWithParam<EffectCase> {};

// Cubic coefficient: the closed loop keeps y smaller (about 0.6 rms against 1.8
// in open loop), so its effect needs a larger c to be of similar size.
double cubic_for(bool closed) { return closed ? 0.3 : 0.02; }

double complex_b1(const std::string& mode) { return mode == "m1" ? 0.1 : -0.02; }

PlantSpec plant_with(const std::string& effect, bool closed) {
  PlantSpec p;
  p.modes = base_modes();
  p.noise_variance = 1e-6;  // std 1e-3 against an output of about 0.5 rms
  if (effect == "mode") {
    PlantMode m;
    m.modal = {60.0, 0.02, 0.3};
    m.submodel = make_mode("m3", m.modal);
    p.modes.push_back(m);
  } else if (effect == "rigid_body") {
    PlantMode m;
    m.resonant = false;
    m.submodel = make_rigid_body("rb", 0.2, 2);
    p.modes.push_back(m);
  } else if (effect == "complex_modes") {
    // Numerators b0 + b1 p: zeros at -2 wn for the first mode, +1.25 wn for the second.
    for (PlantMode& m : p.modes) {
      m.resonant = false;
      m.submodel.m = 1;
      m.submodel.b.conservativeResize(2);
      m.submodel.b(1) = complex_b1(m.submodel.name);
    }
  } else if (effect == "feedthrough") {
    PlantMode m;
    m.resonant = false;
    m.submodel = make_rigid_body("d", 0.1, 0);
    p.modes.push_back(m);
  } else if (effect == "offset") {
    p.effects.output_offset = 0.2;
  } else if (effect == "delay") {
    p.effects.input_delay = 3;
  } else if (effect == "coulomb") {
    p.effects.coulomb = 0.3;
  } else if (effect == "cubic") {
    p.effects.cubic = cubic_for(closed);
  }
  return p;
}

TEST_P(DiagnoseEffect, RanksTheEffectFirstAndRecoversIt) {
  const EffectCase c = GetParam();
  std::printf("%s, %s loop\n", c.name.c_str(), c.closed ? "closed" : "open");
  const Diagnosed d = run(plant_with(c.name, c.closed), c.closed);
  ASSERT_GE(d.result.steps.size(), 2u) << d.result.stop_reason;
  // The right effect ranks first at the first step and is added.
  ASSERT_FALSE(d.result.steps[0].ranking.empty());
  EXPECT_EQ(effect_name(d.result.steps[0].ranking.front().kind), c.name);
  const DiagnoseStep& added = d.result.steps[1];
  ASSERT_EQ(added.effect, c.name);
  if (c.name == "mode") {
    EXPECT_NEAR(param(added, "wn"), 60.0, 0.02 * 60.0);
  }
  if (c.name == "delay") {
    EXPECT_EQ(param(added, "samples"), 3.0);
  }
  if (c.name == "coulomb") {
    EXPECT_NEAR(param(added, "fc"), 0.3, 0.1 * 0.3);
  }
  if (c.name == "cubic") {
    EXPECT_NEAR(param(added, "c"), cubic_for(c.closed), 0.1 * cubic_for(c.closed));
  }
  if (c.name == "offset") {
    EXPECT_NEAR(param(added, "value"), 0.2, 0.1 * 0.2);
  }
  if (c.name == "rigid_body") {
    EXPECT_NEAR(param(added, "gain"), 0.2, 0.1 * 0.2);
  }
  if (c.name == "complex_modes") {
    EXPECT_EQ(param(added, "modes"), 2.0);
    for (const Submodel& s : added.model.linear.submodels) {
      ASSERT_EQ(s.m, 1) << s.name;
      EXPECT_NEAR(s.b(1), complex_b1(s.name), 0.1 * std::abs(complex_b1(s.name))) << s.name;
    }
  }
  if (c.name == "feedthrough") {
    EXPECT_NEAR(param(added, "gain"), 0.1, 0.1 * 0.1);
  }
  // The validation error drops at least 5x with the effect alone.
  EXPECT_LE(added.validation_rms, d.before / 5.0) << "before " << d.before << " after " << added.validation_rms;
}

std::string case_name(const ::testing::TestParamInfo<EffectCase>& info) {
  return info.param.name + (info.param.closed ? "_closed" : "_open");
}

INSTANTIATE_TEST_SUITE_P(Synthetic, DiagnoseEffect,
                         ::testing::Values(EffectCase{"mode", false}, EffectCase{"mode", true},
                                           EffectCase{"rigid_body", false}, EffectCase{"rigid_body", true},
                                           EffectCase{"offset", false}, EffectCase{"offset", true},
                                           EffectCase{"delay", false}, EffectCase{"delay", true},
                                           EffectCase{"coulomb", false}, EffectCase{"coulomb", true},
                                           EffectCase{"cubic", false}, EffectCase{"cubic", true},
                                           EffectCase{"complex_modes", false}, EffectCase{"complex_modes", true},
                                           EffectCase{"feedthrough", false}, EffectCase{"feedthrough", true}),
                         case_name);

class DiagnoseNoEffect : public ::testing::TestWithParam<bool> {};

TEST_P(DiagnoseNoEffect, AddsNothing) {
  std::printf("no effect, %s loop\n", GetParam() ? "closed" : "open");
  const Diagnosed d = run(plant_with("none", GetParam()), GetParam());
  EXPECT_EQ(d.result.steps.size(), 1u) << "added " << (d.result.steps.size() > 1 ? d.result.steps[1].effect : "");
}

INSTANTIATE_TEST_SUITE_P(Synthetic, DiagnoseNoEffect, ::testing::Values(false, true),
                         [](const ::testing::TestParamInfo<bool>& i) {
                           return std::string(i.param ? "closed" : "open");
                         });

// ------------------------------------------------------------ stop rules

// The stop reason is the rule that ended the run, each provoked on a small record.
DiagnoseResult diagnose_with(const PlantSpec& plant, const DiagnoseOptions& options) {
  return diagnose(make_record(plant, false, 11, 30.0), make_record(plant, false, 12, 15.0), configured_model(),
                  LoopSpec{}, options);
}

bool mentions(const std::string& text, const std::string& what) { return text.find(what) != std::string::npos; }

TEST(DiagnoseStop, TheBestCandidateImprovesLessThanAsked) {
  DiagnoseOptions options;
  options.library = {EffectKind::offset};
  options.min_improvement = 0.999;
  const DiagnoseResult r = diagnose_with(plant_with("offset", false), options);
  ASSERT_EQ(r.steps.size(), 1u) << r.stop_reason;
  EXPECT_EQ(r.stop, DiagnoseStop::min_improvement) << r.stop_reason;
  // The offset was found (the error drops from the 0.2 offset to the 1e-3 noise) but not added.
  ASSERT_EQ(r.steps[0].ranking.size(), 1u);
  EXPECT_NEAR(r.steps[0].ranking[0].validation_rms, 1e-3, 2e-4);
  EXPECT_NEAR(r.steps[0].validation_rms, 0.2, 0.01);
  EXPECT_TRUE(mentions(r.stop_reason, "best candidate (offset) lowers the validation RMS by 99.5 %")) << r.stop_reason;
  EXPECT_TRUE(mentions(r.stop_reason, "less than the 99.9 % asked")) << r.stop_reason;
}

// A plant with an output offset and a third mode (60 rad/s) the model lacks.
PlantSpec offset_and_mode() {
  PlantSpec p = plant_with("mode", false);
  p.effects.output_offset = 0.2;
  return p;
}

TEST(DiagnoseStop, MaxStepsReachedWhileTheResidualStillFails) {
  DiagnoseOptions options;
  options.library = {EffectKind::mode, EffectKind::offset};
  options.max_steps = 1;
  const DiagnoseResult r = diagnose_with(offset_and_mode(), options);
  ASSERT_EQ(r.steps.size(), 2u) << r.stop_reason;
  EXPECT_EQ(r.stop, DiagnoseStop::max_steps) << r.stop_reason;
  EXPECT_FALSE(r.steps[1].residual.pass());
  EXPECT_EQ(r.stop_reason, "1 effects added, the most allowed");
}

TEST(DiagnoseStop, ModeCapReached) {
  DiagnoseOptions options;
  options.library = {EffectKind::mode, EffectKind::offset};
  options.max_modes_added = 0;
  const DiagnoseResult r = diagnose_with(offset_and_mode(), options);
  // The missing mode is never tried, and the offset alone explains little of the error.
  ASSERT_EQ(r.steps.size(), 1u) << r.stop_reason;
  EXPECT_EQ(r.stop, DiagnoseStop::mode_cap) << r.stop_reason;
  ASSERT_EQ(r.steps[0].ranking.size(), 1u);
  EXPECT_EQ(r.steps[0].ranking[0].kind, EffectKind::offset);
  EXPECT_TRUE(mentions(r.stop_reason, "0 modes added, the most allowed; of the other effects, best candidate (offset)"))
      << r.stop_reason;

  // Two modes missing, one allowed: the first is added, the second never tried.
  PlantSpec two = plant_with("mode", false);
  PlantMode m;
  m.modal = {40.0, 0.02, 0.3};
  m.submodel = make_mode("m4", m.modal);
  two.modes.push_back(m);
  options.library = {EffectKind::mode};
  options.max_modes_added = 1;
  const DiagnoseResult one = diagnose_with(two, options);
  ASSERT_EQ(one.steps.size(), 2u) << one.stop_reason;
  EXPECT_EQ(one.steps[1].effect, "mode");
  const double hz = param(one.steps[1], "hz");
  EXPECT_TRUE(std::abs(hz - 60.0 / (2 * std::numbers::pi)) < 0.02 * hz ||
              std::abs(hz - 40.0 / (2 * std::numbers::pi)) < 0.02 * hz)
      << hz;
  EXPECT_FALSE(one.steps[1].residual.pass());
  EXPECT_TRUE(one.steps[1].ranking.empty());
  EXPECT_EQ(one.stop, DiagnoseStop::mode_cap) << one.stop_reason;
  EXPECT_EQ(one.stop_reason, "1 modes added, the most allowed, and no other effect to try");
}

TEST(DiagnoseStop, NoCandidateCouldBeFittedNamesEachAndWhy) {
  DiagnoseOptions options;
  options.library = {EffectKind::drift};
  const DiagnoseResult r = diagnose_with(plant_with("offset", false), options);
  // A drift stands in for the offset once; the second drift is refused.
  ASSERT_EQ(r.steps.size(), 2u) << r.stop_reason;
  EXPECT_EQ(r.steps[1].effect, "drift");
  EXPECT_EQ(r.stop, DiagnoseStop::not_fitted) << r.stop_reason;
  EXPECT_EQ(r.stop_reason, "no candidate could be fitted: drift (already in the model)");
}

// ------------------------------------------------------------ credit over the refit

// The open-loop plant with a cubic stiffness (and an output offset when given),
// diagnosed with cubic and offset only and 2 output-error iterations per fit:
// the cubic model of step 1 has no SRIVC start and is left short of its
// optimum, so a refit of it alone lowers the validation error further.
DiagnoseResult under_converged(double offset) {
  PlantSpec plant = plant_with("cubic", false);
  plant.effects.output_offset = offset;
  DiagnoseOptions options;
  options.library = {EffectKind::cubic, EffectKind::offset};
  options.oe_iterations = 2;
  options.max_steps = 2;
  return diagnose_with(plant, options);
}

const Candidate* ranked(const DiagnoseStep& s, EffectKind kind) {
  for (const Candidate& c : s.ranking)
    if (c.kind == kind) return &c;
  return nullptr;
}

TEST(DiagnoseCredit, AnOffsetTheDataLackGetsNoCreditForTheRefit) {
  const DiagnoseResult r = under_converged(0.0);
  ASSERT_GE(r.steps.size(), 2u) << r.stop_reason;
  const DiagnoseStep& cubic = r.steps[1];
  ASSERT_EQ(cubic.effect, "cubic");
  // Under-converged: 0.016 left where the refit alone reaches the 1e-3 noise.
  EXPECT_GT(cubic.validation_rms, 0.01);
  EXPECT_NEAR(cubic.refit.validation_rms, 1e-3, 1e-4);
  // The offset's fit, a refit with one more parameter, leaves the same error:
  // against the step's model it would be a 90 % drop, against the refit nothing.
  const Candidate* offset = ranked(cubic, EffectKind::offset);
  ASSERT_NE(offset, nullptr);
  EXPECT_NEAR(offset->validation_rms, 1e-3, 1e-4);
  EXPECT_LT(offset->validation_rms, 0.1 * cubic.validation_rms);
  EXPECT_DOUBLE_EQ(offset->credit, cubic.refit.validation_rms - offset->validation_rms);
  EXPECT_LT(std::abs(offset->credit), 1e-3 * cubic.refit.validation_rms);
  EXPECT_EQ(r.stop, DiagnoseStop::min_improvement) << r.stop_reason;
  EXPECT_TRUE(mentions(r.stop_reason, "best candidate (offset)")) << r.stop_reason;
  EXPECT_TRUE(mentions(r.stop_reason, "beyond the refit without it")) << r.stop_reason;
}

TEST(DiagnoseResult, IsTheLastModelRefittedWhenThatValidatesBetter) {
  const DiagnoseResult r = under_converged(0.0);
  // The cubic step, short of its optimum, then its refit alone as the result:
  // the same structure, down to the 1e-3 noise.
  ASSERT_EQ(r.steps.size(), 3u) << r.stop_reason;
  const DiagnoseStep& cubic = r.steps[1];
  const DiagnoseStep& last = r.steps[2];
  EXPECT_EQ(last.effect, "refit");
  EXPECT_TRUE(last.params.empty());
  EXPECT_EQ(last.model.linear.submodels.size(), cubic.model.linear.submodels.size());
  EXPECT_TRUE(last.model.effects.cubic_on);
  EXPECT_FALSE(last.model.effects.output_offset_on);
  EXPECT_NEAR(last.model.effects.cubic, cubic_for(false), 0.05 * cubic_for(false));
  EXPECT_NEAR(last.validation_rms, 1e-3, 1e-4);
  EXPECT_DOUBLE_EQ(last.refit_validation_rms, cubic.validation_rms);
  EXPECT_DOUBLE_EQ(last.credit, cubic.validation_rms - last.validation_rms);
  EXPECT_TRUE(mentions(r.stop_reason, "the last model refitted alone lowers the validation RMS")) << r.stop_reason;
  // The stop rule is still the one that ended the augmentation.
  EXPECT_EQ(r.stop, DiagnoseStop::min_improvement) << r.stop_reason;
}

TEST(DiagnoseCredit, AnOffsetInTheDataIsCreditedWithWhatItAdds) {
  const DiagnoseResult r = under_converged(0.02);
  ASSERT_EQ(r.steps.size(), 3u) << r.stop_reason;
  ASSERT_EQ(r.steps[1].effect, "cubic");
  const DiagnoseStep& added = r.steps[2];
  ASSERT_EQ(added.effect, "offset");
  EXPECT_NEAR(param(added, "value"), 0.02, 0.1 * 0.02);
  // From the cubic step's 0.026: the refit alone takes it to the offset's 0.02,
  // the offset from there to the 1e-3 noise; the offset is credited with the second part.
  EXPECT_GT(r.steps[1].validation_rms, 0.024);
  EXPECT_NEAR(added.refit_validation_rms, 0.02, 0.001);
  EXPECT_DOUBLE_EQ(added.refit_validation_rms, r.steps[1].refit.validation_rms);
  EXPECT_NEAR(added.validation_rms, 1e-3, 1e-4);
  const Candidate* offset = ranked(r.steps[1], EffectKind::offset);
  ASSERT_NE(offset, nullptr);
  EXPECT_DOUBLE_EQ(added.credit, offset->credit);
  EXPECT_NEAR(added.credit, 0.019, 0.001);
  EXPECT_GT(added.credit, 0.9 * added.refit_validation_rms);
}

// ------------------------------------------------------------ one effects model

// The augmented model with the true modes and effects, run on a noise-free
// record of the simulator, gives back the record's output: both run the
// effects of include/modalwatch/effects.hpp.
class AugmentedModelMatchesSimulator : public ::testing::TestWithParam<bool> {};

TEST_P(AugmentedModelMatchesSimulator, WithEveryEffect) {
  const bool closed = GetParam();
  PlantSpec plant;
  plant.modes = base_modes();
  plant.effects.output_offset = 0.2;
  plant.effects.input_offset = -0.1;
  plant.effects.input_delay = closed ? 1 : 3;
  plant.effects.coulomb = 0.3;
  plant.effects.cubic = cubic_for(closed);
  const Record data = make_record(plant, closed, 5, 20.0);
  AugmentedModel model;
  for (const PlantMode& m : plant.modes) model.linear.submodels.push_back(m.submodel);
  ModelEffects& e = model.effects;
  e.output_offset_on = e.input_offset_on = e.coulomb_on = e.cubic_on = true;
  static_cast<PlantEffects&>(e) = plant.effects;
  LoopSpec loop;
  loop.closed = closed;
  if (closed) loop.controller = pd_controller();
  Eigen::VectorXd u_sim;
  const Eigen::VectorXd y = simulate_augmented(model, data, loop, &u_sim);
  ASSERT_TRUE(y.allFinite());
  const double scale = data.y.cwiseAbs().maxCoeff();
  EXPECT_GT(scale, 0.5);
  EXPECT_LT((y - data.y).cwiseAbs().maxCoeff(), 1e-10 * scale);
  EXPECT_LT((u_sim - data.u).cwiseAbs().maxCoeff(), 1e-10 * data.u.cwiseAbs().maxCoeff());
  // Without the Coulomb branch the output moves by far more than that.
  e.coulomb_on = false;
  EXPECT_GT((simulate_augmented(model, data, loop) - data.y).cwiseAbs().maxCoeff(), 1e-3 * scale);
}

INSTANTIATE_TEST_SUITE_P(Effects, AugmentedModelMatchesSimulator, ::testing::Values(false, true),
                         [](const ::testing::TestParamInfo<bool>& i) {
                           return std::string(i.param ? "closed" : "open");
                         });

// ------------------------------------------------------------ residual tests

// A configured mode far above Nyquist (1 kHz at 100 Hz): the fit of the
// configured structure names it (the check of physical.hpp) and returns a
// feedthrough beside the two true modes.
TEST(DiagnosePhysical, ModeAboveNyquistBecomesFeedthrough) {
  PlantSpec plant;
  plant.modes = base_modes();
  plant.noise_variance = 1e-6;
  const Record est = make_record(plant, false, 11, 30.0);
  const Record val = make_record(plant, false, 12, 15.0);
  AdditiveModel model = configured_model();
  model.submodels.push_back(make_mode("fast", {2 * std::numbers::pi * 1000.0, 0.1, 0.01}));
  DiagnoseOptions options;
  options.max_steps = 0;
  const DiagnoseResult r = diagnose(est, val, model, LoopSpec{}, options);
  const DiagnoseStep& s = r.steps.front();
  ASSERT_FALSE(s.physical.empty());
  EXPECT_EQ(s.physical.front().submodel, "fast");
  EXPECT_EQ(s.physical.front().verdict, ModeVerdict::feedthrough) << s.physical.front().reason;
  ASSERT_EQ(s.model.linear.submodels.size(), 3u);
  EXPECT_TRUE(s.model.linear.submodels[2].is_feedthrough());
  EXPECT_NEAR(s.model.linear.submodels[2].b(0), 0.0, 1e-3);  // the plant has none
  const double wn[] = {5.0, 20.0}, zeta[] = {0.05, 0.03};
  for (int i = 0; i < 2; ++i) {
    const ModalParameters p = modal_parameters(s.model.linear.submodels[static_cast<std::size_t>(i)]);
    EXPECT_NEAR(p.wn, wn[i], 0.01 * wn[i]) << i;
    EXPECT_NEAR(p.zeta, zeta[i], 0.2 * zeta[i]) << i;
  }
}

TEST(ResidualTests, WhiteNoisePassesAndColouredNoiseFails) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> normal;
  const int N = 4000;
  Eigen::VectorXd e(N), u(N), ar(N);
  for (int k = 0; k < N; ++k) {
    e(k) = normal(rng);
    u(k) = normal(rng);
    ar(k) = (k ? 0.8 * ar(k - 1) : 0.0) + e(k);  // AR(1): rho(1) = 0.8
  }
  const ResidualAnalysis white = analyse_residual(e, u, 0.01, 25);
  EXPECT_TRUE(white.whiteness.pass) << white.whiteness.statistic;
  EXPECT_TRUE(white.independence.pass) << white.independence.statistic;
  EXPECT_TRUE(white.coherence.pass) << white.coherence.statistic << " vs " << white.coherence.threshold;
  EXPECT_NEAR(white.whiteness.threshold, 2.58 / std::sqrt(4000.0), 1e-12);
  const ResidualAnalysis coloured = analyse_residual(ar, u, 0.01, 25);
  EXPECT_FALSE(coloured.whiteness.pass);
  EXPECT_NEAR(coloured.autocorrelation(1), 0.8, 0.03);
  // A residual that is the input two samples late fails independence at lag 2.
  Eigen::VectorXd late = 0.1 * e;
  late.tail(N - 2) += u.head(N - 2);
  const ResidualAnalysis dependent = analyse_residual(late, u, 0.01, 25);
  EXPECT_FALSE(dependent.independence.pass);
  EXPECT_GT(dependent.cross_correlation(2), 0.9);
  EXPECT_FALSE(dependent.coherence.pass);
}

TEST(ResidualTests, WelchFindsASineAtItsFrequency) {
  const int N = 8192;
  const double T = 0.01;
  Eigen::VectorXd e(N), u = Eigen::VectorXd::Ones(N);
  for (int k = 0; k < N; ++k) e(k) = std::sin(2 * std::numbers::pi * 12.5 * k * T);
  const Spectra sp = welch_spectra(e, u, T, 1024);
  Eigen::Index peak = 0;
  sp.residual_psd.maxCoeff(&peak);
  EXPECT_NEAR(sp.frequency_hz(peak), 12.5, 100.0 / 1024);
}

// e = u - 0.5 u delayed one sample: S_eu / S_uu is that filter's response
// 1 - 0.5 exp(-j w T), magnitude and phase, with coherence 1.
TEST(ResidualTests, WelchCrossSpectrumOfAKnownFilterIsItsResponse) {
  const int N = 1 << 15;
  const double T = 0.001;
  std::mt19937_64 rng(4);
  std::normal_distribution<double> z;
  Eigen::VectorXd u(N), e(N);
  for (int k = 0; k < N; ++k) u(k) = z(rng);
  e(0) = u(0);
  for (int k = 1; k < N; ++k) e(k) = u(k) - 0.5 * u(k - 1);
  const Spectra sp = welch_spectra(e, u, T, 1024);
  ASSERT_EQ(sp.frequency_hz.size(), 513);
  EXPECT_EQ(sp.segments, 63);
  for (Eigen::Index f = 1; f < sp.frequency_hz.size() - 1; f += 16) {
    const std::complex<double> h =
        1.0 - 0.5 * std::exp(std::complex<double>(0.0, -2.0 * std::numbers::pi * sp.frequency_hz(f) * T));
    EXPECT_NEAR(std::abs(sp.cross(f) - h), 0.0, 0.01) << sp.frequency_hz(f) << " Hz";
    EXPECT_NEAR(sp.coherence(f), 1.0, 1e-3) << sp.frequency_hz(f) << " Hz";
  }
}

// ------------------------------------------------------------ measured records

const std::string kShared = MODALWATCH_SHARED_DATA;

// The measured records are read in place from MODALWATCH_SHARED_DATA; without
// them these tests skip.
#define SKIP_WITHOUT_SHARED(file)                                                                     \
  do {                                                                                                \
    if (!std::filesystem::exists(kShared + "/" + (file)))                                             \
      GTEST_SKIP() << "measured record " << (file) << " not found in " << kShared                     \
                   << " (configure with -DMODALWATCH_SHARED_DATA=<folder of the benchmark records>)"; \
  } while (false)

// Silverbox: one linear mode; diagnose must find the cubic stiffness first.
// A smaller run than the README's table (two multisine realisations, 4
// substeps, the library narrowed to four effects) to stay within the test budget.
TEST(DiagnoseMeasured, SilverboxFindsCubicStiffness) {
  SKIP_WITHOUT_SHARED("silverbox_snls80mv.csv");
  const Record full = read_record(kShared + "/silverbox_snls80mv.csv");
  const Record est = full.segment(40650, 2 * 8692);
  const Record val = full.segment(100, 40475);  // the arrow
  const Config config = load_config(test_support::source_file("config/silverbox.yaml"));
  DiagnoseOptions options;
  options.library = {EffectKind::mode, EffectKind::offset, EffectKind::coulomb, EffectKind::cubic};
  options.max_steps = 2;
  LoopSpec loop;
  loop.interpolate_input = true;  // band-limited input (--input-hold foh)
  loop.substeps = 4;
  const DiagnoseResult r = diagnose(est, val, config.model, loop, options);
  for (const auto& s : r.steps) std::printf("silverbox: %-8s val rms %.4g V\n", s.effect.c_str(), s.validation_rms);
  ASSERT_EQ(r.steps.size(), 3u) << r.stop_reason;
  EXPECT_EQ(r.steps[1].effect, "cubic");
  EXPECT_GT(param(r.steps[1], "c"), 0.0);  // hardening
  EXPECT_LT(r.steps[1].validation_rms, 0.5 * r.steps[0].validation_rms);
  // Then the offset; on the arrow 15 mV before, about 1 mV after (0.97 mV
  // with 8 substeps in the README's table).
  EXPECT_EQ(r.steps[2].effect, "offset");
  EXPECT_LT(r.steps.back().validation_rms, 1.2e-3);
}

// EMPS: rigid body + viscous friction in closed loop; diagnose must find the
// Coulomb friction and the force offset (IDIM-LS reference 20.39 N, -3.16 N).
TEST(DiagnoseMeasured, EmpsFindsCoulombFrictionAndTheOffset) {
  SKIP_WITHOUT_SHARED("emps_train.csv");
  SKIP_WITHOUT_SHARED("emps_pulses_test.csv");
  const Record est = read_record(kShared + "/emps_train.csv");
  const Record val = read_record(kShared + "/emps_pulses_test.csv");
  const Config config = load_config(test_support::source_file("config/emps.yaml"));
  LoopSpec loop;
  loop.closed = true;
  loop.controller = config.controller;
  DiagnoseOptions options;
  options.library = {EffectKind::offset, EffectKind::drift, EffectKind::coulomb, EffectKind::cubic};
  options.max_steps = 2;
  const DiagnoseResult r = diagnose(est, val, config.model, loop, options);
  const double gtau = 35.15065;  // N/V
  for (const auto& s : r.steps) std::printf("emps: %-8s val rms %.4g m\n", s.effect.c_str(), s.validation_rms);
  ASSERT_EQ(r.steps.size(), 3u) << r.stop_reason;
  EXPECT_EQ(r.steps[1].effect, "coulomb");
  EXPECT_NEAR(gtau * param(r.steps[1], "fc"), 20.39, 0.1 * 20.39);
  EXPECT_EQ(r.steps[2].effect, "offset");
  EXPECT_EQ(param(r.steps[2], "input"), 1.0);
  // The model's u_off enters as +u_off; the benchmark's offset is subtracted from the force.
  EXPECT_NEAR(-gtau * param(r.steps[2], "value"), -3.16, 0.1 * 3.16);
  EXPECT_LT(r.steps.back().validation_rms, r.steps[0].validation_rms / 3.0);
}

// DaISy robot arm (no sample rate: time in samples), started from the two
// peaks of the data alone. Its modes have complex residues and the modes above
// the band leave a constant: with both it reaches the best any linear model
// fitted by output error on the first 70 % does on the rest (about 90 %).
TEST(DiagnoseMeasured, RobotArmNeedsComplexModesAndAFeedthrough) {
  SKIP_WITHOUT_SHARED("daisy_robot_arm.csv");
  RecordColumns columns;
  columns.t = "n";
  const Record full = read_record({kShared + "/daisy_robot_arm.csv", columns});
  const Eigen::Index n_est = 716;
  const Record est = full.segment(0, n_est);
  DiagnoseOptions options;
  options.max_steps = 3;
  options.validation_lead_in = n_est;  // validated on the rest, the model run through the first 70 %
  const DiagnoseResult r = diagnose(est, full, initial_modes(est, 2, false), LoopSpec{}, options);
  for (const auto& s : r.steps) std::printf("robot arm: %-13s fit %.2f %%\n", s.effect.c_str(), s.fit_percent);
  ASSERT_GE(r.steps.size(), 3u) << r.stop_reason;
  EXPECT_LT(r.steps[0].fit_percent, 70.0);  // real residues, no feedthrough
  EXPECT_EQ(r.steps[1].effect, "complex_modes");
  EXPECT_EQ(r.steps[2].effect, "feedthrough");
  EXPECT_GT(r.steps.back().fit_percent, 89.0);
  for (const Submodel& s : r.steps.back().model.linear.submodels) {
    if (s.n == 2) {
      EXPECT_GT(s.a(0), 0.0) << s.name << " is not damped";
    }
  }
}

// HSM150 servo rig: the speed after two torque steps, from rest (0.05 N m,
// then 0.065 N m at 10 s). No resonance: the start is the non-resonant
// structure of least BIC, a lag of one pole, and diagnose adds the Coulomb
// friction of the motor (the record's steady speeds, 139.0 and 306.5 rad/s,
// give an affine torque-speed relation with an intercept of about 0.037 N m).
TEST(DiagnoseMeasured, Hsm150StepStartsFromALagAndFindsCoulombFriction) {
  SKIP_WITHOUT_SHARED("hsm150_ident_step_pos_0.065_2.csv");
  const Record full = read_record(kShared + "/hsm150_ident_step_pos_0.065_2.csv");
  const Record est = full.segment(0, 14000);
  SrivcOptions fit;
  fit.best_cycle = true;
  const NonResonantStart start = choose_non_resonant_start(est, resolving_response(est, false), fit);
  ASSERT_EQ(start.structure, "a lag of one pole");
  AdditiveModel initial;
  initial.submodels = {start.submodel};
  DiagnoseOptions options;
  options.max_steps = 1;
  options.validation_lead_in = 14000;  // the model run through the estimation part
  const DiagnoseResult r = diagnose(est, full, initial, LoopSpec{}, options);
  for (const auto& s : r.steps)
    std::printf("hsm150 step: %-8s est rms %.4g, val rms %.4g rad/s\n", s.effect.c_str(), s.estimation_rms,
                s.validation_rms);
  ASSERT_EQ(r.steps.size(), 2u) << r.stop_reason;
  EXPECT_EQ(r.steps[1].effect, "coulomb");
  EXPECT_NEAR(param(r.steps[1], "fc"), 0.037, 0.1 * 0.037);
  EXPECT_LT(r.steps[1].estimation_rms, 0.2 * r.steps[0].estimation_rms);
}

// F-16 ground vibration test, level 1: the model declares 2 of the modes;
// diagnose adds modes at the measured FRF peaks (9.18 and 6.59 Hz in the
// benchmark's description) and the validation error drops at each step. A
// short run: 2 periods to estimate, 2 steps.
TEST(DiagnoseMeasured, F16AddsModesAtTheFrfPeaks) {
  SKIP_WITHOUT_SHARED("f16_fullmsine_level1.csv");
  RecordColumns columns;
  columns.y = "y2";
  const Record full = read_record({kShared + "/f16_fullmsine_level1.csv", columns});
  const Eigen::Index n_est = 2 * 8192;
  const Record est = full.segment(0, n_est);
  const Record val = full.segment(0, n_est + 8192);  // simulated from rest, scored after n_est
  const Config config = load_config(test_support::source_file("config/f16.yaml"));
  DiagnoseOptions options;
  options.library = {EffectKind::mode};
  options.max_steps = 2;
  options.min_improvement = 0.02;
  options.validation_lead_in = n_est;
  const DiagnoseResult r = diagnose(est, val, config.model, LoopSpec{}, options);
  for (const auto& s : r.steps)
    std::printf("f16: %-5s %s val rms %.4g\n", s.effect.c_str(),
                s.params.empty() ? "" : std::to_string(param(s, "hz")).c_str(), s.validation_rms);
  ASSERT_EQ(r.steps.size(), 3u) << r.stop_reason;
  EXPECT_NEAR(param(r.steps[1], "hz"), 9.18, 0.02 * 9.18);
  EXPECT_NEAR(param(r.steps[2], "hz"), 6.59, 0.02 * 6.59);
  EXPECT_LT(r.steps[1].validation_rms, 0.8 * r.steps[0].validation_rms);
  EXPECT_LT(r.steps[2].validation_rms, r.steps[1].validation_rms);
}

}  // namespace
}  // namespace modalwatch
