#pragma once
// A block (one submodel of the additive model) as the recursive estimator
// keeps it: theta-bar and P-bar in normalised time, and its four prefilters.
#include <cmath>

#include <Eigen/Core>

#include "hot_path.hpp"
#include "modalwatch/prefilter.hpp"
#include "second_order_filter_bank.hpp"

namespace modalwatch::detail {

// theta_i has at most n + m + 1 <= 2 kMaxFilterOrder + 1 entries; fixed capacity
// keeps step() free of heap allocation.
constexpr int kMaxTheta = 2 * kMaxFilterOrder + 1;
using ThetaVec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxTheta, 1>;
using ThetaMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxTheta, kMaxTheta>;

// The prefilters of a block (eqs. 19-20, 29, 32-33): 1/A on the residual
// output (kY) and on the auxiliary output (kX, the instrument), 1/(p^l A) on u
// (kU) and on the instrument input z (kZ).
enum Channel { kY = 0, kX = 1, kU = 2, kZ = 3 };

// A block's four prefilters. A mode (n = 2, no rigid poles) with a held output
// (ZOH) filters all four signals through 1/A(p) with the same hold, so one
// discretisation serves them (the signal enters only through the held input,
// so the filter's matrices are the same for all four): a SecondOrderFilterBank,
// re-discretised in place as theta moves (the estimator's inner loop).
// Otherwise four Prefilters (rigid-body submodels, FOH output, other orders).
struct BlockFilters {
  bool shared = false;
  // The block's output B/(p^l A) w uses p^N w_f of u and z only when biproper
  // (m = n + l); the shared bank leaves it out otherwise.
  bool input_top = true;
  SecondOrderFilterBank mode;
  Prefilter f[4];

  void init(const FilterVector& a, const FilterVector& den, double T, Hold output_hold, bool biproper) {
    shared = a.size() == 3 && den.size() == 3 && output_hold == Hold::zoh;
    input_top = biproper || !shared;
    if (shared) {
      if (a(2) == 0.0) throw std::invalid_argument("discretize: leading coefficient is zero");
      mode = SecondOrderFilterBank{};
      mode.set_denominator(a(0), a(1), a(2), T);
      for (auto& p : f) p = Prefilter();
      return;
    }
    f[kY] = Prefilter(a, T, output_hold);
    f[kX] = Prefilter(a, T, output_hold);
    f[kU] = Prefilter(den, T, Hold::zoh);
    f[kZ] = Prefilter(den, T, Hold::zoh);
  }
  void reset() {
    if (shared) {
      mode.reset();
      return;
    }
    for (auto& p : f) p.reset();
  }
  // A sample t_k in two phases. begin_sample() moves the held-input states to
  // t_k: all four at once for a mode (one vectorised loop); Prefilters (a FOH
  // output needs w_k) wait for their sample. take(c, w) then gives channel c's
  // derivatives at t_k for w_k (Prefilter::step for those that waited).
  // advance_held(c) + complete(c, w) is take() split for the instrument input,
  // whose w_k is solved for after its free response is known.
  MODALWATCH_HOT void begin_sample() {
    if (shared) mode.advance_all();
  }
  MODALWATCH_HOT const double* take(Channel c, double w) { return shared ? mode.complete(c, w) : f[c].step(w).data(); }
  MODALWATCH_HOT void advance_held(Channel c) {
    if (!shared) f[c].advance();
  }
  MODALWATCH_HOT const double* complete(Channel c, double w) {
    return shared ? mode.complete(c, w) : f[c].complete(w).data();
  }
  // take() and complete() for the input channels kU and kZ, whose derivatives
  // the block uses up to p^m only (fill(), output()).
  MODALWATCH_HOT const double* take_input(Channel c, double w) {
    return input_top ? take(c, w) : mode.complete_state(c, w);
  }
  MODALWATCH_HOT const double* complete_input(Channel c, double w) {
    return input_top ? complete(c, w) : mode.complete_state(c, w);
  }
  MODALWATCH_HOT const double* derivatives(Channel c) const {
    return shared ? mode.derivatives(c) : f[c].derivatives().data();
  }
};

// Per-direction bound on a symmetric P (nt x nt, column-major): D P D with
// D = diag(min(1, sqrt(bound/P_jj))) keeps P symmetric positive definite while
// stopping wind-up in unexcited directions. D_jj scales row j and mirrors it
// into column j, and P_jj becomes D_jj^2 P_jj = bound_j. N > 0 fixes nt at
// compile time (as iv_update). True when a direction was bounded.
template <int N>
MODALWATCH_HOT bool bound_covariance(double* P, const double* bound, int nt_runtime) {
  const int nt = N > 0 ? N : nt_runtime;
  bool clamped = false;
  for (int j = 0; j < nt; ++j) {
    if (P[j + j * nt] > bound[j]) {
      const double f = std::sqrt(bound[j] / P[j + j * nt]);
      for (int k = 0; k < nt; ++k) {
        if (k == j) continue;
        P[j + k * nt] *= f;
        P[k + j * nt] = P[j + k * nt];
      }
      P[j + j * nt] = bound[j];
      clamped = true;
    }
  }
  return clamped;
}

struct Block {
  int n = 0, m = 0, l = 0, nt = 0;
  int z = 0;              // the output is p^z times the position response (Submodel::output_derivatives)
  int input = 0;          // the measured input that drives it (Submodel::input)
  bool biproper = false;  // m + z = n + l: the output has a direct feedthrough
  // The common cases without loops: B = b0 on a position output (output()),
  // and a mode so (fill()).
  bool b0_position = true;    // m = 0, z = 0
  bool position_mode = true;  // n = 2, m = 0, z = 0
  double ws = 1.0, lambda = 1.0;
  double lambda_now = 1.0;  // the forgetting of the last update (lambda held by min_memory)
  double random_walk = 0.0;  // relative std of theta's drift per update (Q, CONTSID's Kalman-filter adaptation)
  // update_divisor T / min_memory (s): 1 - lambda may not exceed this times
  // decay_rate() (EstimatorSettings::min_memory); 0: lambda as configured.
  double forget_per_decay = 0.0;
  // The same at settled_memory: the floor while the block is not adapting.
  double settled_forget_per_decay = 0.0;
  ThetaVec scale;            // theta' = scale .* theta (physical)
  ThetaVec theta;            // theta-bar, normalised
  ThetaMat P;                // P-bar, normalised
  // Per-direction bound on diag(P): covariance_bound x its reference, diag(P(t0))
  // or what one memory of the warm-up window gives (Impl::build).
  ThetaVec p_bound;
  // The bound that applies now: p_bound, lifted by a change boost's factor for
  // one memory of the block after it (lift_bound()), while the boosted P
  // re-converges; without the lift the bound would undo the boost.
  ThetaVec p_limit;
  std::uint64_t lifted = 0;  // updates left with the lifted bound
  void lift_bound(double factor, std::uint64_t updates) {
    p_limit = factor * p_bound;
    lifted = updates;
  }
  void drop_lift() {
    p_limit = p_bound;
    lifted = 0;
  }
  // Stabilised forgetting: off, waiting for sigma^2 (P_ref needs it), or on.
  enum class Stabilisation : unsigned char { off, pending, on };
  Stabilisation stabilisation = Stabilisation::off;
  double stabilisation_ratio = 0.0;  // P_ref's relative std (EstimatorSettings::stabilisation)
  ThetaVec theta_ref;                // normalised
  // P_ref_j / (K nt (1 - lambda)): the variance of the pseudo-measurement
  // theta_ref_j that gives theta_j back, once every K nt updates (K blocks), the
  // information K nt (1 - lambda) / P_ref_j forgotten over those updates.
  ThetaVec ref_var;
  BlockFilters filters;
  // The a_1 (damping term) of a mode's prefilters and auxiliary model, which
  // follows theta's only past a deadband (Impl::follow).
  double filter_a1 = 0.0;
  // The prefilters take theta's a_1 as it is (a start, a restore, a boost).
  void filter_takes_damping() {
    if (n == 2) filter_a1 = theta(0);
  }
  // phi^T P psi / (lambda + phi^T P psi) of the last update: how much of the
  // error it took into theta (near 1 at a start or after a boost, about nt over
  // the memory once settled).
  double update_gain = 1.0;
  double xu = 0.0, xz = 0.0;  // B/(p^l A) driven by u and by z, at t_k
  ThetaVec good_theta;
  ThetaMat good_P;
  ThetaVec phi, psi;
  // What not knowing the other blocks adds to P (normalised): JointInformation's C_i.
  ThetaMat cross;
  // The estimate's sampling covariance (normalised, over sigma^2): block (i, i)
  // of JointInformation's (J + R)^-1 J (J + R)^-1, while JointInformation::current().
  ThetaMat sampling;
  // The output error's correlation with this block's instrument over e_short's
  // window, and the instrument's own (upper triangle): the score test's sums,
  // which blocks a change of the output error belongs to (boost_changed_blocks).
  ThetaVec score;
  ThetaMat score_info;
  // The change test's last alarm named this block (boost_changed_blocks);
  // updates left during which it keeps its estimate while named ones
  // re-converge (held), or during which it re-converges itself (adapting).
  bool named = false;
  // Until this many updates (EstimatorStatus::updates) its floor is
  // min_memory, not the settled floor: while it adapts, or after an alarm
  // that boosted no block released it (boost_changed_blocks).
  std::uint64_t min_floor_until = 0;
  std::uint64_t held = 0, adapting = 0;

  // Decay rate (1/s) of the slowest pole of A when A is of first or second
  // order, stable, and the submodel has no rigid poles; else 0 (no such bound).
  // In normalised time A = 1 + theta_0 p' (+ theta_1 p'^2), p' = p / ws.
  // Pole::fastest: the faster of two real poles instead (a pair decays as one).
  enum class Pole : unsigned char { slowest, fastest };
  MODALWATCH_HOT double decay_rate(Pole which = Pole::slowest) const {
    if (l != 0 || !(theta(0) > 0.0)) return 0.0;
    if (n == 1) return ws / theta(0);
    if (n != 2 || !(theta(1) > 0.0)) return 0.0;
    const double a1 = theta(0), a2 = theta(1);
    const double disc = a1 * a1 - 4.0 * a2;
    if (disc < 0.0) return ws * a1 / (2.0 * a2);
    const double root = std::sqrt(disc);
    return ws * (which == Pole::slowest ? a1 - root : a1 + root) / (2.0 * a2);
  }
  // theta' = scale .* theta for the time scale ws (t' = ws t): a_j ws^j and
  // b_k ws^(k+z-l).
  void set_scale() {
    scale.resize(nt);
    for (int j = 1; j <= n; ++j) scale(j - 1) = std::pow(ws, j);
    for (int k = 0; k <= m; ++k) scale(n + k) = std::pow(ws, k + z - l);
  }
  FilterVector a_poly() const {
    FilterVector c(n + 1);
    c(0) = 1.0;
    c.tail(n) = theta.head(n);
    return c;
  }
  // The prefilters' A: theta's, but for a mode's a_1 (filter_a1, Impl::follow).
  FilterVector filter_a_poly() const {
    FilterVector c = a_poly();
    if (n == 2) c(1) = filter_a1;
    return c;
  }
  FilterVector filter_denominator() const {
    FilterVector c = FilterVector::Zero(n + l + 1);
    c.tail(n + 1) = filter_a_poly();
    return c;
  }
  // p^z B/(p^l A) w from the filter's derivatives d = [w_f, p w_f, ...].
  MODALWATCH_HOT double output(const double* d) const {
    if (b0_position) return theta(n) * d[0];  // a mode's B = b0 (the common case)
    double s = 0.0;
    for (int k = z; k <= m + z; ++k) s += theta(n - z + k) * d[k];  // b_j on p^(j+z)
    return s;
  }
  // Regressor (eqs. 19, 33) and instrument (eqs. 20, 29, 32) from the filtered
  // residual output dy, auxiliary output dx, input du and instrument input dz;
  // b_k's are the input's (k+z)-th derivatives.
  MODALWATCH_HOT void fill(const double* dy, const double* dx, const double* du, const double* dz) {
    if (position_mode) {  // a mode (the common case), without the loops
      phi(0) = -dy[1];
      phi(1) = -dy[2];
      phi(2) = du[0];
      psi(0) = -dx[1];
      psi(1) = -dx[2];
      psi(2) = dz[0];
      return;
    }
    for (int j = 1; j <= n; ++j) {
      phi(j - 1) = -dy[j];
      psi(j - 1) = -dx[j];
    }
    for (int k = z; k <= m + z; ++k) {  // b_j on p^(j+z)
      phi(n - z + k) = du[k];
      psi(n - z + k) = dz[k];
    }
  }
  MODALWATCH_HOT double feedthrough() const { return biproper ? theta(n + m) / (n > 0 ? theta(n - 1) : 1.0) : 0.0; }
};

}  // namespace modalwatch::detail
