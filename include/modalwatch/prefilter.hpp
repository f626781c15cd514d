#pragma once
// Continuous-time prefilters on sampled data: the filters 1/A(p) and
// 1/(p^l A(p)) through which the estimator sees the signals (eqs. 19-20).
//
// The filter 1/D(p), D(p) = d_0 + d_1 p + ... + d_N p^N (for a submodel,
// D = p^l A(p)), is simulated in controllable canonical form: its state is
// x = [w_f, p w_f, ..., p^{N-1} w_f] with w_f = w / D. The top derivative is not
// integrated but follows algebraically from the current sample,
//
//   p^N w_f(t_k) = (w(t_k) - sum_{j<N} d_j p^j w_f(t_k)) / d_N,
//
// so that sum_j d_j p^j w_f(t_k) = w(t_k) exactly. The filter is discretised
// exactly (matrix exponential) for the assumed intersample behaviour of w:
// held (ZOH) or linearly interpolated (FOH).
//
// Time scaling is the caller's: pass D and T in normalised time (t' = ws t,
// which keeps the coefficients of D near 1 and the discretisation well
// conditioned) and the derivatives come out in that time unit.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>

#include <Eigen/Core>

namespace modalwatch {

enum class Hold { zoh, foh };
// Its name in the configuration (model.output_hold) and in logs.
inline const char* hold_name(Hold h) noexcept { return h == Hold::foh ? "foh" : "zoh"; }

// Largest filter order N supported without heap allocation.
inline constexpr int kMaxFilterOrder = 8;

using FilterVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxFilterOrder + 1, 1>;
using FilterMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxFilterOrder, kMaxFilterOrder>;

// x(t_{k+1}) = phi x(t_k) + gamma0 w_k + gamma1 (w_{k+1} - w_k)
// (gamma1 = 0 for ZOH).
struct Discretization {
  FilterMatrix phi;
  FilterVector gamma0;
  FilterVector gamma1;
};

// Exact discretisation of 1/D(p) with sample time T. N = 1 and N = 2 with
// d_0 != 0 use closed forms (no general matrix exponential); other orders use
// the matrix exponential of an augmented matrix.
Discretization discretize(const Eigen::Ref<const Eigen::VectorXd>& denominator, double T, Hold hold);

// The closed form for N = 2, d_0 != 0, as plain numbers (discretize_second_order
// below): for callers that re-discretise as often as theta moves (the recursive
// estimator's modes), where Eigen's dynamic-size storage costs more than the
// arithmetic. discretize() returns exactly these numbers for such a D. gamma1
// is the FOH term (a ZOH caller ignores it). Unchecked: d_0 != 0, d_2 != 0 and
// T > 0 are the caller's.
struct SecondOrderDiscretization {
  double phi[2][2];
  double gamma0[2];
  double gamma1[2];
};

namespace detail {

// 2x2 matrices as four scalars: the per-sample re-discretisation of a mode runs
// in the recursive estimator's inner loop, where dynamic-size Eigen costs more
// than the arithmetic.
struct M2 {
  double a, b, c, d;  // [[a, b], [c, d]]
};

// 1/k! and 1e-18 k! for k = 0..39: the series below without divisions.
struct FactorialTables {
  double inverse[40];
  double tolerance[40];
};
constexpr FactorialTables factorial_tables() {
  FactorialTables t{};
  double f = 1.0;
  for (int k = 0; k < 40; ++k) {
    if (k > 0) f *= k;
    t.inverse[k] = 1.0 / f;
    t.tolerance[k] = 1e-18 * f;
  }
  return t;
}
inline constexpr FactorialTables kFactorial = factorial_tables();

// The length of phi's series, sum_{k <= J} (AT)^k/k!, by quarter binade of
// |AT| < 2: for |AT| = 2^-i (1 + f) with q = floor(4 f), the J at the interval's
// top, u = 2^-i (1 + (q + 1)/4), whose next term, u^(J+1)/(J+1)!, is below 1e-18
// (the term count then costs one table look-up instead of a loop, and is never
// more than a quarter binade's worth above what |AT| itself needs).
struct SeriesLengths {
  int last_term[64 * 4];
};
constexpr SeriesLengths series_lengths() {
  SeriesLengths t{};
  double binade = 1.0;  // 2^-i
  for (int i = 0; i < 64; ++i) {
    for (int q = 0; q < 4; ++q) {
      const double top = binade * (1.0 + (q + 1) / 4.0);
      int J = 0;
      for (double power = top; J < 34 && power >= kFactorial.tolerance[J + 1]; power *= top) ++J;
      t.last_term[4 * i + q] = J;
    }
    binade *= 0.5;
  }
  return t;
}
inline constexpr SeriesLengths kSeriesLength = series_lengths();
// Index of |AT| in (0, 2) into SeriesLengths: 4 i + q from the exponent and the
// top two mantissa bits (below 2^-63 the last entry, which over-covers).
inline int series_index(double norm) {
  const std::uint64_t bits = std::bit_cast<std::uint64_t>(norm);
  const int i = 1023 - static_cast<int>((bits >> 52) & 0x7ff);  // norm in [2^-i, 2^(1-i)): i >= 0
  return i > 63 ? 4 * 63 + 3 : 4 * i + static_cast<int>((bits >> 50) & 3);
}

// The branch for |A T| >= 2 (exp and sincos of the eigenvalues), out of line:
// the estimator's modes stay below (normalised time, |A T| ~ w T).
SecondOrderDiscretization discretize_second_order_closed_form(double d0, double d1, double d2, double T) noexcept;

}  // namespace detail

// N = 2, d_0 != 0. For |A T| < 2 the Taylor series of exp(A T) and of the
// input integrals (below 1 the A^{-1} forms would cancel; up to 2 the series is
// still exact to round-off and costs less than exp and sincos); above, the
// closed form. B = [0, 1/d2]. Inline: the recursive estimator compiles its
// per-sample path once per instruction set (portable and AVX2+FMA) and needs
// the body where it re-discretises.
[[gnu::always_inline]] inline SecondOrderDiscretization discretize_second_order(double d0, double d1, double d2,
                                                                                double T) noexcept {
  const double bB = 1.0 / d2;
  const detail::M2 AT{0.0, T, -d0 / d2 * T, -d1 / d2 * T};
  const double norm = std::max(std::abs(AT.b), std::abs(AT.c) + std::abs(AT.d));
  if (!(norm < 2.0)) return detail::discretize_second_order_closed_form(d0, d1, d2, T);
  SecondOrderDiscretization z;
  // Taylor: phi = sum (AT)^k/k!, Psi0 = sum (AT)^k/(k+1)!, Psi1 = sum (AT)^k/(k+2)!,
  // phi's terms while |AT|^k/k! >= 1e-18 (J <= 25). Only the second
  // columns are needed (B = e2/d2), in Horner form: s1 = Psi1 e2, then
  // s0 = Psi0 e2 = e2 + AT s1 and phi e2 = e2 + AT s0; the first column of phi
  // from phi = c0 I + c1 AT (Cayley-Hamilton): c1 = phi_01/T, c0 = phi_11 - c1 AT_11.
  // Up to |AT| = 2 the terms stay below 2 and their sum below e^2, so the
  // series is as accurate as the closed form and cheaper than its
  // exp and sincos (the estimator's fastest mode sits at |AT| ~ 1.2).
  const int J = detail::kSeriesLength.last_term[detail::series_index(norm)];  // phi's last term (AT)^J/J!
  // Psi1's last term (AT)^K/(K+2)!. The first components of the columns start
  // at order |AT| (gamma0_0, gamma1_0 ~ T^2): K = J + 1 keeps them accurate
  // relative to themselves, not only to the largest entry.
  //
  // Horner: (v0, v1) <- AT (v0, v1) + e2/(k+2)! for k = K-1..0 from
  // (0, 1/(K+2)!). As AT's first row is [0, T], v0 is always T times the
  // previous v1, so v1 alone follows the two-term recurrence
  //   u_k = (AT_10 T) u_{k+2} + AT_11 u_{k+1} + 1/(k+2)!,  u_K = 1/(K+2)!, u_{K+1} = 0,
  // and s1 = (T u_1, u_0). K is rounded up to even (the extra term is below
  // 1e-18) so that the steps go two at a time, and after the first two when
  // K = 2 mod 4, four at a time.
  const int K = (J + 2) & ~1;
  const double cb = AT.c * AT.b;
  double u2 = 0.0, u1 = detail::kFactorial.inverse[K + 2];  // u_{k+2}, u_{k+1}
  int k = K - 1;
  if (K & 2) {
    u2 = cb * u2 + AT.d * u1 + detail::kFactorial.inverse[k + 2];  // u_k
    u1 = cb * u1 + AT.d * u2 + detail::kFactorial.inverse[k + 1];  // u_{k-1}
    k -= 2;
  }
  for (; k > 0; k -= 4) {
    u2 = cb * u2 + AT.d * u1 + detail::kFactorial.inverse[k + 2];  // u_k
    u1 = cb * u1 + AT.d * u2 + detail::kFactorial.inverse[k + 1];  // u_{k-1}
    u2 = cb * u2 + AT.d * u1 + detail::kFactorial.inverse[k];      // u_{k-2}
    u1 = cb * u1 + AT.d * u2 + detail::kFactorial.inverse[k - 1];  // u_{k-3}
  }
  const double v0 = AT.b * u2, v1 = u1;                             // s1 = Psi1 e2
  const double s0 = AT.b * v1, s1 = 1.0 + AT.c * v0 + AT.d * v1;    // Psi0 e2
  const double p01 = AT.b * s1, p11 = 1.0 + AT.c * s0 + AT.d * s1;  // phi e2
  const double c1 = p01 / AT.b, c0 = p11 - c1 * AT.d;
  z.phi[0][0] = c0;
  z.phi[0][1] = p01;
  z.phi[1][0] = c1 * AT.c;
  z.phi[1][1] = p11;
  z.gamma0[0] = T * s0 * bB;
  z.gamma0[1] = T * s1 * bB;
  z.gamma1[0] = T * v0 * bB;
  z.gamma1[1] = T * v1 * bB;
  return z;
}

class Prefilter {
 public:
  Prefilter() = default;
  Prefilter(const Eigen::Ref<const Eigen::VectorXd>& denominator, double T, Hold hold);

  // Re-discretises for a new denominator of the same order, keeping the state
  // (the parameters are assumed to change only at sampling instants).
  void set_denominator(const Eigen::Ref<const Eigen::VectorXd>& denominator);
  // The same with a discretisation already computed for this denominator, T and
  // hold (filters sharing a denominator discretise once).
  void set_denominator(const Eigen::Ref<const Eigen::VectorXd>& denominator, const Discretization& discretization);
  const Discretization& discretization() const { return disc_; }
  void reset();  // zero state, zero past input

  // Advances from t_{k-1} to t_k with the new sample w_k and returns
  // [w_f, p w_f, ..., p^N w_f] at t_k (size N+1).
  const FilterVector& step(double w);

  // step(w) in two phases, for algebraic loops (a biproper controller around a
  // plant with feedthrough): advance() moves the state to t_k with the held
  // input (ZOH only); complete(w) then sets the derivatives for the sample w_k
  // and may be called again with a corrected w_k.
  void advance();
  const FilterVector& complete(double w);
  const FilterVector& derivatives() const { return out_; }

  // Output of B(p)/D(p) from the current derivatives: sum_j b_j p^j w_f.
  double combine(const Eigen::Ref<const Eigen::VectorXd>& b) const;

  int order() const { return order_; }
  double sample_time() const { return T_; }
  Hold hold() const { return hold_; }
  const FilterVector& state() const { return x_; }
  void set_state(const FilterVector& x, double previous_input);
  double previous_input() const { return w_prev_; }

 private:
  void propagate(double w_next);

  int order_ = 0;
  double T_ = 0.0;
  Hold hold_ = Hold::zoh;
  FilterVector d_;  // denominator, ascending
  Discretization disc_;
  FilterVector x_;
  FilterVector out_;
  double w_prev_ = 0.0;
};

}  // namespace modalwatch
