#pragma once
// Continuous-time prefilters on sampled data (DESIGN.md point 1).
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
// Time scaling (DESIGN.md point 3) is the caller's: pass D and T in normalised
// time (t' = ws t) and the derivatives come out in that time unit.
#include <Eigen/Core>

namespace modalwatch {

enum class Hold { zoh, foh };

// Largest filter order N supported without heap allocation.
inline constexpr int kMaxFilterOrder = 8;

using FilterVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxFilterOrder + 1, 1>;
using FilterMatrix =
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxFilterOrder, kMaxFilterOrder>;

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

// The closed form for N = 2, d_0 != 0, as plain numbers: for callers that
// re-discretise at every sample (the recursive estimator's modes), where
// Eigen's dynamic-size storage costs more than the arithmetic. discretize()
// returns exactly these numbers for such a D. gamma1 is the FOH term (a ZOH
// caller ignores it). Unchecked: d_0 != 0, d_2 != 0 and T > 0 are the caller's.
struct SecondOrderDiscretization {
  double phi[2][2];
  double gamma0[2];
  double gamma1[2];
};
SecondOrderDiscretization discretize_second_order(double d0, double d1, double d2, double T) noexcept;

// Prefilters 1/D(p) of one second-order D = d0 + d1 p + d2 p^2 (d0, d2 != 0)
// on kSignals held (ZOH) signals, sharing one discretisation: a mode's four
// prefilters in the recursive estimator, re-discretised at every update. Fixed
// size, the discretisation computed in place and never copied. The arithmetic
// is a Prefilter's per signal, in the same order, but for the top derivative:
// a product with 1/d2 in place of a division by d2 (equal to round-off).
// The states are stored signal by signal in arrays (x0[i], x1[i]), so that
// advance_all() moves the four of them in one loop the compiler vectorises.
class SecondOrderFilterBank {
 public:
  static constexpr int kSignals = 4;

  // Keeps the states (the parameters change only at sampling instants).
  // Unchecked: d0 != 0, d2 != 0, T > 0 (discretize_second_order).
  void set_denominator(double d0, double d1, double d2, double T) noexcept {
    set_denominator(d0, d1, d2, discretize_second_order(d0, d1, d2, T));
  }
  // The same with disc = discretize_second_order(d0, d1, d2, T) computed by the
  // caller (the estimator inlines it into its per-sample path).
  void set_denominator(double d0, double d1, double d2, const SecondOrderDiscretization& disc) noexcept {
    d_[0] = d0;
    d_[1] = d1;
    d_[2] = d2;
    inv_d2_ = 1.0 / d2;
    disc_ = disc;
  }
  void reset() noexcept {
    for (int i = 0; i < kSignals; ++i) {
      x0_[i] = x1_[i] = w_prev_[i] = 0.0;
      for (double& d : out_[i]) d = 0.0;
    }
  }
  // Prefilter::advance, complete, step and derivatives for signal i.
  // x(t_k) = phi x(t_{k-1}) + gamma0 w_{k-1}.
  void advance(int i) noexcept {
    const double x0 = disc_.gamma0[0] * w_prev_[i] + disc_.phi[0][0] * x0_[i] + disc_.phi[0][1] * x1_[i];
    const double x1 = disc_.gamma0[1] * w_prev_[i] + disc_.phi[1][0] * x0_[i] + disc_.phi[1][1] * x1_[i];
    x0_[i] = x0;
    x1_[i] = x1;
  }
  // advance(i) for every signal: the inputs are held, so all four states can
  // move to t_k before any of the new samples is known.
  void advance_all() noexcept {
    const double g0 = disc_.gamma0[0], g1 = disc_.gamma0[1];
    const double p00 = disc_.phi[0][0], p01 = disc_.phi[0][1], p10 = disc_.phi[1][0], p11 = disc_.phi[1][1];
    // Component by component, so that the loops run across the signals.
    double x0[kSignals], x1[kSignals];
    for (int i = 0; i < kSignals; ++i) x0[i] = g0 * w_prev_[i] + p00 * x0_[i] + p01 * x1_[i];
    for (int i = 0; i < kSignals; ++i) x1[i] = g1 * w_prev_[i] + p10 * x0_[i] + p11 * x1_[i];
    for (int i = 0; i < kSignals; ++i) {
      x0_[i] = x0[i];
      x1_[i] = x1[i];
    }
  }
  // [w_f, p w_f, p^2 w_f] at t_k with p^2 w_f = (w_k - d0 w_f - d1 p w_f) / d2.
  const double* complete(int i, double w) noexcept {
    double* out = out_[i];
    out[0] = x0_[i];
    out[1] = x1_[i];
    out[2] = (w - d_[0] * x0_[i] - d_[1] * x1_[i]) * inv_d2_;
    w_prev_[i] = w;
    return out;
  }
  // complete(i, w) but for the top derivative (derivatives(i)[2] is left as it
  // was): for a signal whose use needs only [w_f, p w_f], such as u and the
  // instrument input z of a mode whose B has degree < 2.
  const double* complete_state(int i, double w) noexcept {
    double* out = out_[i];
    out[0] = x0_[i];
    out[1] = x1_[i];
    w_prev_[i] = w;
    return out;
  }
  const double* step(int i, double w) noexcept {
    advance(i);
    return complete(i, w);
  }
  const double* derivatives(int i) const noexcept { return out_[i]; }

 private:
  double d_[3] = {1.0, 0.0, 1.0};
  double inv_d2_ = 1.0;
  SecondOrderDiscretization disc_{};
  // Per signal: the state [w_f, p w_f] at t_k, the held input, and the
  // derivatives [w_f, p w_f, p^2 w_f] at t_k.
  double x0_[kSignals] = {0.0, 0.0, 0.0, 0.0};
  double x1_[kSignals] = {0.0, 0.0, 0.0, 0.0};
  double w_prev_[kSignals] = {0.0, 0.0, 0.0, 0.0};
  double out_[kSignals][3] = {};
};

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
