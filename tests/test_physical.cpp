// Physical modes: a mode above Nyquist becomes a feedthrough with the same
// response on the band, an unstable mode is projected to stability, and two
// modes that split one resonance with cancelling gains are merged and refitted.
#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "simulation_support.hpp"

#include "modalwatch/physical.hpp"
#include "modalwatch/polynomial.hpp"
#include "modalwatch/simulator.hpp"
#include "modalwatch/srivc.hpp"

namespace modalwatch {
namespace {

constexpr double kPi = std::numbers::pi;

const ModeFinding& finding(const std::vector<ModeFinding>& all, const std::string& name) {
  for (const auto& f : all)
    if (f.submodel == name) return f;
  throw std::runtime_error("no finding for " + name);
}

using test_support::open_loop_prbs;

PlantMode resonant(const std::string& name, const ModalParameters& m) {
  PlantMode pm;
  pm.modal = m;
  pm.submodel = make_mode(name, m);
  return pm;
}

TEST(CheckPhysical, PhysicalModesAreKeptAsFitted) {
  AdditiveModel m;
  m.submodels = {make_mode("low", {2 * kPi * 0.05, 0.02, 1.0}), make_mode("high", {2 * kPi * 0.2, 0.05, -0.3})};
  const PhysicalCheck c = check_physical(m, Eigen::MatrixXd(), 1.0);
  EXPECT_FALSE(c.changed());
  EXPECT_FALSE(c.refit);
  ASSERT_EQ(c.findings.size(), 2u);
  for (const auto& f : c.findings) EXPECT_EQ(f.verdict, ModeVerdict::physical);
  EXPECT_EQ(c.model, m);
}

TEST(CheckPhysical, ModeAboveNyquistBecomesFeedthroughWithTheSameResponseOnTheBand) {
  // 1e5 Hz at fs = 1 Hz: a static gain over [0, 0.5 Hz].
  AdditiveModel m;
  m.submodels = {make_mode("mode1", {2 * kPi * 0.1, 0.03, 1.0}), make_mode("mode2", {2 * kPi * 1e5, 0.1, 0.4})};
  const PhysicalCheck c = check_physical(m, Eigen::MatrixXd(), 1.0);
  EXPECT_TRUE(c.refit);
  EXPECT_EQ(c.findings[0].verdict, ModeVerdict::physical);
  EXPECT_EQ(c.findings[1].verdict, ModeVerdict::feedthrough);
  EXPECT_NE(c.findings[1].reason.find("Nyquist"), std::string::npos) << c.findings[1].reason;
  ASSERT_EQ(c.model.submodels.size(), 2u);
  const Submodel& d = c.model.submodels[1];
  EXPECT_TRUE(d.is_feedthrough());
  EXPECT_EQ(d.name, "mode2");
  EXPECT_EQ(d.b(0), 0.4);
  // The mode departs from b0 by b0 2 zeta w / wn to first order (4e-7 at Nyquist).
  for (double w = 0.0; w <= kPi; w += kPi / 200)
    EXPECT_LE(std::abs(c.model.response(w) - m.response(w)), 1.001 * 0.4 * 2 * 0.1 * w / (2 * kPi * 1e5) + 1e-15)
        << w;
}

TEST(CheckPhysical, ModeWhoseResponseIsConstantWithinItsUncertaintyBecomesFeedthrough) {
  // Below Nyquist (0.45 Hz at fs = 1 Hz), heavily damped, with a_1 and a_2
  // known to a std of twice their values: its departure from b0 is within
  // 2 std (1.0 at most) everywhere on the band.
  AdditiveModel m;
  m.submodels = {make_mode("mode1", {2 * kPi * 0.05, 0.03, 1.0}), make_mode("ghost", {2 * kPi * 0.45, 0.9, 0.2})};
  const Submodel& g = m.submodels[1];
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(6, 6);
  cov(3, 3) = 4.0 * g.a(0) * g.a(0);
  cov(4, 4) = 4.0 * g.a(1) * g.a(1);
  cov(5, 5) = 1e-6;
  const PhysicalCheck c = check_physical(m, cov, 1.0);
  EXPECT_EQ(c.findings[0].verdict, ModeVerdict::physical);
  EXPECT_EQ(c.findings[1].verdict, ModeVerdict::feedthrough) << c.findings[1].reason;
  EXPECT_TRUE(c.model.submodels[1].is_feedthrough());
  EXPECT_EQ(c.model.submodels[1].b(0), 0.2);
  // Known to 1 %, the same mode is a resonance the data show; and so it is
  // when only its gain is uncertain (a gain the record leaves open).
  cov(3, 3) = 1e-4 * g.a(0) * g.a(0);
  cov(4, 4) = 1e-4 * g.a(1) * g.a(1);
  EXPECT_EQ(check_physical(m, cov, 1.0).findings[1].verdict, ModeVerdict::physical);
  cov(5, 5) = 100.0;
  EXPECT_EQ(check_physical(m, cov, 1.0).findings[1].verdict, ModeVerdict::physical);
}

TEST(CheckPhysical, UnstableModeIsProjectedAndNamed) {
  AdditiveModel m;
  m.submodels = {make_mode("stable", {2.0, 0.05, 1.0}), make_mode("unstable", {5.0, 0.04, 2.0})};
  m.submodels[1].a(0) = -m.submodels[1].a(0);  // zeta = -0.04
  const PhysicalCheck c = check_physical(m, Eigen::MatrixXd(), 0.05);
  EXPECT_EQ(c.findings[0].verdict, ModeVerdict::physical);
  const ModeFinding& f = c.findings[1];
  EXPECT_EQ(f.verdict, ModeVerdict::unstable);
  EXPECT_EQ(f.submodel, "unstable");
  EXPECT_NEAR(f.fitted.zeta, -0.04, 1e-12);
  EXPECT_FALSE(c.refit);
  const Submodel& s = c.model.submodels[1];
  EXPECT_TRUE(is_hurwitz(s.a));
  const ModalParameters p = modal_parameters(s);
  // The reflection s -> -conj(s) keeps |A(jw)|: same wn, |zeta|, same gain.
  EXPECT_NEAR(p.wn, 5.0, 1e-9);
  EXPECT_NEAR(p.zeta, 0.04, 1e-9);
  EXPECT_EQ(p.gain, 2.0);
}

TEST(CheckPhysical, NegativeStiffnessModeIsProjected) {
  // a_2 < 0: one real root in the right half plane.
  Submodel s = make_mode("saddle", {3.0, 0.1, 1.0});
  s.a(1) = -s.a(1);
  AdditiveModel m;
  m.submodels = {s};
  const PhysicalCheck c = check_physical(m, Eigen::MatrixXd(), 0.01);
  EXPECT_EQ(c.findings[0].verdict, ModeVerdict::unstable);
  EXPECT_TRUE(is_hurwitz(c.model.submodels[0].a));
}

TEST(CheckPhysical, CloseModesWithOppositeGainsAreMerged) {
  AdditiveModel m;
  m.submodels = {make_mode("a", {10.0, 0.02, 1.0}), make_mode("b", {10.05, 0.03, -0.4}),
                 make_mode("c", {30.0, 0.02, 1.0})};
  // std of wn 0.05 rad/s for a and b: 0.05 apart is within the joint 0.07.
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(9, 9);
  const double sa = 0.05 * 2.0 / std::pow(10.0, 3), sb = 0.05 * 2.0 / std::pow(10.05, 3);  // d a2 / d wn = -2/wn^3
  cov(1, 1) = sa * sa;
  cov(4, 4) = sb * sb;
  const PhysicalCheck c = check_physical(m, cov, 0.05);
  EXPECT_TRUE(c.refit);
  EXPECT_EQ(c.findings[0].verdict, ModeVerdict::physical);
  EXPECT_EQ(c.findings[1].verdict, ModeVerdict::merged);
  EXPECT_EQ(c.findings[1].into, "a");
  EXPECT_EQ(c.findings[2].verdict, ModeVerdict::physical);
  ASSERT_EQ(c.model.submodels.size(), 2u);
  const ModalParameters merged = modal_parameters(c.model.submodels[0]);
  EXPECT_NEAR(merged.wn, 10.025, 1e-9);
  EXPECT_NEAR(merged.gain, 0.6, 1e-12);
  // Same signs, or farther apart than their uncertainty: kept.
  AdditiveModel same = m;
  same.submodels[1].b(0) = 0.4;
  EXPECT_FALSE(check_physical(same, cov, 0.05).changed());
  Eigen::MatrixXd sharp = cov / 100.0;  // std 0.005: 0.05 apart is 7 joint std
  EXPECT_FALSE(check_physical(m, sharp, 0.05).changed());
}

// A poorly determined mode far from another is no split of it: their peaks do
// not overlap, so the two cannot cancel, however wide the frequency's std.
TEST(CheckPhysical, ModesWhosePeaksDoNotOverlapAreNotMerged) {
  AdditiveModel m;
  const double w1 = 2 * kPi * 9.17, w2 = 2 * kPi * 36.0;
  m.submodels = {make_mode("low", {w1, 0.007, 1.0}), make_mode("high", {w2, 0.05, -0.05})};
  // std of wn: 0.01 rad/s for "low", 200 rad/s (32 Hz) for "high": the gap
  // of 169 rad/s is within one joint std, but 24 times the half-widths
  // zeta wn (0.4 + 11.3 rad/s).
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(6, 6);
  const double s1 = 0.01 * 2.0 / std::pow(w1, 3), s2 = 200.0 * 2.0 / std::pow(w2, 3);
  cov(1, 1) = s1 * s1;
  cov(4, 4) = s2 * s2;
  const PhysicalCheck c = check_physical(m, cov, 1.0 / 400.0);
  EXPECT_GT(c.findings[1].fitted_std.wn, w2 - w1);
  EXPECT_FALSE(c.changed()) << c.findings[1].reason;
  // The same uncertainty with the peaks overlapping (36 Hz damped at 0.8): merged.
  AdditiveModel wide = m;
  wide.submodels[1] = make_mode("high", {w2, 0.8, -0.05});
  const PhysicalCheck merged = check_physical(wide, cov, 1.0 / 400.0);
  EXPECT_EQ(merged.findings[1].verdict, ModeVerdict::merged) << merged.findings[1].reason;
}

// An accelerometer's mode above Nyquist is b0 p^2 on the band: no constant a
// feedthrough could stand for, and no resonance of the record. It is left out
// and the model refitted, unless it is the only submodel.
TEST(CheckPhysical, AnAccelerometersModeAboveNyquistIsLeftOut) {
  AdditiveModel m;
  m.submodels = {make_mode("a", {10.0, 0.02, 1.0}, 2), make_mode("high", {80.0, 0.02, 0.5}, 2)};
  const PhysicalCheck c = check_physical(m, Eigen::MatrixXd(), 0.05);  // Nyquist 62.8 rad/s
  EXPECT_TRUE(c.refit);
  EXPECT_EQ(c.findings[0].verdict, ModeVerdict::physical);
  EXPECT_EQ(c.findings[1].verdict, ModeVerdict::removed);
  EXPECT_NE(c.findings[1].reason.find("above the Nyquist frequency"), std::string::npos) << c.findings[1].reason;
  ASSERT_EQ(c.model.submodels.size(), 1u);
  EXPECT_EQ(c.model.submodels[0].name, "a");
  AdditiveModel alone;
  alone.submodels = {m.submodels[1]};
  EXPECT_FALSE(check_physical(alone, Eigen::MatrixXd(), 0.05).changed());
}

// Two resonances seen from two inputs, each submodel on u2 sharing its u1
// view's A: when the u1 views merge, b's u2 view goes with them into a's.
TEST(CheckPhysical, AMergedResonanceTakesItsOtherInputsViewsAlong) {
  AdditiveModel m;
  m.inputs = {"u1", "u2"};
  m.submodels = {make_mode("a_u1", {10.0, 0.02, 1.0}), make_mode("a_u2", {10.0, 0.02, 0.3}),
                 make_mode("b_u1", {10.05, 0.03, -0.4}), make_mode("b_u2", {10.05, 0.03, 0.2})};
  m.submodels[1].input = m.submodels[3].input = 1;
  m.submodels[1].poles_of = "a_u1";
  m.submodels[3].poles_of = "b_u1";
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(12, 12);
  const double sa = 0.05 * 2.0 / std::pow(10.0, 3), sb = 0.05 * 2.0 / std::pow(10.05, 3);
  for (const int o : {0, 3}) cov(o + 1, o + 1) = sa * sa;
  for (const int o : {6, 9}) cov(o + 1, o + 1) = sb * sb;
  const PhysicalCheck c = check_physical(m, cov, 0.05);
  EXPECT_TRUE(c.refit);
  EXPECT_EQ(c.findings[2].verdict, ModeVerdict::merged);
  EXPECT_EQ(c.findings[2].into, "a_u1");
  EXPECT_EQ(c.findings[3].verdict, ModeVerdict::merged);  // same-sign gains on u2: merged with its resonance
  EXPECT_EQ(c.findings[3].into, "a_u2");
  ASSERT_EQ(c.model.submodels.size(), 2u);
  EXPECT_EQ(c.model.submodels[1].name, "a_u2");
  EXPECT_EQ(c.model.submodels[1].poles_of, "a_u1");
  EXPECT_NEAR(modal_parameters(c.model.submodels[1]).gain, 0.5, 1e-12);
  EXPECT_NO_THROW(pole_groups(c.model));
}

// End to end: a plant with a feedthrough (a sensor's direct path) fitted with a
// mode far above Nyquist in its place: the fit comes out with the feedthrough.
TEST(FitPhysical, ModeAboveNyquistIsRefittedAsFeedthrough) {
  PlantSpec plant;
  plant.modes.push_back(resonant("mode1", {2 * kPi * 2.0, 0.05, 1.0}));
  PlantMode direct;
  direct.resonant = false;
  direct.submodel = make_rigid_body("direct", 0.3, 0);
  plant.modes.push_back(direct);
  plant.noise_variance = 1e-4;
  const auto sim = simulate(plant, open_loop_prbs(0.02, 60.0, 3));
  AdditiveModel start;
  start.submodels = {make_mode("mode1", {2 * kPi * 1.9, 0.08, 0.8}), make_mode("mode2", {2 * kPi * 500.0, 0.1, 0.2})};
  std::vector<ModeFinding> findings;
  const FitResult fit = fit_physical(sim.record, start, SrivcOptions{}, findings);
  ASSERT_EQ(fit.model.submodels.size(), 2u);
  // Either the first fit already put mode2 above Nyquist (then named a
  // feedthrough) or it was given as one: the result holds the plant's structure.
  ASSERT_FALSE(findings.empty());
  EXPECT_EQ(finding(findings, "mode2").verdict, ModeVerdict::feedthrough);
  const Submodel& d = fit.model.submodels[1];
  EXPECT_TRUE(d.is_feedthrough());
  EXPECT_NEAR(d.b(0), 0.3, 0.01);
  const ModalParameters p = modal_parameters(fit.model.submodels[0]);
  EXPECT_NEAR(p.wn, 2 * kPi * 2.0, 0.01 * 2 * kPi * 2.0);
  EXPECT_NEAR(p.zeta, 0.05, 0.01);
}

// One resonance given two blocks with cancelling gains: merged into one mode and refitted.
TEST(FitPhysical, SplitResonanceIsMergedAndRefitted) {
  PlantSpec plant;
  plant.modes.push_back(resonant("mode1", {2 * kPi * 1.0, 0.04, 1.0}));
  plant.modes.push_back(resonant("mode2", {2 * kPi * 4.0, 0.02, 0.5}));
  plant.noise_variance = 1e-3;
  const auto sim = simulate(plant, open_loop_prbs(0.02, 40.0, 5));
  AdditiveModel fitted;
  fitted.submodels = {make_mode("mode1", {2 * kPi * 1.0, 0.04, 1.0}), make_mode("mode2", {2 * kPi * 4.0, 0.02, 0.8}),
                      make_mode("mode3", {2 * kPi * 4.001, 0.02, -0.3})};
  // The uncertainty of a split pair: its frequencies are poorly determined.
  Eigen::MatrixXd cov = Eigen::MatrixXd::Identity(9, 9) * 1e-12;
  const double d = 0.05 * 2.0 / std::pow(2 * kPi * 4.0, 3);
  cov(4, 4) = cov(7, 7) = d * d;
  const PhysicalCheck c = check_physical(fitted, cov, 0.02);
  ASSERT_TRUE(c.refit);
  EXPECT_EQ(c.findings[2].verdict, ModeVerdict::merged);
  const FitResult fit = fit_srivc(sim.record, c.model, SrivcOptions{});
  ASSERT_EQ(fit.model.submodels.size(), 2u);
  const ModalParameters p = modal_parameters(fit.model.submodels[1]);
  EXPECT_NEAR(p.wn, 2 * kPi * 4.0, 0.01 * 2 * kPi * 4.0);
  EXPECT_NEAR(p.zeta, 0.02, 0.2 * 0.02);
  EXPECT_NEAR(p.gain, 0.5, 0.05);
}

}  // namespace
}  // namespace modalwatch
