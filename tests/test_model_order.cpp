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

TEST(ModelOrder, AtLeastOneModeIsAsked) {
  const auto sim =
      simulate(test_support::plant_of({mode_at(6.0, 0.03, 1.0)}, 30.0), test_support::open_loop_prbs(kT, 20.0, 1));
  OrderOptions order;
  order.max_modes = 0;
  EXPECT_THROW(select_order(sim.record, SrivcOptions{}, order), std::invalid_argument);
}

}  // namespace
}  // namespace modalwatch
