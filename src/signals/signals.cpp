#include "modalwatch/signals.hpp"

#include <array>
#include <cmath>
#include <numbers>
#include <random>
#include <stdexcept>

namespace modalwatch {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

Eigen::VectorXd sum_of_sines(const SignalSpec& s, const Eigen::VectorXd& t) {
  if (s.amplitudes.size() != s.frequencies_rad_s.size())
    throw std::invalid_argument("sum_of_sines: amplitudes and frequencies differ in length");
  if (!s.phases.empty() && s.phases.size() != s.amplitudes.size())
    throw std::invalid_argument("sum_of_sines: phases must be empty or one per sine");
  Eigen::VectorXd y = Eigen::VectorXd::Zero(t.size());
  for (std::size_t k = 0; k < s.amplitudes.size(); ++k) {
    const double phase = s.phases.empty() ? 0.0 : s.phases[k];
    y += s.amplitudes[k] * (s.frequencies_rad_s[k] * t.array() + phase).sin().matrix();
  }
  return y;
}

// Uniform in [0, 2 pi) from the top 53 bits, so that a seed gives the same
// phases with any standard library (uniform_real_distribution is not portable).
double random_phase(std::mt19937_64& rng) { return kTwoPi * static_cast<double>(rng() >> 11) * 0x1.0p-53; }

Eigen::VectorXd multisine(const SignalSpec& s, const Eigen::VectorXd& t) {
  if (!(s.period_s > 0.0)) throw std::invalid_argument("multisine: period_s must be > 0");
  if (!(s.f_min_hz >= 0.0) || !(s.f_max_hz >= s.f_min_hz))
    throw std::invalid_argument("multisine: need 0 <= f_min_hz <= f_max_hz");
  // Lines k / period_s inside [f_min, f_max], DC excluded; the tolerance keeps
  // band edges that fall on the grid up to round-off.
  const long k_min = std::max(1L, static_cast<long>(std::ceil(s.f_min_hz * s.period_s - 1e-9)));
  const long k_max = static_cast<long>(std::floor(s.f_max_hz * s.period_s + 1e-9));
  if (k_max < k_min) throw std::invalid_argument("multisine: no frequency line in [f_min_hz, f_max_hz]");
  const long lines = k_max - k_min + 1;
  // Each cosine of amplitude A has power A^2/2: the sum has rms A sqrt(lines/2).
  const double amplitude = s.rms * std::sqrt(2.0 / static_cast<double>(lines));
  std::mt19937_64 rng(s.seed);
  Eigen::VectorXd y = Eigen::VectorXd::Zero(t.size());
  for (long k = k_min; k <= k_max; ++k) {
    const double w = kTwoPi * static_cast<double>(k) / s.period_s;
    y += amplitude * (w * t.array() + random_phase(rng)).cos().matrix();
  }
  return y;
}

// Feedback taps of maximum-length Fibonacci LFSRs, register_bits 2..31
// (Xilinx XAPP052 table; each is a primitive polynomial over GF(2)). Zero ends a list.
constexpr std::array<std::array<int, 4>, 32> kPrbsTaps = {{
    {0, 0, 0, 0},   {0, 0, 0, 0},   {2, 1, 0, 0},    {3, 2, 0, 0},     {4, 3, 0, 0},   {5, 3, 0, 0},  {6, 5, 0, 0},
    {7, 6, 0, 0},   {8, 6, 5, 4},   {9, 5, 0, 0},    {10, 7, 0, 0},    {11, 9, 0, 0},  {12, 6, 4, 1}, {13, 4, 3, 1},
    {14, 5, 3, 1},  {15, 14, 0, 0}, {16, 15, 13, 4}, {17, 14, 0, 0},   {18, 11, 0, 0}, {19, 6, 2, 1}, {20, 17, 0, 0},
    {21, 19, 0, 0}, {22, 21, 0, 0}, {23, 18, 0, 0},  {24, 23, 22, 17}, {25, 22, 0, 0}, {26, 6, 2, 1}, {27, 5, 2, 1},
    {28, 25, 0, 0}, {29, 27, 0, 0}, {30, 6, 4, 1},   {31, 28, 0, 0},
}};

// One LFSR bit per call: s_k = XOR over taps t of s_{k-t}. Bit (t-1) of the
// register holds s_{k-t}; the all-ones start is a nonzero state, so the
// sequence has period 2^bits - 1.
class Lfsr {
 public:
  explicit Lfsr(int bits) : taps_(kPrbsTaps[static_cast<std::size_t>(bits)]), mask_((1UL << bits) - 1), reg_(mask_) {}
  bool next() {
    unsigned long bit = 0;
    for (int tap : taps_)
      if (tap > 0) bit ^= (reg_ >> (tap - 1)) & 1UL;
    reg_ = ((reg_ << 1) | bit) & mask_;
    return bit != 0;
  }

 private:
  std::array<int, 4> taps_;
  unsigned long mask_;
  unsigned long reg_;
};

Eigen::VectorXd prbs(const SignalSpec& s, const Eigen::VectorXd& t) {
  if (s.register_bits < 2 || s.register_bits > 31) throw std::invalid_argument("prbs: register_bits must be in 2..31");
  if (s.clock_period < 1) throw std::invalid_argument("prbs: clock_period must be >= 1");
  if (s.prbs_shift < 0) throw std::invalid_argument("prbs: prbs_shift must be >= 0");
  Lfsr lfsr(s.register_bits);
  for (long long k = 0; k < s.prbs_shift; ++k) lfsr.next();
  Eigen::VectorXd y(t.size());
  double level = 0.0;
  for (Eigen::Index k = 0; k < t.size(); ++k) {
    if (k % s.clock_period == 0) level = lfsr.next() ? s.amplitude : -s.amplitude;
    y(k) = level;
  }
  return y;
}

// amplitude * sign(sin(2 pi f t)) + offset, from the fractional phase so that
// half-period instants land on the next level instead of on sin's round-off.
Eigen::VectorXd square(const SignalSpec& s, const Eigen::VectorXd& t) {
  if (!(s.frequency_hz > 0.0)) throw std::invalid_argument("square: frequency_hz must be > 0");
  Eigen::VectorXd y(t.size());
  for (Eigen::Index k = 0; k < t.size(); ++k) {
    const double cycles = s.frequency_hz * t(k);
    const double fraction = cycles - std::floor(cycles);
    y(k) = s.offset + (fraction < 0.5 ? s.amplitude : -s.amplitude);
  }
  return y;
}

}  // namespace

Eigen::VectorXd generate(const SignalSpec& spec, const Eigen::VectorXd& t) {
  switch (spec.kind) {
    case SignalSpec::Kind::sum_of_sines:
      return sum_of_sines(spec, t);
    case SignalSpec::Kind::multisine:
      return multisine(spec, t);
    case SignalSpec::Kind::prbs:
      return prbs(spec, t);
    case SignalSpec::Kind::square:
      return square(spec, t);
    case SignalSpec::Kind::csv:
      break;
  }
  throw std::invalid_argument("generate: csv signals are read by the I/O layer, not generated");
}

}  // namespace modalwatch
