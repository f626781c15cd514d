// The prefilter p^j/D(p) on sampled data must equal the continuous-time
// response of the filter to the held (ZOH) or interpolated (FOH) input, to
// round-off. Truth here is analytic: residues of the Laplace transform.
#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>
#include <vector>

#include <gtest/gtest.h>
#include <unsupported/Eigen/MatrixFunctions>

#include "modalwatch/polynomial.hpp"
#include "modalwatch/prefilter.hpp"

namespace modalwatch {
namespace {

using cd = std::complex<double>;

cd dpoly(const Eigen::VectorXd& c, cd s) {
  cd v = 0.0;
  for (Eigen::Index k = c.size() - 1; k >= 1; --k) v = v * s + static_cast<double>(k) * c(k);
  return v;
}

// j-th derivative of the response of 1/D(p) (simple, non-zero roots, D(0) != 0) to
// t^q/q! (q = 0: unit step, q = 1: unit ramp) at time t: residues of
// s^j e^{st} / (s^{q+1} D(s)).
double analytic(const Eigen::VectorXd& d, int q, int j, double t) {
  cd y = 0.0;
  for (const cd& s : roots(d)) y += std::pow(s, j) * std::exp(s * t) / (std::pow(s, q + 1) * dpoly(d, s));
  // Residue at s = 0 (pole of order q+1-j when j <= q).
  const double d0 = d(0), d1 = d.size() > 1 ? d(1) : 0.0;
  if (q == 0 && j == 0) y += 1.0 / d0;
  if (q == 1 && j == 0) y += t / d0 - d1 / (d0 * d0);
  if (q == 1 && j == 1) y += 1.0 / d0;
  return y.real();
}

Eigen::VectorXd mode_denominator(double wn, double zeta) {
  Eigen::VectorXd d(3);
  d << 1.0, 2.0 * zeta / wn, 1.0 / (wn * wn);
  return d;
}

void expect_step_response(const Eigen::VectorXd& d, double T, int samples) {
  Prefilter f(d, T, Hold::zoh);
  const int N = static_cast<int>(d.size()) - 1;
  double scale = 0.0;
  for (int k = 0; k < samples; ++k) {
    for (int j = 0; j <= N; ++j) {
      scale = std::max(scale, std::abs(analytic(d, 0, j, k * T)));
    }
  }
  for (int k = 0; k < samples; ++k) {
    const auto& out = f.step(1.0);  // unit step applied at t_0, held
    for (int j = 0; j < N; ++j) {
      ASSERT_NEAR(out(j), analytic(d, 0, j, k * T), 1e-9 * scale) << "k=" << k << " j=" << j;
    }
    // The top derivative is the algebraic one; for t > 0 it equals the true p^N w_f.
    if (k > 0) {
      ASSERT_NEAR(out(N), analytic(d, 0, N, k * T), 1e-9 * scale) << "top, k=" << k;
    }
  }
}

TEST(Prefilter, ZohStepOfUnderdampedModeMatchesAnalyticResponse) {
  expect_step_response(mode_denominator(20.0, 0.1), 0.05, 400);
}
TEST(Prefilter, ZohStepOfOverdampedSecondOrderMatchesAnalyticResponse) {
  expect_step_response(mode_denominator(3.0, 2.5), 0.05, 400);
}
TEST(Prefilter, ZohStepOfSlowModeUsesSeriesBranchAccurately) {
  expect_step_response(mode_denominator(0.5, 0.3), 0.05, 2000);  // |A T| < 0.5
}
TEST(Prefilter, ZohStepOfFirstOrderMatchesAnalyticResponse) {
  Eigen::VectorXd d(2);
  d << 1.0, 0.25;
  expect_step_response(d, 0.01, 300);
}
TEST(Prefilter, ZohStepOfFourthOrderUsesMatrixExponentialAccurately) {
  // The Rao-Garnier denominator, anti-monic.
  Eigen::VectorXd d(5);
  d << 1600.0, 416.0, 408.0, 5.0, 1.0;
  d /= 1600.0;
  expect_step_response(d, 0.01, 1000);
}

TEST(Prefilter, FohRampMatchesAnalyticResponse) {
  for (const auto& d : {mode_denominator(20.0, 0.1), mode_denominator(0.5, 0.3)}) {
    const double T = 0.05;
    Prefilter f(d, T, Hold::foh);
    for (int k = 0; k < 400; ++k) {
      const auto& out = f.step(k * T);  // the ramp t, exactly linear between samples
      ASSERT_NEAR(out(0), analytic(d, 1, 0, k * T), 1e-9 * (1.0 + k * T));
      ASSERT_NEAR(out(1), analytic(d, 1, 1, k * T), 1e-9);
    }
  }
}

TEST(Prefilter, HeldSineMatchesSuperpositionOfAnalyticSteps) {
  // Any held sequence is a sum of steps: y(t_k) = sum_i (w_i - w_{i-1}) s(t_k - t_i).
  const Eigen::VectorXd d = mode_denominator(17.0, 0.05);
  const double T = 0.05;
  const int n = 300;
  Prefilter f(d, T, Hold::zoh);
  std::vector<double> w(n);
  for (int k = 0; k < n; ++k) w[k] = std::sin(17.5 * k * T) + 0.3 * std::sin(2.0 * k * T);
  for (int k = 0; k < n; ++k) {
    const auto& out = f.step(w[k]);
    double y = 0.0, dy = 0.0;
    for (int i = 0; i <= k; ++i) {
      const double jump = w[i] - (i > 0 ? w[i - 1] : 0.0);
      y += jump * analytic(d, 0, 0, (k - i) * T);
      dy += jump * analytic(d, 0, 1, (k - i) * T);
    }
    ASSERT_NEAR(out(0), y, 1e-9 * 10.0);
    ASSERT_NEAR(out(1), dy, 1e-9 * 10.0 * 17.0);
  }
}

TEST(Prefilter, TopDerivativeMakesTheDenominatorSumEqualTheInputExactly) {
  // sum_j d_j p^j w_f(t_k) = w(t_k) whatever the hold (the top derivative is algebraic, not integrated).
  const Eigen::VectorXd d = mode_denominator(20.0, 0.1);
  for (Hold h : {Hold::zoh, Hold::foh}) {
    Prefilter f(d, 0.05, h);
    for (int k = 0; k < 200; ++k) {
      const double w = std::cos(0.37 * k) + 0.1 * k;
      const auto& out = f.step(w);
      EXPECT_NEAR(d.dot(out), w, 1e-12 * (1.0 + std::abs(w)));
    }
  }
}

TEST(Prefilter, ClosedFormDiscretisationComposesOverTwoSamplesAtEveryScale) {
  // An exact discretisation satisfies phi(2T) = phi(T)^2 and
  // gamma0(2T) = phi(T) gamma0(T) + gamma0(T); covers the series and closed-form branches.
  for (double T : {1e-4, 0.01, 0.3, 2.0}) {
    Eigen::VectorXd d = mode_denominator(7.0, 0.2);
    const auto closed = discretize(d, T, Hold::foh);
    const auto twice = discretize(d, 2 * T, Hold::zoh);
    const FilterMatrix phi2 = closed.phi * closed.phi;
    EXPECT_LT((twice.phi - phi2).cwiseAbs().maxCoeff(), 1e-12 * (1.0 + phi2.cwiseAbs().maxCoeff()));
    const FilterVector g2 = closed.phi * closed.gamma0 + closed.gamma0;
    EXPECT_LT((twice.gamma0 - g2).cwiseAbs().maxCoeff(), 1e-11 * g2.cwiseAbs().maxCoeff());
  }
}

// exp([[A T, B T, 0], [0, 0, 1], [0, 0, 0]]) = [[phi, gamma0, gamma1], ...] for
// the companion form of 1/D, D = d0 + d1 p + d2 p^2: Eigen's matrix exponential
// (Pade with scaling and squaring), independent of the closed forms.
SecondOrderDiscretization reference_discretization(double d0, double d1, double d2, double T) {
  Eigen::Matrix4d M = Eigen::Matrix4d::Zero();
  M(0, 1) = T;
  M(1, 0) = -d0 / d2 * T;
  M(1, 1) = -d1 / d2 * T;
  M(1, 2) = T / d2;
  M(2, 3) = 1.0;
  const Eigen::Matrix4d E = M.exp();
  SecondOrderDiscretization z{};
  for (int i = 0; i < 2; ++i) {
    for (int j = 0; j < 2; ++j) z.phi[i][j] = E(i, j);
    z.gamma0[i] = E(i, 2);
    z.gamma1[i] = E(i, 3);
  }
  return z;
}

TEST(Prefilter, SecondOrderClosedFormMatchesTheMatrixExponentialInEveryBranch) {
  // |A T| from 1e-7 to 4: every series length (one per binade) and the
  // complex, real and nearly repeated eigenvalue closed forms; d0 != 1 too.
  struct Case {
    double d0, d1, d2;
  };
  const Case cases[] = {{1.0, 2.0 * 0.1 / 7.0, 1.0 / 49.0},       // underdamped
                        {1.0, 2.0 * 2.5 / 3.0, 1.0 / 9.0},        // overdamped
                        {1.0, 2.0 / 5.0, 1.0 / 25.0},             // critically damped
                        {2.5, 0.3, 0.7},                          // d0 != 1
                        {1.0, 2.0 * 0.001 / 20.0, 1.0 / 400.0}};  // light damping
  int checked = 0;
  for (const Case& c : cases) {
    for (double T = 1e-8; T < 0.6; T *= 1.37) {
      const SecondOrderDiscretization got = discretize_second_order(c.d0, c.d1, c.d2, T);
      const SecondOrderDiscretization want = reference_discretization(c.d0, c.d1, c.d2, T);
      const double g0 = std::max(std::abs(want.gamma0[0]), std::abs(want.gamma0[1]));
      const double g1 = std::max(std::abs(want.gamma1[0]), std::abs(want.gamma1[1]));
      double p = 1.0;
      for (const auto& row : want.phi) p = std::max({p, std::abs(row[0]), std::abs(row[1])});
      for (int i = 0; i < 2; ++i) {
        for (int j = 0; j < 2; ++j) ASSERT_NEAR(got.phi[i][j], want.phi[i][j], 1e-13 * p) << "T=" << T;
        ASSERT_NEAR(got.gamma0[i], want.gamma0[i], 1e-12 * g0) << "T=" << T << " i=" << i;
        ASSERT_NEAR(got.gamma1[i], want.gamma1[i], 1e-12 * g1) << "T=" << T << " i=" << i;
      }
      ++checked;
    }
  }
  EXPECT_GT(checked, 200);
}

TEST(Prefilter, SecondOrderClosedFormStaysExactForStiffOverdampedFilters) {
  // d2 -> 0 with the damping held: eigenvalues -1/d1 (slow) and -d1/d2 (fast,
  // down to -3e11 per sample here). e^sigma cosh(w) overflowed to NaN beyond
  // w ~ 710 (an estimator's mode with a_2 -> 0 then locked its resets on it).
  // Eigen's matrix exponential loses digits on these matrices (scaling and
  // squaring at |A T| up to 1e13), so the checks are the semigroup property,
  // phi(2T) = phi(T)^2 and gamma0(2T) = phi(T) gamma0(T) + gamma0(T), and one
  // case against a 40-digit reference (mpmath.expm of the augmented matrix).
  const double T = 0.0993, d1 = 0.0338;
  int checked = 0;
  for (int e = 2; e <= 14; ++e) {
    const double d2 = std::pow(10.0, -e);
    const SecondOrderDiscretization one = discretize_second_order(1.0, d1, d2, T);
    const SecondOrderDiscretization two = discretize_second_order(1.0, d1, d2, 2.0 * T);
    for (int i = 0; i < 2; ++i) {
      const double g2 = one.phi[i][0] * one.gamma0[0] + one.phi[i][1] * one.gamma0[1] + one.gamma0[i];
      ASSERT_TRUE(std::isfinite(two.gamma0[i])) << "d2=" << d2;
      ASSERT_NEAR(two.gamma0[i], g2, 1e-12 * std::max(1.0, std::abs(g2))) << "d2=" << d2 << " i=" << i;
      for (int j = 0; j < 2; ++j) {
        const double p2 = one.phi[i][0] * one.phi[0][j] + one.phi[i][1] * one.phi[1][j];
        ASSERT_TRUE(std::isfinite(two.phi[i][j])) << "d2=" << d2;
        ASSERT_NEAR(two.phi[i][j], p2, 1e-13 * std::max(1.0, std::abs(p2))) << "d2=" << d2 << " i=" << i << " j=" << j;
      }
    }
    ++checked;
  }
  EXPECT_EQ(checked, 13);
  const SecondOrderDiscretization z = discretize_second_order(1.0, d1, 1e-8, T);
  const double phi[2][2] = {{0.052977563497461353861, 1.5673972552816308214e-8},
                            {-1.5673972552816308214, -4.6373105776790106319e-7}};
  const double gamma0[2] = {0.94702243650253864614, 1.5673972552816308214};
  for (int i = 0; i < 2; ++i) {
    for (int j = 0; j < 2; ++j) EXPECT_NEAR(z.phi[i][j], phi[i][j], 1e-15) << i << j;
    EXPECT_NEAR(z.gamma0[i], gamma0[i], 1e-15) << i;
  }
}

TEST(Prefilter, RigidBodyDoubleIntegratorIsExact) {
  Eigen::VectorXd d(3);
  d << 0.0, 0.0, 1.0;  // 1/p^2
  Prefilter f(d, 0.1, Hold::zoh);
  for (int k = 0; k < 50; ++k) {
    const auto& out = f.step(1.0);
    const double t = k * 0.1;
    ASSERT_NEAR(out(0), 0.5 * t * t, 1e-12 * (1 + t * t));
    ASSERT_NEAR(out(1), t, 1e-12 * (1 + t));
  }
}

TEST(Prefilter, NormalisedTimeGivesTheSameFilterAt700HzAnd10kHzAsAt1RadPerSecond) {
  // Normalised time: scaling time by ws maps a 700 Hz mode at 10 kHz onto a
  // 1 rad/s problem; outputs must agree once derivatives are rescaled by ws^j.
  const double wn = 2.0 * std::numbers::pi * 700.0, zeta = 0.01, T = 1e-4;
  Prefilter physical(mode_denominator(wn, zeta), T, Hold::zoh);
  Prefilter normalised(mode_denominator(1.0, zeta), T * wn, Hold::zoh);
  for (int k = 0; k < 2000; ++k) {
    const double w = std::sin(0.01 * k * k);
    const auto& a = physical.step(w);
    const auto& b = normalised.step(w);
    ASSERT_NEAR(a(0), b(0), 1e-10);
    ASSERT_NEAR(a(1) / wn, b(1), 1e-10);
    ASSERT_NEAR(a(2) / (wn * wn), b(2), 1e-9);
  }
}

}  // namespace
}  // namespace modalwatch
