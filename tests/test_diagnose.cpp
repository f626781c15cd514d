// modalwatch diagnose on records with one undeclared effect each (acceptance 1
// of the diagnose issue), made by the simulator from a 2-mode plant plus the
// effect, diagnosed with the 2-mode model; and the residual tests themselves.
#include <cmath>
#include <cstdio>
#include <numbers>
#include <optional>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "modalwatch/diagnose.hpp"
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
  ExperimentSpec ex;
  ex.sample_time = kT;
  ex.duration = duration;
  ex.seed = seed;
  ex.closed_loop = closed;
  if (closed) ex.controller = pd_controller();
  ex.excitation.kind = SignalSpec::Kind::multisine;
  ex.excitation.f_min_hz = 0.1;
  ex.excitation.f_max_hz = 10.0;
  ex.excitation.period_s = 10.0;
  ex.excitation.rms = 1.0;
  ex.excitation.seed = seed;
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
      std::printf("      cand %-10s val %.4g bic %.1f %s", effect_name(c.kind), c.validation_rms, c.bic, c.note.c_str());
      for (const auto& [k, v] : c.params) std::printf(" %s=%.5g", k.c_str(), v);
      std::printf("\n");
    }
  }
  std::printf("  stop: %s\n", d.result.stop_reason.c_str());
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

class DiagnoseEffect : public ::testing::TestWithParam<EffectCase> {};

// Cubic coefficient: the closed loop keeps y smaller (about 0.6 rms against 1.8
// in open loop), so its effect needs a larger c to be of similar size.
double cubic_for(bool closed) { return closed ? 0.3 : 0.02; }

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
  if (c.name == "mode") { EXPECT_NEAR(param(added, "wn"), 60.0, 0.02 * 60.0); }
  if (c.name == "delay") { EXPECT_EQ(param(added, "samples"), 3.0); }
  if (c.name == "coulomb") { EXPECT_NEAR(param(added, "fc"), 0.3, 0.1 * 0.3); }
  if (c.name == "cubic") { EXPECT_NEAR(param(added, "c"), cubic_for(c.closed), 0.1 * cubic_for(c.closed)); }
  if (c.name == "offset") { EXPECT_NEAR(param(added, "value"), 0.2, 0.1 * 0.2); }
  if (c.name == "rigid_body") { EXPECT_NEAR(param(added, "gain"), 0.2, 0.1 * 0.2); }
  // The validation error drops at least 5x.
  EXPECT_LE(d.after, d.before / 5.0) << "before " << d.before << " after " << d.after;
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
                                           EffectCase{"cubic", false}, EffectCase{"cubic", true}),
                         case_name);

class DiagnoseNoEffect : public ::testing::TestWithParam<bool> {};

TEST_P(DiagnoseNoEffect, AddsNothing) {
  std::printf("no effect, %s loop\n", GetParam() ? "closed" : "open");
  const Diagnosed d = run(plant_with("none", GetParam()), GetParam());
  EXPECT_EQ(d.result.steps.size(), 1u) << "added " << (d.result.steps.size() > 1 ? d.result.steps[1].effect : "");
}

INSTANTIATE_TEST_SUITE_P(Synthetic, DiagnoseNoEffect, ::testing::Values(false, true),
                         [](const ::testing::TestParamInfo<bool>& i) { return std::string(i.param ? "closed" : "open"); });

}  // namespace
}  // namespace modalwatch
