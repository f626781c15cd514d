// Excitation signals against their definitions: formula values, the exact
// spectrum and rms of a multisine over one period, and the maximum-length
// property of every PRBS register size (by period where it is cheap, by
// primitivity of the feedback polynomial for all 2..31 bits).
#include <array>
#include <cmath>
#include <complex>
#include <cstdint>
#include <numbers>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

#include "modalwatch/signals.hpp"

namespace modalwatch {
namespace {

constexpr double kPi = std::numbers::pi;

Eigen::VectorXd time_grid(Eigen::Index n, double T) {
  return Eigen::VectorXd::LinSpaced(n, 0.0, static_cast<double>(n - 1)) * T;
}

TEST(Signals, SumOfSinesMatchesFormula) {
  SignalSpec s;
  s.kind = SignalSpec::Kind::sum_of_sines;
  s.amplitudes = {3.0, 1.0};
  s.frequencies_rad_s = {0.005, 17.5};
  s.phases = {0.0, 0.3};
  const Eigen::VectorXd t = time_grid(200, 0.05);
  const Eigen::VectorXd y = generate(s, t);
  for (Eigen::Index k = 0; k < t.size(); ++k)
    EXPECT_NEAR(y(k), 3.0 * std::sin(0.005 * t(k)) + std::sin(17.5 * t(k) + 0.3), 1e-14) << k;
  s.phases.clear();  // default: zero phases
  EXPECT_NEAR(generate(s, t)(7), 3.0 * std::sin(0.005 * 0.35) + std::sin(17.5 * 0.35), 1e-14);
  s.phases = {1.0};
  EXPECT_THROW(generate(s, t), std::invalid_argument);
  s.phases.clear();
  s.amplitudes = {1.0};
  EXPECT_THROW(generate(s, t), std::invalid_argument);
}

SignalSpec multisine_spec(std::uint64_t seed) {
  SignalSpec s;
  s.kind = SignalSpec::Kind::multisine;
  s.f_min_hz = 1.0;
  s.f_max_hz = 5.0;
  s.period_s = 10.0;
  s.rms = 0.7;
  s.seed = seed;
  return s;
}

// One period at 100 Hz (1000 samples): lines k = 10..50 of the DFT carry
// amplitude rms sqrt(2/41) each (|X_k| = A N / 2), every other bin is zero.
TEST(Signals, MultisineFlatSpectrumAndRms) {
  const int n = 1000;
  const Eigen::VectorXd y = generate(multisine_spec(7), time_grid(n, 0.01));
  EXPECT_NEAR(std::sqrt(y.squaredNorm() / n), 0.7, 1e-12);
  const double line = 0.7 * std::sqrt(2.0 / 41.0) * n / 2.0;
  for (int k = 0; k <= n / 2; ++k) {
    std::complex<double> X = 0.0;
    for (int i = 0; i < n; ++i) X += y(i) * std::polar(1.0, -2.0 * kPi * k * i / n);
    const double expected = (k >= 10 && k <= 50) ? line : 0.0;
    EXPECT_NEAR(std::abs(X), expected, 1e-9 * line) << "bin " << k;
  }
}

TEST(Signals, MultisineSeedReproducible) {
  const Eigen::VectorXd t = time_grid(500, 0.01);
  EXPECT_EQ(generate(multisine_spec(3), t), generate(multisine_spec(3), t));
  EXPECT_GT((generate(multisine_spec(3), t) - generate(multisine_spec(4), t)).norm(), 1.0);
  SignalSpec empty_band = multisine_spec(1);
  empty_band.f_min_hz = 1.01;
  empty_band.f_max_hz = 1.09;  // no multiple of 0.1 Hz inside
  EXPECT_THROW(generate(empty_band, t), std::invalid_argument);
}

SignalSpec prbs_spec(int bits, int clock = 1) {
  SignalSpec s;
  s.kind = SignalSpec::Kind::prbs;
  s.register_bits = bits;
  s.clock_period = clock;
  s.amplitude = 0.5;
  return s;
}

std::vector<int> prime_factors(std::uint64_t n) {
  std::vector<int> f;
  for (std::uint64_t p = 2; p * p <= n; ++p) {
    if (n % p != 0) continue;
    f.push_back(static_cast<int>(p));
    while (n % p == 0) n /= p;
  }
  if (n > 1) f.push_back(static_cast<int>(n));
  return f;
}

// An m-sequence of period N = 2^n - 1: periodic with N and with no divisor
// of N, and 2^(n-1) high values against 2^(n-1) - 1 low ones per period.
TEST(Signals, PrbsHasMaximumPeriodUpTo20Bits) {
  for (int bits = 2; bits <= 20; ++bits) {
    const Eigen::Index N = (Eigen::Index{1} << bits) - 1;
    const Eigen::VectorXd y = generate(prbs_spec(bits), time_grid(2 * N, 1e-3));
    ASSERT_TRUE((y.head(N).array() == y.tail(N).array()).all()) << bits << " bits: not periodic in 2^n - 1";
    for (int p : prime_factors(static_cast<std::uint64_t>(N))) {
      const Eigen::Index d = N / p;
      EXPECT_FALSE((y.head(N).array() == y.segment(d, N).array()).all()) << bits << " bits: period " << d;
    }
    const auto high = (y.head(N).array() == 0.5).count();
    EXPECT_EQ(high, N / 2 + 1) << bits;
    EXPECT_EQ((y.head(N).array() == -0.5).count(), N / 2) << bits;
  }
}

// GF(2) polynomials as bit masks (bit i = coefficient of x^i), degree <= 31.
std::uint64_t mulmod(std::uint64_t a, std::uint64_t b, std::uint64_t poly, int degree) {
  std::uint64_t r = 0;
  for (int i = 0; i < degree; ++i)
    if ((b >> i) & 1U) r ^= a << i;
  for (int i = 2 * degree - 2; i >= degree; --i)
    if ((r >> i) & 1U) r ^= poly << (i - degree);
  return r;
}

std::uint64_t x_power_mod(std::uint64_t e, std::uint64_t poly, int degree) {
  std::uint64_t result = 1, base = 2;  // base = x
  for (; e > 0; e >>= 1) {
    if (e & 1U) result = mulmod(result, base, poly, degree);
    base = mulmod(base, base, poly, degree);
  }
  return result;
}

// x has multiplicative order 2^n - 1 modulo P only when P is primitive.
bool is_primitive(std::uint64_t poly, int degree) {
  const std::uint64_t order = (std::uint64_t{1} << degree) - 1;
  if (x_power_mod(order, poly, degree) != 1) return false;
  for (int p : prime_factors(order))
    if (x_power_mod(order / static_cast<std::uint64_t>(p), poly, degree) == 1) return false;
  return true;
}

// Feedback taps as documented in signals.cpp (XAPP052); the generated
// sequence is checked to obey s_k = XOR_t s_{k-t}, so its characteristic
// polynomial x^n + sum_t x^(n-t) is the one proven primitive here.
constexpr std::array<std::array<int, 4>, 32> kTaps = {{
    {0, 0, 0, 0},   {0, 0, 0, 0},   {2, 1, 0, 0},    {3, 2, 0, 0},     {4, 3, 0, 0},   {5, 3, 0, 0},  {6, 5, 0, 0},
    {7, 6, 0, 0},   {8, 6, 5, 4},   {9, 5, 0, 0},    {10, 7, 0, 0},    {11, 9, 0, 0},  {12, 6, 4, 1}, {13, 4, 3, 1},
    {14, 5, 3, 1},  {15, 14, 0, 0}, {16, 15, 13, 4}, {17, 14, 0, 0},   {18, 11, 0, 0}, {19, 6, 2, 1}, {20, 17, 0, 0},
    {21, 19, 0, 0}, {22, 21, 0, 0}, {23, 18, 0, 0},  {24, 23, 22, 17}, {25, 22, 0, 0}, {26, 6, 2, 1}, {27, 5, 2, 1},
    {28, 25, 0, 0}, {29, 27, 0, 0}, {30, 6, 4, 1},   {31, 28, 0, 0},
}};

TEST(Signals, PrbsFeedbackIsPrimitiveForAllSizes) {
  // The check itself: x^4+x+1 is primitive; x^4+x^3+x^2+x+1 is irreducible of
  // order 5 and x^4+x^2+1 is reducible.
  EXPECT_TRUE(is_primitive(0b10011, 4));
  EXPECT_FALSE(is_primitive(0b11111, 4));
  EXPECT_FALSE(is_primitive(0b10101, 4));
  for (int bits = 2; bits <= 31; ++bits) {
    std::uint64_t poly = std::uint64_t{1} << bits;
    for (int t : kTaps[bits])
      if (t > 0) poly ^= std::uint64_t{1} << (bits - t);
    EXPECT_TRUE(is_primitive(poly, bits)) << bits << " bits";

    const Eigen::VectorXd y = generate(prbs_spec(bits), time_grid(20000, 1e-3));
    for (Eigen::Index k = bits; k < y.size(); ++k) {
      bool bit = false;
      for (int t : kTaps[bits])
        if (t > 0) bit ^= y(k - t) > 0.0;
      ASSERT_EQ(y(k) > 0.0, bit) << bits << " bits, sample " << k;
    }
  }
}

TEST(Signals, PrbsClockPeriodHoldsEachValue) {
  const Eigen::VectorXd fast = generate(prbs_spec(7), time_grid(127, 1e-3));
  const Eigen::VectorXd slow = generate(prbs_spec(7, 3), time_grid(381, 1e-3));
  for (Eigen::Index k = 0; k < slow.size(); ++k) ASSERT_EQ(slow(k), fast(k / 3)) << k;
  EXPECT_THROW(generate(prbs_spec(1), time_grid(10, 1e-3)), std::invalid_argument);
  EXPECT_THROW(generate(prbs_spec(32), time_grid(10, 1e-3)), std::invalid_argument);
  EXPECT_THROW(generate(prbs_spec(7, 0), time_grid(10, 1e-3)), std::invalid_argument);
}

// Input j of n starts j / n of a period in: the same sequence, shifted, and
// over a whole period the two are uncorrelated (an m-sequence's circular
// autocorrelation off zero lag is -1/N).
TEST(Signals, PrbsShiftStartsTheSameSequenceLaterAndDecorrelatesAWholePeriod) {
  const int N = 1023;
  const Eigen::VectorXd y = generate(prbs_spec(10), time_grid(2 * N, 1e-3));
  SignalSpec shifted = prbs_spec(10);
  shifted.prbs_shift = 511;
  const Eigen::VectorXd z = generate(shifted, time_grid(N, 1e-3));
  EXPECT_EQ(z, y.segment(511, N));
  const double a = shifted.amplitude;
  EXPECT_DOUBLE_EQ(y.head(N).dot(z) / N, -a * a / N);
  shifted.prbs_shift = -1;
  EXPECT_THROW(generate(shifted, time_grid(10, 1e-3)), std::invalid_argument);
}

TEST(Signals, SquareWaveLevelsAndMean) {
  SignalSpec s;
  s.kind = SignalSpec::Kind::square;
  s.frequency_hz = 2.0;
  s.amplitude = 1.5;
  s.offset = 0.2;
  Eigen::VectorXd t(5);
  t << 0.0, 0.1, 0.25, 0.3, 0.5;
  const Eigen::VectorXd y = generate(s, t);
  EXPECT_EQ(y(0), 1.7);
  EXPECT_EQ(y(1), 1.7);
  EXPECT_EQ(y(2), -1.3);
  EXPECT_EQ(y(3), -1.3);
  EXPECT_EQ(y(4), 1.7);
  // 4096 Hz, 2 Hz: 1024 samples per half period, so the mean over whole periods is the offset.
  const Eigen::VectorXd full = generate(s, time_grid(4096, 1.0 / 4096.0));
  EXPECT_NEAR(full.mean(), 0.2, 1e-12);
}

TEST(Signals, CsvIsNotGeneratedHere) {
  SignalSpec s;
  s.kind = SignalSpec::Kind::csv;
  s.csv_path = "r.csv";
  EXPECT_THROW(generate(s, time_grid(3, 0.1)), std::invalid_argument);
}

}  // namespace
}  // namespace modalwatch
