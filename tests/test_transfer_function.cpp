// DiscreteTransferFunction against hand-computed recursions, exact
// steady-state sinusoid responses, and the closed-loop poles of the paper's
// example (section 5) computed from an independent ZOH discretisation.
#include <cmath>
#include <complex>
#include <numbers>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>
#include <unsupported/Eigen/MatrixFunctions>

#include "modalwatch/transfer_function.hpp"

namespace modalwatch {
namespace {

std::vector<double> impulse_response(DiscreteTransferFunction tf, int n) {
  std::vector<double> h;
  for (int k = 0; k < n; ++k) h.push_back(tf.step(k == 0 ? 1.0 : 0.0));
  return h;
}

TEST(TransferFunction, NormalisesByA0AndRightAlignsNumerator) {
  const DiscreteTransferFunction tf({2.0, 4.0}, {2.0, 1.0, 0.5});
  EXPECT_EQ(tf.numerator(), (std::vector<double>{0.0, 1.0, 2.0}));
  EXPECT_EQ(tf.denominator(), (std::vector<double>{1.0, 0.5, 0.25}));
  EXPECT_EQ(tf.feedthrough(), 0.0);
  EXPECT_EQ(tf.state().size(), 2u);
}

TEST(TransferFunction, RejectsImproperAndZeroLeadingDenominator) {
  EXPECT_THROW(DiscreteTransferFunction({1.0, 2.0, 3.0}, {1.0, 0.5}), std::invalid_argument);
  EXPECT_THROW(DiscreteTransferFunction({1.0}, {0.0, 1.0}), std::invalid_argument);
  EXPECT_THROW(DiscreteTransferFunction({1.0}, {}), std::invalid_argument);
  EXPECT_THROW(DiscreteTransferFunction({}, {1.0}), std::invalid_argument);
  EXPECT_THROW(DiscreteTransferFunction({NAN}, {1.0}), std::invalid_argument);
  EXPECT_TRUE(DiscreteTransferFunction().empty());
}

// The paper's controller (q^2 form, with the corrected -0.02058): y_k = y_{k-1}
// + 0.02329 e_k - 0.02058 e_{k-1} + 0.00454 e_{k-2}.
TEST(TransferFunction, PaperControllerImpulseResponse) {
  const DiscreteTransferFunction c({0.02329, -0.02058, 0.00454}, {1.0, -1.0, 0.0});
  EXPECT_DOUBLE_EQ(c.feedthrough(), 0.02329);
  const auto h = impulse_response(c, 6);
  EXPECT_NEAR(h[0], 0.02329, 1e-15);
  EXPECT_NEAR(h[1], 0.02329 - 0.02058, 1e-15);
  for (int k = 2; k < 6; ++k) EXPECT_NEAR(h[k], 0.02329 - 0.02058 + 0.00454, 1e-15) << k;
}

// 1/(q - 0.5) is q^-1/(1 - 0.5 q^-1): one sample of delay, then 0.5^(k-1).
TEST(TransferFunction, StrictlyProperAndQInverseForms) {
  for (const auto& num : {std::vector<double>{1.0}, std::vector<double>{0.0, 1.0}}) {
    const DiscreteTransferFunction tf(num, {1.0, -0.5});
    EXPECT_EQ(tf.feedthrough(), 0.0);
    const auto h = impulse_response(tf, 5);
    EXPECT_EQ(h[0], 0.0);
    for (int k = 1; k < 5; ++k) EXPECT_DOUBLE_EQ(h[k], std::pow(0.5, k - 1)) << k;
  }
  const auto h = impulse_response(DiscreteTransferFunction({1.0, 0.0}, {1.0, -0.5}), 5);
  for (int k = 0; k < 5; ++k) EXPECT_DOUBLE_EQ(h[k], std::pow(0.5, k)) << k;
  // A static gain has no state.
  DiscreteTransferFunction gain({3.0}, {2.0});
  EXPECT_DOUBLE_EQ(gain.step(2.0), 3.0);
  EXPECT_TRUE(gain.state().empty());
}

TEST(TransferFunction, PeekDoesNotAdvance) {
  DiscreteTransferFunction c({0.02329, -0.02058, 0.00454}, {1.0, -1.0, 0.0});
  for (double e : {1.0, -0.5, 0.25}) c.step(e);
  const auto before = c.state();
  const double peeked = c.peek(0.7);
  EXPECT_EQ(c.state(), before);
  EXPECT_DOUBLE_EQ(c.peek(0.7), peeked);
  EXPECT_DOUBLE_EQ(c.peek(0.0) + c.feedthrough() * 0.7, peeked);
  EXPECT_EQ(c.step(0.7), peeked);
}

TEST(TransferFunction, StateRoundTripAndReset) {
  DiscreteTransferFunction c({1.0, -0.3, 0.1}, {1.0, -1.2, 0.5});
  for (int k = 0; k < 10; ++k) c.step(std::sin(0.3 * k));
  const auto saved = c.state();
  std::vector<double> first;
  for (int k = 0; k < 5; ++k) first.push_back(c.step(k));
  c.set_state(saved);
  for (int k = 0; k < 5; ++k) EXPECT_EQ(c.step(k), first[k]);
  EXPECT_THROW(c.set_state({1.0}), std::invalid_argument);
  c.reset();
  EXPECT_EQ(c.state(), (std::vector<double>{0.0, 0.0}));
}

// In steady state a cosine comes out scaled and shifted by C(e^{j w T}).
// Poles at 0.6 +- 0.37j (|p| = 0.707): after 400 samples transients are < 1e-60.
TEST(TransferFunction, ResponseMatchesSteadyStateSinusoid) {
  const double T = 0.01;
  for (double w : {0.5, 40.0, 250.0}) {
    DiscreteTransferFunction c({1.0, -0.3, 0.1}, {1.0, -1.2, 0.5});
    const std::complex<double> g = c.response(w, T);
    for (int k = 0; k < 400; ++k) c.step(std::cos(w * k * T));
    for (int k = 400; k < 420; ++k) {
      const double y = c.step(std::cos(w * k * T));
      EXPECT_NEAR(y, std::abs(g) * std::cos(w * k * T + std::arg(g)), 1e-12) << "w=" << w << " k=" << k;
    }
  }
  // Static values: 1/(q - 0.5) is 2 at DC and -2/3 at Nyquist.
  const DiscreteTransferFunction tf({1.0}, {1.0, -0.5});
  EXPECT_NEAR(std::abs(tf.response(0.0, 1.0) - 2.0), 0.0, 1e-15);
  EXPECT_NEAR(std::abs(tf.response(std::numbers::pi, 1.0) + 2.0 / 3.0), 0.0, 1e-15);
}

TEST(TransferFunctionClosedLoop, ScalarPlantsAnalytic) {
  const Eigen::MatrixXd phi = Eigen::MatrixXd::Constant(1, 1, 0.9);
  const Eigen::MatrixXd one = Eigen::MatrixXd::Ones(1, 1);
  // Static gain K: pole a - K; with plant feedthrough d: a - K / (1 + K d).
  const DiscreteTransferFunction k({0.5}, {1.0});
  EXPECT_NEAR(closed_loop_spectral_radius(k, phi, one, one, 0.0), 0.4, 1e-14);
  EXPECT_NEAR(closed_loop_spectral_radius(k, phi, one, one, 0.5), 0.5, 1e-14);
  // Integrator 0.1/(q - 1) around 1/(q - 0.5): q^2 - 1.5 q + 0.6, |q| = sqrt(0.6).
  const Eigen::MatrixXd half = Eigen::MatrixXd::Constant(1, 1, 0.5);
  const DiscreteTransferFunction i({0.1}, {1.0, -1.0});
  EXPECT_NEAR(closed_loop_spectral_radius(i, half, one, one, 0.0), std::sqrt(0.6), 1e-14);
  EXPECT_THROW(closed_loop_spectral_radius(i, half, Eigen::MatrixXd::Ones(2, 1), one, 0.0), std::invalid_argument);
}

// ZOH discretisation of the paper's sum of three modes b0/(a2 p^2 + a1 p + 1),
// states [w, p w] per mode, via the matrix exponential of [[A, B], [0, 0]] T.
struct PaperPlant {
  Eigen::MatrixXd phi, gamma, c;
};

PaperPlant paper_plant(double T) {
  const double b0[] = {3.0, 0.5, 1.0}, a2[] = {0.25, 0.04, 0.0025}, a1[] = {0.25, 0.01, 0.01};
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(7, 7);
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(1, 6);
  for (int i = 0; i < 3; ++i) {
    M(2 * i, 2 * i + 1) = 1.0;
    M(2 * i + 1, 2 * i) = -1.0 / a2[i];
    M(2 * i + 1, 2 * i + 1) = -a1[i] / a2[i];
    M(2 * i + 1, 6) = 1.0 / a2[i];
    c(0, 2 * i) = b0[i];
  }
  const Eigen::MatrixXd E = (M * T).exp();
  return {E.topLeftCorner(6, 6), E.topRightCorner(6, 1), c};
}

// Section 5: the printed -0.2058 destabilises the loop; -0.02058 is what the
// paper's closed-loop data must have used.
TEST(TransferFunctionClosedLoop, PaperExample) {
  const PaperPlant p = paper_plant(0.05);
  const DiscreteTransferFunction good({0.02329, -0.02058, 0.00454}, {1.0, -1.0, 0.0});
  const double rho = closed_loop_spectral_radius(good, p.phi, p.gamma, p.c, 0.0);
  EXPECT_LT(rho, 1.0);
  EXPECT_NEAR(rho, 0.9956, 1e-3);
  const DiscreteTransferFunction printed({0.02329, -0.2058, 0.00454}, {1.0, -1.0, 0.0});
  const double rho_printed = closed_loop_spectral_radius(printed, p.phi, p.gamma, p.c, 0.0);
  EXPECT_GT(rho_printed, 1.0);
  EXPECT_NEAR(rho_printed, 1.25, 0.05);
  RecordProperty("rho", std::to_string(rho));
  RecordProperty("rho_printed", std::to_string(rho_printed));
}

}  // namespace
}  // namespace modalwatch
