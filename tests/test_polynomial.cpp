#include <cmath>

#include <gtest/gtest.h>

#include "modalwatch/polynomial.hpp"

namespace modalwatch {
namespace {

TEST(Polynomial, RootsOfTheRaoGarnierDenominator) {
  Eigen::VectorXd d(5);
  d << 1600.0, 416.0, 408.0, 5.0, 1.0;
  const Eigen::VectorXcd r = roots(d);
  ASSERT_EQ(r.size(), 4);
  for (const auto& s : r) {
    std::complex<double> v = 0.0;
    for (int k = 4; k >= 0; --k) v = v * s + d(k);
    EXPECT_LT(std::abs(v), 1e-9 * 1600.0);
  }
  // Round trip back to the anti-monic polynomial.
  const Eigen::VectorXd back = polynomial_from_roots(r, 1.0);
  EXPECT_LT((back - d / 1600.0).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(Polynomial, StabilityProjectionReflectsUnstableComplexPairKeepingMagnitude) {
  Eigen::VectorXd a(2);
  a << -0.02, 0.04;  // wn = 5, negative damping
  EXPECT_FALSE(is_hurwitz(a));
  EXPECT_TRUE(project_stable(a));
  EXPECT_NEAR(a(0), 0.02, 1e-15);
  EXPECT_NEAR(a(1), 0.04, 1e-15);
  EXPECT_TRUE(is_hurwitz(a));
}

TEST(Polynomial, StabilityProjectionOfRealRootsOfOppositeSign) {
  // (1 - p/2)(1 + p/3) = 1 - p/6 - p^2/6: one root at +2.
  Eigen::VectorXd a(2);
  a << -1.0 / 6.0, -1.0 / 6.0;
  EXPECT_TRUE(project_stable(a));
  // (1 + p/2)(1 + p/3) = 1 + 5p/6 + p^2/6
  EXPECT_NEAR(a(0), 5.0 / 6.0, 1e-14);
  EXPECT_NEAR(a(1), 1.0 / 6.0, 1e-14);
}

TEST(Polynomial, StablePolynomialIsLeftAlone) {
  Eigen::VectorXd a(4);
  a << 416.0 / 1600, 408.0 / 1600, 5.0 / 1600, 1.0 / 1600;
  const Eigen::VectorXd before = a;
  EXPECT_TRUE(is_hurwitz(a));
  EXPECT_FALSE(project_stable(a));
  EXPECT_EQ(a, before);
}

TEST(Polynomial, HurwitzTestAgreesWithRootsOnHigherOrders) {
  // (p^2 + 0.1 p + 4)(p^2 - 0.2 p + 9), anti-monic: unstable second pair.
  Eigen::VectorXcd r(4);
  r << std::complex<double>(-0.05, std::sqrt(4 - 0.0025)), std::complex<double>(-0.05, -std::sqrt(4 - 0.0025)),
      std::complex<double>(0.1, std::sqrt(9 - 0.01)), std::complex<double>(0.1, -std::sqrt(9 - 0.01));
  Eigen::VectorXd a = polynomial_from_roots(r).tail(4);
  EXPECT_FALSE(is_hurwitz(a));
  EXPECT_TRUE(project_stable(a));
  EXPECT_TRUE(is_hurwitz(a));
  Eigen::VectorXd asc(5);
  asc << 1.0, a;
  for (const auto& s : roots(asc)) EXPECT_LT(s.real(), 0.0);
}

// Unstable means a root in the open right half plane: roots on the imaginary
// axis fail is_hurwitz but are no unstable model.
TEST(Polynomial, UnstableOnlyWithARootInTheRightHalfPlane) {
  Eigen::VectorXd a(2);
  a << 0.1, 0.01;  // zeta = 0.5
  EXPECT_FALSE(is_unstable(a));
  a << -0.1, 0.01;  // zeta = -0.5
  EXPECT_TRUE(is_unstable(a));
  a << 0.1, -0.01;  // real roots of opposite sign
  EXPECT_TRUE(is_unstable(a));
  a << 0.0, 0.01;  // +-10j
  EXPECT_FALSE(is_hurwitz(a));
  EXPECT_FALSE(is_unstable(a));
  Eigen::VectorXd c(3);
  c << 0.1, 0.01, 0.001;  // (1 + 0.1 p)(1 + 0.01 p^2)
  EXPECT_FALSE(is_unstable(c));
  c << 0.1, 0.01, 0.01;  // Routh: 0.1 * 0.01 < 0.01
  EXPECT_TRUE(is_unstable(c));
  c(0) = std::nan("");
  EXPECT_TRUE(is_unstable(c));
}

}  // namespace
}  // namespace modalwatch
