// The number of modes from the data: fits of 1, 2, ... modes from the
// resonance peaks, compared by BIC, with the stabilisation diagram's marks.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include <gtest/gtest.h>

#include "simulation_support.hpp"

#include "modalwatch/model_order.hpp"
#include "modalwatch/simulator.hpp"

namespace modalwatch {
namespace {

constexpr double kT = 0.01;  // 100 Hz

ModalParameters mode_at(double hz, double zeta, double peak) {
  return {2.0 * std::numbers::pi * hz, zeta, 2.0 * zeta * peak};
}

// The chosen order's modes, each within 1 % in wn and 20 % in zeta of the truth.
void expect_chosen(const OrderSelection& s, const std::vector<ModalParameters>& truth) {
  ASSERT_GE(s.chosen, 0);
  const OrderFit& o = s.orders[static_cast<std::size_t>(s.chosen)];
  EXPECT_EQ(o.modes, static_cast<int>(truth.size()));
  ASSERT_EQ(o.diagram.size(), truth.size());
  for (std::size_t i = 0; i < truth.size(); ++i) {
    EXPECT_NEAR(o.diagram[i].modal.wn, truth[i].wn, 0.01 * truth[i].wn) << "mode " << i + 1;
    EXPECT_NEAR(o.diagram[i].modal.zeta, truth[i].zeta, 0.2 * truth[i].zeta) << "mode " << i + 1;
  }
}

TEST(ModelOrder, ThreeModesAreChosenAndThoseFoundBeforeAreStable) {
  const std::vector<ModalParameters> truth = {mode_at(4.0, 0.03, 1.0), mode_at(11.0, 0.02, -2.0),
                                              mode_at(27.0, 0.04, 1.5)};
  const auto sim = simulate(test_support::plant_of(truth, 30.0), test_support::open_loop_prbs(kT, 120.0, 7, 1, 14));
  OrderOptions order;
  order.max_modes = 6;
  const OrderSelection s = select_order(sim.record, SrivcOptions{}, order);
  for (const OrderFit& o : s.orders) {
    std::printf("%d modes: BIC %.1f,", o.modes, o.bic);
    for (const StabilisedMode& m : o.diagram) std::printf(" %.3f Hz%s", m.modal.hz(), m.stable ? "*" : "");
    std::printf("\n");
  }
  // The data show three resonance peaks: no fourth order to start from.
  ASSERT_EQ(s.orders.size(), 3u);
  expect_chosen(s, truth);
  // The modes found at two modes reappear at three within 1 % in frequency and
  // 5 % in damping (stable); the one the third peak adds is new.
  ASSERT_EQ(s.orders[1].diagram.size(), 2u);
  int stable = 0;
  for (const StabilisedMode& m : s.orders[2].diagram) stable += m.stable;
  EXPECT_EQ(stable, 2);
  EXPECT_FALSE(s.orders[2].diagram[0].stable_frequency);  // 4 Hz, first found at three modes
  // The BIC falls to the chosen order.
  for (int k = 1; k <= s.chosen; ++k)
    EXPECT_LT(s.orders[static_cast<std::size_t>(k)].bic, s.orders[static_cast<std::size_t>(k - 1)].bic);
}

// Three modes, the fits given too few cycles to settle the larger orders:
// an unconverged fit still counts, with its cycle of least output error, and
// the lowest BIC is the true order, not the largest order that converged.
TEST(ModelOrder, AFitThatDidNotConvergeCountsWithItsBestCycle) {
  const std::vector<ModalParameters> truth = {mode_at(4.0, 0.03, 1.0), mode_at(11.0, 0.02, -2.0),
                                              mode_at(27.0, 0.04, 1.5)};
  const auto sim = simulate(test_support::plant_of(truth, 30.0), test_support::open_loop_prbs(kT, 120.0, 7, 1, 14));
  SrivcOptions options;
  options.max_iterations = 24;  // the fit of one mode converges in 19, those of two and three do not
  options.best_cycle = true;
  OrderOptions order;
  order.max_modes = 6;
  const OrderSelection s = select_order(sim.record, options, order);
  for (const OrderFit& o : s.orders)
    std::printf("%d modes: BIC %.1f, %s after %d cycles\n", o.modes, o.bic,
                o.fit.converged ? "converged" : "not converged", o.fit.iterations);
  ASSERT_EQ(s.orders.size(), 3u);
  EXPECT_TRUE(s.orders[0].fit.converged);
  EXPECT_FALSE(s.orders[2].fit.converged);
  expect_chosen(s, truth);
}

TEST(ModelOrder, TwoModesInClosedLoop) {
  const std::vector<ModalParameters> truth = {mode_at(6.0, 0.03, 1.0), mode_at(19.0, 0.02, 0.8)};
  const PlantSpec plant = test_support::plant_of(truth, 30.0);
  ExperimentSpec e = test_support::open_loop_prbs(kT, 120.0, 3, 1, 14);
  e.closed_loop = true;
  e.controller = DiscreteTransferFunction({0.25}, {1.0});  // half of 1 / the largest peak (about 2)
  const auto sim = simulate(plant, e);
  SrivcOptions options;
  options.closed_loop = true;
  options.controller = e.controller;
  OrderOptions order;
  order.max_modes = 5;
  const OrderSelection s = select_order(sim.record, options, order);
  expect_chosen(s, truth);
}

// A motor's speed after two torque steps, as on a servo rig: the lag
// K / (1 + tau p) from rest, a step at t = 0 and another at half time. The
// steps' energy lies below the first bins of the Welch estimate, so the
// structure is told by its fit: the lag of one pole, whose fit finds tau and K.
// Read as a velocity it is the same lag, a rigid body b0 / (p (1 + tau p)) in
// position.
TEST(NonResonantStructure, TwoStepsOnAMotorsSpeedChooseALagOfOnePole) {
  const double T = 0.001, tau = 0.5, K = 2000.0;
  const Eigen::Index n = 20000;
  Record r;
  r.t = Eigen::VectorXd::LinSpaced(n, 0.0, T * static_cast<double>(n - 1));
  r.u = (r.t.array() < 10.0).select(Eigen::VectorXd::Constant(n, 0.05), 0.065);
  for (const int z : {0, 1}) {
    Submodel truth;
    truth.name = "lag";
    truth.n = 1;
    truth.rigid_poles = z;
    truth.output_derivatives = z;
    truth.a = Eigen::VectorXd::Constant(1, tau);
    truth.b = Eigen::VectorXd::Constant(1, K);
    AdditiveModel plant;
    plant.submodels = {truth};
    r.y = simulate_model(plant, r) + 0.5 * test_support::white_noise(n, 11);  // speeds of 100 to 130
    SrivcOptions options;
    options.best_cycle = true;
    std::vector<std::pair<std::string, double>> bic;
    const NonResonantStart start = choose_non_resonant_start(r, resolving_response(r, false), options, z, &bic);
    for (const auto& [structure, b] : bic) std::printf("z %d: %s: BIC %.1f\n", z, structure.c_str(), b);
    ASSERT_EQ(start.structure, "a lag of one pole") << z;
    EXPECT_EQ(start.submodel.rigid_poles, z);
    AdditiveModel model;
    model.submodels = {start.submodel};
    std::vector<ModeFinding> findings;
    const FitResult fit = fit_physical(r, model, options, findings);
    ASSERT_EQ(fit.model.submodels.size(), 1u);
    const Submodel& s = fit.model.submodels[0];
    ASSERT_EQ(s.n, 1);
    std::printf("z %d: tau %.4f s, K %.1f (truth %.1f, %.1f)\n", z, s.a(0), s.b(0), tau, K);
    EXPECT_NEAR(s.a(0), tau, 0.01 * tau) << z;
    EXPECT_NEAR(s.b(0), K, 0.01 * K) << z;
  }
}

TEST(ModelOrder, AtLeastOneModeIsAsked) {
  const auto sim =
      simulate(test_support::plant_of({mode_at(6.0, 0.03, 1.0)}, 30.0), test_support::open_loop_prbs(kT, 20.0, 1));
  OrderOptions order;
  order.max_modes = 0;
  EXPECT_THROW(select_order(sim.record, SrivcOptions{}, order), std::invalid_argument);
}

}  // namespace
}  // namespace modalwatch
