#pragma once
// A mode's four prefilters sharing one discretisation (private to the
// estimator, which re-discretises them as theta moves).
#include "modalwatch/prefilter.hpp"

namespace modalwatch::detail {

// Prefilters 1/D(p) of one second-order D = d0 + d1 p + d2 p^2 (d0, d2 != 0)
// on kSignals held (ZOH) signals, sharing one discretisation: a mode's four
// prefilters in the recursive estimator, re-discretised as theta moves. Fixed
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

}  // namespace modalwatch::detail
