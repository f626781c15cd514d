#pragma once
// The parameter update of one block, eqs. (23)-(25), with the guards that act
// on its result (stability projection, random walk, covariance bound). Part of
// the per-sample path: included by step.cpp only (hot_path.hpp).
#include <algorithm>
#include <cmath>

#include <Eigen/Core>

#include "impl.hpp"
#include "modalwatch/polynomial.hpp"

namespace modalwatch {
namespace {

using detail::kMaxTheta;

// Stability projection of an anti-monic A (section 4.7), in place: false when A
// was stable or cannot be projected. Orders 1 and 2 in closed form without
// allocation; higher orders through the general routine (allocates, only when
// A is unstable). Out of line, with the per-sample path (never inlined there).
bool project(double* a_part, int n) {
  constexpr double margin = 1e-6;
  if (n == 1) {
    if (a_part[0] > 0.0) return false;
    a_part[0] = a_part[0] < 0.0 ? -a_part[0] : margin;
    return true;
  }
  if (n == 2) {
    double& a1 = a_part[0];
    double& a2 = a_part[1];
    if (a1 > 0.0 && a2 > 0.0) return false;
    if (a2 > 0.0) {
      // Both roots in the closed right half plane: reflecting both flips their sum.
      a1 = a1 < 0.0 ? -a1 : 2.0 * margin * std::sqrt(a2);
    } else if (a2 < 0.0) {
      // Real roots of opposite sign: reflect the positive one.
      a1 = std::sqrt(a1 * a1 - 4.0 * a2);
      a2 = -a2;
    } else {
      return false;  // degenerate (order drop): caller rejects
    }
    return true;
  }
  Eigen::Map<Eigen::VectorXd> part(a_part, n);
  Eigen::VectorXd a = part;
  if (!project_stable(a)) return false;
  part = a;
  return true;
}

// eqs. (23)-(25) on raw column-major storage (P is nt x nt, leading dimension nt):
// K = P psi / (lambda + phi^T P psi), theta += K eps with eps = y_f - phi^T theta,
// P = (P - K phi^T P) / lambda, and update_gain = phi^T K. The IV recursion
// (eq. 24) does not keep P symmetric; its symmetric part is kept, against
// round-off that would otherwise make P indefinite over millions of updates:
// P = (P - (K w^T + w K^T)/2) / lambda with w = P^T phi = P phi (P symmetric on
// entry), computed on the upper triangle and mirrored. N > 0 fixes the size at
// compile time so that the loops unroll (N = 3: a mode, the common case); N = 0
// takes nt at run time. phi and psi are the caller's local copies: were they
// the block's, every store to theta or P could alias them and force reloads.
template <int N>
MODALWATCH_HOT bool iv_update(int nt_runtime, double* P, double* theta, const double* phi, const double* psi,
                              double lambda, double eps, double& update_gain) {
  const int nt = N > 0 ? N : nt_runtime;
  double Ppsi[kMaxTheta], w[kMaxTheta];
  for (int i = 0; i < nt; ++i) Ppsi[i] = w[i] = 0.0;
  for (int j = 0; j < nt; ++j) {  // by columns: P psi and P phi
    const double* column = P + j * nt;
    for (int i = 0; i < nt; ++i) {
      Ppsi[i] += column[i] * psi[j];
      w[i] += column[i] * phi[j];
    }
  }
  double denom = lambda;
  for (int i = 0; i < nt; ++i) denom += phi[i] * Ppsi[i];
  if (!std::isfinite(denom) || std::abs(denom) < 1e-300) return false;
  update_gain = 1.0 - lambda / denom;
  const double inv_lambda = 1.0 / lambda;
  double K_half[kMaxTheta];  // K / 2 (exact): the symmetric part's 1/2 taken once
  for (int i = 0; i < nt; ++i) {
    const double K = Ppsi[i] / denom;
    theta[i] += K * eps;
    K_half[i] = 0.5 * K;
  }
  for (int j = 0; j < nt; ++j) {
    for (int i = 0; i <= j; ++i) {
      const double v = (P[i + j * nt] - (K_half[i] * w[j] + K_half[j] * w[i])) * inv_lambda;
      P[i + j * nt] = v;
      P[j + i * nt] = v;
    }
  }
  return true;
}

// Stabilised forgetting (Kulhavy & Zarrop 1993) on coordinate j: the
// information R = P^-1 gets 1/ref_var back in direction j, R' = R + e_j e_j^T /
// ref_var, and theta = R'^-1 (R theta + e_j theta_ref_j / ref_var): a scalar
// pseudo-measurement theta_ref_j of theta_j with variance ref_var, a rank-one
// update of P (symmetric on entry, kept so on the upper triangle).
template <int N>
MODALWATCH_HOT void stabilise(int nt_runtime, double* P, double* theta, int j, double theta_ref, double ref_var) {
  const int nt = N > 0 ? N : nt_runtime;
  double c[kMaxTheta];
  for (int i = 0; i < nt; ++i) c[i] = P[i + j * nt];
  const double inv = 1.0 / (ref_var + c[j]);
  const double g = (theta_ref - theta[j]) * inv;
  for (int i = 0; i < nt; ++i) theta[i] += c[i] * g;
  for (int k = 0; k < nt; ++k) {
    const double ck = c[k] * inv;
    for (int i = 0; i <= k; ++i) {
      const double v = P[i + k * nt] - c[i] * ck;
      P[i + k * nt] = v;
      P[k + i * nt] = v;
    }
  }
}

}  // namespace

// One block's update from theta-bar(t_{k-1}), P-bar(t_{k-1}); the filtered
// regressor phi and instrument psi are already in b.
inline bool RecursiveEstimator::Impl::update_block(detail::Block& b, double y_f) {
  return b.nt == 3 ? update_block_n<3>(b, y_f) : update_block_n<0>(b, y_f);
}

// On raw storage, with nt fixed at compile time for N > 0 (as iv_update): at
// nt = 3 Eigen's dynamic-size copies and row/column operations cost more than
// the arithmetic.
template <int N>
inline bool RecursiveEstimator::Impl::update_block_n(detail::Block& b, double y_f) {
  const int nt = N > 0 ? N : b.nt;
  // In place: on a false return the caller goes back to the last good state.
  double* P = b.P.data();  // nt x nt, column-major
  double* theta = b.theta.data();
  // Forgetting no faster than settled_memory decay times of A, min_memory while
  // re-converging after a change boost or released from the settled floor
  // (EstimatorSettings::settled_memory, boost_changed_blocks).
  double lambda = b.lambda;
  if (b.forget_per_decay > 0.0) {
    const double rate = b.decay_rate();
    const double per_decay = status.updates < b.min_floor_until ? b.forget_per_decay : b.settled_forget_per_decay;
    if (rate > 0.0) lambda = std::max(lambda, 1.0 - per_decay * rate);
  }
  b.lambda_now = lambda;
  // phi and psi copied once, for the score test's sums and iv_update: stores
  // to score, info, theta and P could alias the block's own and force reloads.
  double phi[detail::kMaxTheta], psi[detail::kMaxTheta];
  for (int i = 0; i < nt; ++i) {
    phi[i] = b.phi(i);
    psi[i] = b.psi(i);
  }
  double eps = y_f;  // the error before this update
  for (int i = 0; i < nt; ++i) eps -= phi[i] * theta[i];
  {  // The score test's sums (boost_changed_blocks).
    const double rho = e_short_alpha;
    double* score = b.score.data();
    double* info = b.score_info.data();
    for (int i = 0; i < nt; ++i) score[i] = rho * score[i] + psi[i] * eps;
    for (int j = 0; j < nt; ++j)  // the upper triangle: it is symmetric
      for (int i = 0; i <= j; ++i) info[i + j * nt] = rho * info[i + j * nt] + psi[i] * psi[j];
  }
  if (b.held > 0) return true;  // another block re-converges after a change (boost_changed_blocks)
  if (!iv_update<N>(nt, P, theta, phi, psi, lambda, eps, b.update_gain)) return false;
  // Stabilised forgetting on one block per update and one of its coordinates
  // per round, in turn (the same for every refinement of a sample), with K nt
  // times the information per update (set_reference_variance). P_ref needs
  // sigma^2: the warm-up's fit, or the first residuals without a warm-up; then
  // it stays fixed, as theta_ref.
  using Stabilisation = detail::Block::Stabilisation;
  if (&b == &blocks[stabilise_block] && b.stabilisation != Stabilisation::off) {
    if (b.stabilisation == Stabilisation::pending && e_var > 0.0) set_reference_variance(b);
    if (b.stabilisation == Stabilisation::on) {
      const int j = static_cast<int>(stabilise_round % static_cast<unsigned>(nt));
      // ref_var gives back what lambda forgets: less when the memory is held longer.
      const double ref_var = lambda == b.lambda ? b.ref_var[j] : b.ref_var[j] * (1.0 - b.lambda) / (1.0 - lambda);
      stabilise<N>(nt, P, theta, j, b.theta_ref[j], ref_var);
    }
  }
  // A mode with a_1, a_2 > 0 is stable: the common case, decided here.
  const bool stable_mode = b.n == 2 && theta[0] > 0.0 && theta[1] > 0.0;
  if (b.n > 0 && !stable_mode) {
    if (project(theta, b.n)) ++status.projections;
    if (theta[b.n - 1] == 0.0) return false;
  }
  // Guards: random walk (CONTSID's Kalman-filter adaptation), bounded trace.
  // Q is a parameter covariance; P carries theta^2 per output^2 (cov = sigma^2 P).
  if (b.random_walk > 0.0 && e_var > 0.0) {
    const double q2 = b.random_walk * b.random_walk / e_var;  // Q_jj = q2 theta_j^2
    for (int j = 0; j < nt; ++j) P[j + j * nt] += q2 * theta[j] * theta[j];
  }
  if (detail::bound_covariance<N>(P, b.p_limit.data(), nt)) ++status.covariance_clamps;
  double trace = 0.0;
  for (int j = 0; j < nt; ++j) trace += P[j + j * nt] + theta[j];
  return std::isfinite(trace);
}

}  // namespace modalwatch
