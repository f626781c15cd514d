#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>

#include <Eigen/Cholesky>

#include <gtest/gtest.h>

#include "modalwatch/model.hpp"

namespace modalwatch {
namespace {

TEST(Model, ModeRoundTripsThroughItsCoefficients) {
  // The paper's third mode: a_2 = 0.0025, a_1 = 0.01 -> wn = 20 rad/s, zeta = 0.1.
  Submodel s;
  s.n = 2;
  s.a.resize(2);
  s.a << 0.01, 0.0025;
  s.b.resize(1);
  s.b << 1.0;
  const ModalParameters p = modal_parameters(s);
  EXPECT_DOUBLE_EQ(p.wn, 20.0);
  EXPECT_NEAR(p.zeta, 0.1, 1e-15);
  EXPECT_NEAR(p.hz(), 20.0 / (2 * std::numbers::pi), 1e-15);
  const Submodel back = make_mode("m", p);
  EXPECT_NEAR(back.a(0), 0.01, 1e-17);
  EXPECT_NEAR(back.a(1), 0.0025, 1e-18);
}

TEST(Model, FrequencyResponseAtResonanceIsGainOverTwoZeta) {
  const Submodel s = make_mode("m", {5.0, 0.025, 0.5});
  const auto g = s.response(5.0);
  EXPECT_NEAR(std::abs(g), 0.5 / (2 * 0.025), 1e-12);
  EXPECT_NEAR(std::arg(g), -std::numbers::pi / 2, 1e-12);
  EXPECT_NEAR(std::abs(s.response(0.0)), 0.5, 1e-15);
}

TEST(Model, RigidBodyResponseIsGainOverMinusOmegaSquared) {
  const Submodel s = make_rigid_body("body", 0.5, 2);
  const auto g = s.response(3.0);
  EXPECT_NEAR(g.real(), -0.5 / 9.0, 1e-15);
  EXPECT_NEAR(g.imag(), 0.0, 1e-15);
}

TEST(Model, BetaStacksThetasInOrder) {
  AdditiveModel m;
  m.submodels = {make_mode("a", {2, 0.25, 3}), make_mode("b", {5, 0.025, 0.5})};
  const Eigen::VectorXd beta = m.beta();
  ASSERT_EQ(beta.size(), 6);
  EXPECT_DOUBLE_EQ(beta(1), 0.25);  // a_{1,2}
  EXPECT_DOUBLE_EQ(beta(5), 0.5);   // b_{2,0}
  EXPECT_EQ(m.offset(1), 3);
  Eigen::VectorXd changed = beta;
  changed(5) = 0.7;
  m.set_beta(changed);
  EXPECT_DOUBLE_EQ(m.submodels[1].b(0), 0.7);
}

TEST(Model, ModalStdFollowsFirstOrderPropagation) {
  const Submodel s = make_mode("m", {20.0, 0.1, 1.0});
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(3, 3);
  cov(1, 1) = std::pow(1e-6, 2);  // std of a2
  cov(2, 2) = 4e-4;
  const ModalParameters sd = modal_std(s, cov);
  // d wn / d a2 = -0.5 a2^{-3/2} = -0.5 * 8000
  EXPECT_NEAR(sd.wn, 0.5 * std::pow(0.0025, -1.5) * 1e-6, 1e-12);
  EXPECT_NEAR(sd.gain, 0.02, 1e-15);
}

TEST(Model, ModalCovarianceMatchesAMonteCarloOfTheta) {
  // wn = 20 rad/s, zeta = 0.1, gain 1.5; theta = (a1, a2, b0) with relative std
  // 0.5 %, 0.4 %, 0.8 % and correlations -0.6 (a1, a2), 0.3 (a1, b0), -0.2 (a2, b0).
  const Submodel s = make_mode("m", {20.0, 0.1, 1.5});
  const Eigen::Vector3d theta = s.theta();
  const Eigen::Vector3d sd = theta.cwiseProduct(Eigen::Vector3d(0.005, 0.004, 0.008));
  Eigen::Matrix3d corr;
  corr << 1.0, -0.6, 0.3, -0.6, 1.0, -0.2, 0.3, -0.2, 1.0;
  const Eigen::MatrixXd cov = sd.asDiagonal() * corr * sd.asDiagonal();
  const Eigen::Matrix3d predicted = modal_covariance(s, cov);

  const Eigen::Matrix3d l = Eigen::LLT<Eigen::Matrix3d>(cov).matrixL();
  std::mt19937_64 rng(7);
  std::normal_distribution<double> z;
  constexpr int n = 200000;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d sum2 = Eigen::Matrix3d::Zero();
  Submodel draw = s;
  for (int k = 0; k < n; ++k) {
    draw.set_theta(theta + l * Eigen::Vector3d(z(rng), z(rng), z(rng)));
    const ModalParameters p = modal_parameters(draw);
    const Eigen::Vector3d v(p.wn, p.zeta, p.gain);
    sum += v;
    sum2 += v * v.transpose();
  }
  const Eigen::Vector3d mean = sum / n;
  const Eigen::Matrix3d measured = sum2 / n - mean * mean.transpose();
  for (int r = 0; r < 3; ++r) {
    // Variances to 2 % (the sampling error is 0.3 %, the second-order terms less).
    EXPECT_NEAR(predicted(r, r) / measured(r, r), 1.0, 0.02) << r;
    for (int c = 0; c < r; ++c) {
      const double rho_p = predicted(r, c) / std::sqrt(predicted(r, r) * predicted(c, c));
      const double rho_m = measured(r, c) / std::sqrt(measured(r, r) * measured(c, c));
      std::printf("  corr(%d, %d): propagated %+.4f, Monte Carlo %+.4f\n", r, c, rho_p, rho_m);
      EXPECT_NEAR(rho_p, rho_m, 0.01) << r << " " << c;
      EXPECT_EQ(predicted(r, c), predicted(c, r));
    }
  }
  // wn and gain are correlated only through a2 and b0, with the sign of -corr(a2, b0).
  EXPECT_GT(predicted(2, 0), 0.0) << "corr(a2, b0) < 0 and d wn / d a2 < 0";

  // modal_std is the diagonal's square root.
  const ModalParameters msd = modal_std(s, cov);
  EXPECT_DOUBLE_EQ(msd.wn, std::sqrt(predicted(0, 0)));
  EXPECT_DOUBLE_EQ(msd.zeta, std::sqrt(predicted(1, 1)));
  EXPECT_DOUBLE_EQ(msd.gain, std::sqrt(predicted(2, 2)));
}

TEST(Model, ModalCovarianceOfARigidBodyHasTheGainOnly) {
  const Submodel s = make_rigid_body("r", 2.0);
  Eigen::MatrixXd cov(1, 1);
  cov << 0.09;
  const Eigen::Matrix3d c = modal_covariance(s, cov);
  EXPECT_EQ(c(2, 2), 0.09);
  EXPECT_EQ(c.topLeftCorner(2, 2).norm() + c.col(2).head(2).norm(), 0.0);
  EXPECT_EQ(modal_covariance(s, Eigen::MatrixXd::Identity(3, 3)).norm(), 0.0) << "sizes disagree";
}

TEST(Model, ResonancesOfAFourthOrderSubmodel) {
  // (p^2/4 + 0.1 p + 1)(p^2/400 + 0.01 p + 1): modes at 2 and 20 rad/s.
  Submodel s;
  s.n = 4;
  s.m = 1;
  const double a1 = 0.1, a2 = 0.25, c1 = 0.01, c2 = 0.0025;
  s.a.resize(4);
  s.a << a1 + c1, a2 + c2 + a1 * c1, a1 * c2 + a2 * c1, a2 * c2;
  s.b = Eigen::VectorXd::Ones(2);
  const auto r = resonances(s);
  ASSERT_EQ(r.size(), 2u);
  EXPECT_NEAR(r[0].wn, 2.0, 1e-10);
  EXPECT_NEAR(r[0].zeta, 0.1, 1e-10);
  EXPECT_NEAR(r[1].wn, 20.0, 1e-9);
  EXPECT_NEAR(r[1].zeta, 0.1, 1e-10);
}

}  // namespace
}  // namespace modalwatch
