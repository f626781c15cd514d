#include "modalwatch/estimator.hpp"

#include <Eigen/LU>
#include <Eigen/QR>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <new>
#include <numbers>
#include <stdexcept>
#include <string>
#include <string_view>

#include "modalwatch/polynomial.hpp"
#include "modalwatch/record.hpp"
#include "modalwatch/srivc.hpp"
#include "../prefilter/second_order.hpp"

// The per-sample path (advance() and everything inlined into it: the filter
// bank, the discretisation, eqs. 23-25 and the guards) is compiled twice: for
// the build's target (portable x86-64 by default) and, on x86-64, for AVX2 with
// fused multiply-add, where GCC contracts a * b + c into one instruction. Each
// estimator picks one at construction (no per-call dispatch, no global state).
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define MODALWATCH_HAVE_AVX2_FMA 1
#define MODALWATCH_TARGET_AVX2_FMA [[gnu::target("avx2,fma")]]
#else
#define MODALWATCH_HAVE_AVX2_FMA 0
#define MODALWATCH_TARGET_AVX2_FMA
#endif
// Functions of the per-sample path: inlined into both compilations of it.
#define MODALWATCH_HOT [[gnu::always_inline]] inline

namespace modalwatch {
namespace {

// Whether this CPU (and its operating system) runs the AVX2+FMA compilation.
bool cpu_has_avx2_fma() noexcept {
#if MODALWATCH_HAVE_AVX2_FMA
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
  return false;
#endif
}

// theta_i has at most n + m + 1 <= 2 kMaxFilterOrder + 1 entries; fixed capacity
// keeps step() free of heap allocation.
constexpr int kMaxTheta = 2 * kMaxFilterOrder + 1;
using ThetaVec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxTheta, 1>;
using ThetaMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxTheta, kMaxTheta>;

// Per-submodel time normalisation, as in the offline fit (DESIGN.md point 3).
double time_scale(const Submodel& s) {
  if (s.n > 0 && s.a(s.n - 1) != 0.0) return std::pow(std::abs(s.a(s.n - 1)), -1.0 / s.n);
  return 1.0;
}

// Stability projection of an anti-monic A (section 4.7). Orders 1 and 2 in
// closed form without allocation; higher orders through the general routine
// (allocates, only when A is unstable).
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

constexpr const char* kResetNonFiniteModel = "non-finite auxiliary model or instrument output";
constexpr const char* kResetUnstableLoop = "the instrument's closed loop with the current model is unstable";
constexpr const char* kResetDiverged =
    "output error diverged (residual RMS above divergence_ratio x its last good value)";
constexpr const char* kResetDegenerate = "non-finite or degenerate update (NaN/Inf in theta, P or the gain)";

// The prefilters of a block (eqs. 19-20, 29, 32-33): 1/A on the residual
// output (kY) and on the auxiliary output (kX, the instrument), 1/(p^l A) on u
// (kU) and on the instrument input z (kZ).
enum Channel { kY = 0, kX = 1, kU = 2, kZ = 3 };

// A block's four prefilters. A mode (n = 2, no rigid poles) with a held output
// (ZOH) filters all four signals through 1/A(p) with the same hold, so one
// discretisation serves them (DESIGN.md point 1): a SecondOrderFilterBank,
// re-discretised in place at every update (the estimator's inner loop).
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
  MODALWATCH_HOT const double* complete(Channel c, double w) { return shared ? mode.complete(c, w) : f[c].complete(w).data(); }
  // take() and complete() for the input channels kU and kZ, whose derivatives
  // the block uses up to p^m only (fill(), output()).
  MODALWATCH_HOT const double* take_input(Channel c, double w) {
    return input_top ? take(c, w) : mode.complete_state(c, w);
  }
  MODALWATCH_HOT const double* complete_input(Channel c, double w) {
    return input_top ? complete(c, w) : mode.complete_state(c, w);
  }
  MODALWATCH_HOT const double* derivatives(Channel c) const { return shared ? mode.derivatives(c) : f[c].derivatives().data(); }
};

struct Block {
  int n = 0, m = 0, l = 0, nt = 0;
  bool biproper = false;  // m = n + l: the output has a direct feedthrough
  double ws = 1.0, lambda = 1.0;
  double random_walk = 0.0;  // relative std of theta's drift per update (Q, CONTSID's Kalman-filter adaptation)
  ThetaVec scale;  // theta' = scale .* theta (physical)
  ThetaVec theta;  // theta-bar, normalised
  ThetaMat P;      // P-bar, normalised
  ThetaVec p_bound;  // per-direction bound on diag(P): covariance_bound x diag(P(t0))
  BlockFilters filters;
  double xu = 0.0, xz = 0.0;  // B/(p^l A) driven by u and by z, at t_k
  ThetaVec good_theta;
  ThetaMat good_P;
  ThetaVec phi, psi;

  FilterVector a_poly() const {
    FilterVector c(n + 1);
    c(0) = 1.0;
    c.tail(n) = theta.head(n);
    return c;
  }
  FilterVector denominator() const {
    FilterVector c = FilterVector::Zero(n + l + 1);
    c.tail(n + 1) = a_poly();
    return c;
  }
  // B/(p^l A) w from the filter's derivatives d = [w_f, p w_f, ...].
  MODALWATCH_HOT double output(const double* d) const {
    if (m == 0) return theta(n) * d[0];  // a mode's B = b0 (the common case)
    double s = 0.0;
    for (int j = 0; j <= m; ++j) s += theta(n + j) * d[j];
    return s;
  }
  // Regressor (eqs. 19, 33) and instrument (eqs. 20, 29, 32) from the filtered
  // residual output dy, auxiliary output dx, input du and instrument input dz.
  MODALWATCH_HOT void fill(const double* dy, const double* dx, const double* du, const double* dz) {
    if (n == 2 && m == 0) {  // a mode (the common case), without the loops
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
    for (int j = 0; j <= m; ++j) {
      phi(n + j) = du[j];
      psi(n + j) = dz[j];
    }
  }
  MODALWATCH_HOT double feedthrough() const {
    return biproper ? theta(n + m) / (n > 0 ? theta(n - 1) : 1.0) : 0.0;
  }
};

}  // namespace

bool EstimatorSettings::operator==(const EstimatorSettings& o) const {
  const auto same_covariances = [&] {
    if (initial_covariance.size() != o.initial_covariance.size()) return false;
    for (std::size_t i = 0; i < initial_covariance.size(); ++i)
      if (initial_covariance[i].size() != o.initial_covariance[i].size() ||
          initial_covariance[i] != o.initial_covariance[i])
        return false;
    return true;
  };
  return sample_time == o.sample_time && closed_loop == o.closed_loop && controller == o.controller &&
         output_hold == o.output_hold && block_iterations == o.block_iterations &&
         refinements == o.refinements && update_divisor == o.update_divisor && forgetting == o.forgetting &&
         warmup_samples == o.warmup_samples && fit_on_warmup == o.fit_on_warmup &&
         warmup_iterations == o.warmup_iterations && defer_warmup_fit == o.defer_warmup_fit &&
         same_covariances() && initial_covariance_relative == o.initial_covariance_relative &&
         random_walk == o.random_walk && random_walks == o.random_walks &&
         covariance_bound == o.covariance_bound && divergence_ratio == o.divergence_ratio &&
         gap_factor == o.gap_factor && outlier_sigma == o.outlier_sigma &&
         residual_window == o.residual_window && low_excitation_ratio == o.low_excitation_ratio &&
         low_excitation_window == o.low_excitation_window;
}

const std::vector<const char*>& reset_reasons() {
  static const std::vector<const char*> reasons = {kResetNonFiniteModel, kResetUnstableLoop, kResetDiverged,
                                                   kResetDegenerate};
  return reasons;
}

struct WarmupFit::Context {
  AdditiveModel initial;
  EstimatorSettings cfg;
};

WarmupFit::WarmupFit() = default;
WarmupFit::~WarmupFit() = default;
WarmupFit::WarmupFit(WarmupFit&&) noexcept = default;
WarmupFit& WarmupFit::operator=(WarmupFit&&) noexcept = default;

struct RecursiveEstimator::Impl {
  EstimatorSettings cfg;
  AdditiveModel initial;
  std::shared_ptr<const WarmupFit::Context> fit_context;  // immutable, shared with the jobs
  std::vector<Block> blocks;
  std::vector<BlockFilters> snapshot;  // filters at t_{k-1}, for refinements
  DiscreteTransferFunction controller;  // C_d(q) of the instrument's loop (eqs. 9, 29)
  EstimatorStatus status;

  // Warm-up window, preallocated; a WarmupFit job holds it while it runs.
  Eigen::VectorXd wt, wu, wy, wr;
  int buffered = 0;
  bool fit_pending = false;      // window full, its fit not applied yet (defer_warmup_fit)
  bool fit_taken = false;        // ... and the window is out in a job
  std::uint64_t fit_generation = 0;  // tells a stale job (restore() since) from the pending one

  double t_prev = 0.0;
  bool have_prev = false;
  bool just_restored = false;  // restore() ran and no sample has come since
  double last_u = 0.0, last_r = 0.0;  // held in place of a non-finite sample
  std::uint64_t since_update = 0;
  std::uint64_t updates_since_good = 0;

  double e_var = 0.0;        // output-error variance (EWMA over the residual window)
  double e_alpha = 0.0;      // its forgetting
  std::uint64_t e_count = 0;
  double e_short = 0.0;      // the same over a few samples: divergence detector
  double e_short_alpha = 0.0;
  double e_var_good = 0.0;   // e_var when the last good state was saved
  std::uint64_t rearm = 0;   // samples until the divergence detector is armed again
  std::uint64_t settling = 0;  // after a filter restart: samples left to catch up (no update meanwhile)
  int outlier_run = 0;       // consecutive samples replaced as outliers
  double pow_short = 0.0, pow_ref = 0.0, pow_alpha = 0.0, pow_ref_alpha = 0.0;
  std::uint64_t pow_count = 0;

  // The per-sample path, one compilation per instruction set (see the top of
  // this file), chosen once: advance() calls through kernel.
  using Kernel = unsigned (Impl::*)(const Sample&, bool);
  Kernel kernel = &Impl::advance_portable;
  StepKernel kernel_id = StepKernel::portable;

  void build(const AdditiveModel& model, const std::vector<Eigen::MatrixXd>* fit_covariance, double fit_sigma2,
             double y_var);
  MODALWATCH_HOT void rediscretise(Block& b);
  void rediscretise_prefilters(Block& b, double Ts);
  void allocate_window() {
    for (Eigen::VectorXd* w : {&wt, &wu, &wy, &wr}) w->resize(cfg.warmup_samples);
  }
  void reset_filters();
  void restart_filters();
  void save_good();
  void restore_good(const char* reason);
  unsigned advance(const Sample& s, bool allow_update) { return (this->*kernel)(s, allow_update); }
  unsigned advance_portable(const Sample& s, bool allow_update);
  MODALWATCH_TARGET_AVX2_FMA unsigned advance_avx2_fma(const Sample& s, bool allow_update);
  MODALWATCH_HOT unsigned advance_body(const Sample& s, bool allow_update);
  bool select_kernel(StepKernel k) noexcept;
  MODALWATCH_HOT unsigned finish_update();
  MODALWATCH_HOT bool update_block(Block& b, double y_f);
  template <int N>
  MODALWATCH_HOT bool update_block_n(Block& b, double y_f);
  void finish_warmup(const WarmupFit& fit);
};

inline void RecursiveEstimator::Impl::rediscretise(Block& b) {
  const double Ts = b.ws * cfg.sample_time;
  if (b.filters.shared) {  // a mode, ZOH: A = 1 + a1 p + a2 p^2 for all four
    const double a1 = b.theta(0), a2 = b.theta(1);
    b.filters.mode.set_denominator(1.0, a1, a2, detail::discretize_second_order_inline(1.0, a1, a2, Ts));
    return;
  }
  rediscretise_prefilters(b, Ts);
}

// Out of line: its Eigen temporaries would otherwise cost every mode's
// rediscretise() a heavier call frame.
[[gnu::noinline]] void RecursiveEstimator::Impl::rediscretise_prefilters(Block& b, double Ts) {
  Prefilter* f = b.filters.f;
  const FilterVector a = b.a_poly();
  const Discretization da = discretize(a, Ts, cfg.output_hold);
  f[kY].set_denominator(a, da);
  f[kX].set_denominator(a, da);
  if (b.l == 0 && cfg.output_hold == Hold::zoh) {  // p^l A = A: one discretisation serves all four
    f[kU].set_denominator(a, da);
    f[kZ].set_denominator(a, da);
    return;
  }
  const FilterVector den = b.denominator();
  const Discretization dd = discretize(den, Ts, Hold::zoh);
  f[kU].set_denominator(den, dd);
  f[kZ].set_denominator(den, dd);
}

void RecursiveEstimator::Impl::build(const AdditiveModel& model, const std::vector<Eigen::MatrixXd>* fit_cov,
                                     double fit_sigma2, double y_var) {
  blocks.clear();
  const double T = cfg.sample_time;
  for (std::size_t i = 0; i < model.submodels.size(); ++i) {
    const Submodel& s = model.submodels[i];
    Block b;
    b.n = s.n;
    b.m = s.m;
    b.l = s.rigid_poles;
    b.nt = s.n_theta();
    b.biproper = b.m == b.n + b.l;
    b.ws = time_scale(s);
    b.lambda = cfg.forgetting.empty() ? 1.0 : cfg.forgetting[i];
    b.random_walk = cfg.random_walks.empty() ? cfg.random_walk : cfg.random_walks[i];
    b.scale.resize(b.nt);
    for (int j = 1; j <= b.n; ++j) b.scale(j - 1) = std::pow(b.ws, j);
    for (int k = 0; k <= b.m; ++k) b.scale(b.n + k) = std::pow(b.ws, k - b.l);
    b.theta = s.theta().cwiseProduct(Eigen::VectorXd(b.scale));
    // P(t0): given, from the warm-up fit, or relative to the parameter size.
    b.P = ThetaMat::Zero(b.nt, b.nt);
    if (i < cfg.initial_covariance.size() && cfg.initial_covariance[i].size() == b.nt) {
      for (int j = 0; j < b.nt; ++j) b.P(j, j) = cfg.initial_covariance[i](j) * b.scale(j) * b.scale(j);
    } else if (fit_cov && fit_sigma2 > 0.0) {
      const Eigen::MatrixXd& c = (*fit_cov)[i];
      for (int j = 0; j < b.nt; ++j)
        for (int k = 0; k < b.nt; ++k) b.P(j, k) = c(j, k) * b.scale(j) * b.scale(k) / fit_sigma2;
    } else {
      const double rho = cfg.initial_covariance_relative;
      for (int j = 0; j < b.nt; ++j) {
        const double v = rho * std::max(std::abs(b.theta(j)), 1e-3);
        b.P(j, j) = v * v / std::max(y_var, 1e-300);
      }
    }
    b.p_bound = cfg.covariance_bound * b.P.diagonal().cwiseMax(1e-300);
    b.filters.init(b.a_poly(), b.denominator(), b.ws * T, cfg.output_hold, b.biproper);
    b.phi.resize(b.nt);
    b.psi.resize(b.nt);
    blocks.push_back(std::move(b));
  }
  snapshot.resize(blocks.size());
  controller = cfg.controller;
  controller.reset();
  save_good();
}

void RecursiveEstimator::Impl::reset_filters() {
  for (auto& b : blocks) {
    b.filters.reset();
    b.xu = b.xz = 0.0;
  }
  controller.reset();
}

// After a gap (or a reset) the filters restart from rest, and the model output
// needs a few time constants of the slowest mode to catch up with the data. That
// transient is neither a divergence nor information about theta: as in the
// warm-up (section 4.7), the filters run without updating theta until the output
// error is back near the noise level (at most kSettleWindows residual windows,
// after which updates resume so that a plant that changed during the gap can
// still be followed); the divergence detector is not consulted meanwhile.
void RecursiveEstimator::Impl::restart_filters() {
  constexpr double kSettleWindows = 4.0;
  reset_filters();
  // Unsettled until the short-term error, started at the divergence level, has
  // come down to near the noise level on the restarted filters' own output.
  e_short = cfg.divergence_ratio * cfg.divergence_ratio * e_var_good;
  settling = static_cast<std::uint64_t>(kSettleWindows / (1.0 - e_alpha));
  outlier_run = 0;
}

void RecursiveEstimator::Impl::save_good() {
  for (auto& b : blocks) {
    b.good_theta = b.theta;
    b.good_P = b.P;
  }
  e_var_good = e_var;
  updates_since_good = 0;
}

void RecursiveEstimator::Impl::restore_good(const char* reason) {
  for (auto& b : blocks) {
    b.theta = b.good_theta;
    b.P = b.good_P;
    rediscretise(b);
  }
  e_var = e_var_good;
  e_count = 0;  // outlier statistics restart with the filters
  restart_filters();
  // Give the restored state one residual window before judging it again.
  rearm = static_cast<std::uint64_t>(1.0 / (1.0 - e_alpha));
  ++status.resets;
  status.last_reset_reason = reason;
}

// eqs. (23)-(25) on raw column-major storage (P is nt x nt, leading dimension nt):
// K = P psi / (lambda + phi^T P psi), theta += K (y_f - phi^T theta),
// P = (P - K phi^T P) / lambda. The IV recursion (eq. 24) does not keep P
// symmetric; its symmetric part is kept against round-off (DESIGN.md point 4):
// P = (P - (K w^T + w K^T)/2) / lambda with w = P^T phi = P phi (P symmetric on
// entry), computed on the upper triangle and mirrored. N > 0 fixes the size at
// compile time so that the loops unroll (N = 3: a mode, the common case); N = 0
// takes nt at run time.
template <int N>
MODALWATCH_HOT bool iv_update(int nt_runtime, double* P, double* theta, const double* phi, const double* psi, double lambda,
               double y_f) {
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
  double denom = lambda, eps = y_f;
  for (int i = 0; i < nt; ++i) {
    denom += phi[i] * Ppsi[i];
    eps -= phi[i] * theta[i];
  }
  if (!std::isfinite(denom) || std::abs(denom) < 1e-300) return false;
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

// One block's update from theta-bar(t_{k-1}), P-bar(t_{k-1}); the filtered
// regressor phi and instrument psi are already in b.
inline bool RecursiveEstimator::Impl::update_block(Block& b, double y_f) {
  return b.nt == 3 ? update_block_n<3>(b, y_f) : update_block_n<0>(b, y_f);
}

// On raw storage, with nt fixed at compile time for N > 0 (as iv_update): at
// nt = 3 Eigen's dynamic-size copies and row/column operations cost more than
// the arithmetic.
template <int N>
inline bool RecursiveEstimator::Impl::update_block_n(Block& b, double y_f) {
  const int nt = N > 0 ? N : b.nt;
  // In place: on a false return the caller goes back to the last good state.
  double* P = b.P.data();  // nt x nt, column-major
  double* theta = b.theta.data();
  if (!iv_update<N>(nt, P, theta, b.phi.data(), b.psi.data(), b.lambda, y_f)) return false;
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
  // Per-direction bound: D P D with D = diag(min(1, sqrt(bound/P_jj))) keeps P
  // symmetric positive definite while stopping wind-up in unexcited directions.
  // P is symmetric here, so D_jj scales row j and mirrors it into column j, and
  // P_jj becomes D_jj^2 P_jj = bound_j.
  bool clamped = false;
  const double* bound = b.p_bound.data();
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
  if (clamped) ++status.covariance_clamps;
  double trace = 0.0;
  for (int j = 0; j < nt; ++j) trace += P[j + j * nt] + theta[j];
  return std::isfinite(trace);
}

bool RecursiveEstimator::Impl::select_kernel(StepKernel k) noexcept {
  switch (k) {
    case StepKernel::portable:
      kernel = &Impl::advance_portable;
      break;
    case StepKernel::avx2_fma:
#if MODALWATCH_HAVE_AVX2_FMA
      if (!cpu_has_avx2_fma()) return false;
      kernel = &Impl::advance_avx2_fma;
      break;
#else
      return false;
#endif
  }
  kernel_id = k;
  return true;
}

unsigned RecursiveEstimator::Impl::advance_portable(const Sample& s, bool allow_update) {
  return advance_body(s, allow_update);
}

#if MODALWATCH_HAVE_AVX2_FMA
unsigned RecursiveEstimator::Impl::advance_avx2_fma(const Sample& s, bool allow_update) {
  return advance_body(s, allow_update);
}
#endif

inline unsigned RecursiveEstimator::Impl::advance_body(const Sample& s, bool allow_update) {
  unsigned flags = 0;
  const bool refine = cfg.refinements > 0 || cfg.block_iterations > 1;
  if (refine && allow_update) {
    for (std::size_t i = 0; i < blocks.size(); ++i) snapshot[i] = blocks[i].filters;
  }
  for (auto& b : blocks) b.filters.begin_sample();
  // 1. Instrument input z_k = S_uo(q, t_k) r_k: the noise-free loop with the
  //    known controller and the current model (eq. 29), solved for a biproper
  //    controller. In open loop z = u.
  //    With it, each block's output for u at t_k, and y_hat, their sum.
  double z = s.u;
  double y_hat = 0.0;
  if (cfg.closed_loop) {
    double free = 0.0, D = 0.0;
    for (auto& b : blocks) {
      b.filters.advance_held(kZ);
      b.xz = b.output(b.filters.complete_input(kZ, 0.0));  // the free response
      free += b.xz;
      D += b.feedthrough();  // 0 unless biproper
    }
    const double c0 = controller.feedthrough();
    z = (c0 * (s.r - free) + controller.peek(0.0)) / (1.0 + c0 * D);
    controller.step(s.r - (free + D * z));
    for (auto& b : blocks) {
      const double* dz = b.filters.complete_input(kZ, z);
      // Strictly proper (m < n + l): the output uses the state alone, not z_k.
      if (b.biproper) b.xz = b.output(dz);
      b.xu = b.output(b.filters.take_input(kU, s.u));
      y_hat += b.xu;
    }
  } else {
    for (auto& b : blocks) {
      b.xu = b.output(b.filters.take_input(kU, s.u));
      b.xz = b.xu;
      y_hat += b.xu;
    }
  }
  if (!std::isfinite(y_hat) || !std::isfinite(z)) {
    restore_good(kResetNonFiniteModel);
    return flags | kReset;
  }
  // The instrument's loop (eq. 29) runs the current model with the controller; a
  // wrong model can make that loop unstable even when every mode is stable.
  if (cfg.closed_loop && pow_ref > 0.0 && z * z > 1e8 * pow_ref) {
    restore_good(kResetUnstableLoop);
    return flags | kReset;
  }
  // 2. Outliers: a sample far outside the residual spread is replaced by the
  //    model's output so that it does not enter the filter states.
  double y = s.y;
  const double e = std::isfinite(s.y) ? s.y - y_hat : 0.0;
  bool update = allow_update;
  // A run of more than kOutlierRun "outliers" is not outliers but a mismatch
  // (a restart, a changed plant): accept it, or the estimator would lock up.
  constexpr int kOutlierRun = 10;
  // Nor is a residual at the round-off of y_hat an outlier: on noise-free data
  // e_var is round-off too, and a residual ten times it would say no more than
  // how y_hat was rounded (with FMA or without). kRoundOff, relative to the
  // outputs summed into y_hat, is 10^4 times their round-off and far below any
  // sensor's resolution (a 24-bit converter resolves 6e-8 of its range).
  constexpr double kRoundOff = 1e-12;
  const auto above_round_off = [&] {
    double sum = 0.0;
    for (const auto& b : blocks) sum += std::abs(b.xu);
    return std::abs(e) > kRoundOff * sum;
  };
  if (!std::isfinite(s.y)) {
    y = y_hat;
  } else if (e_count > 100 && outlier_run < kOutlierRun && e * e > cfg.outlier_sigma * cfg.outlier_sigma * e_var &&
             above_round_off()) {
    y = y_hat;
    ++outlier_run;
    ++status.outliers;
    flags |= kOutlier;
    update = false;
  } else {
    outlier_run = 0;
    e_var = e_count == 0 ? e * e : e_alpha * e_var + (1.0 - e_alpha) * e * e;
    e_short = e_count == 0 ? e * e : e_short_alpha * e_short + (1.0 - e_short_alpha) * e * e;
    ++e_count;
  }
  // Divergence: the output error an order of magnitude above what it was when
  // the last good state was saved (DESIGN.md point 4). Plant changes that the
  // estimator can follow raise it far less.
  constexpr double kSettledRatio = 3.0;  // output error RMS within 3x its last good value
  const bool diverging =
      allow_update && e_var_good > 0.0 && e_short > cfg.divergence_ratio * cfg.divergence_ratio * e_var_good;
  if (settling > 0) {
    const bool settled = !(e_short > kSettledRatio * kSettledRatio * e_var_good);
    settling = settled ? 0 : settling - 1;
    if (!settled) update = false;
  } else if (rearm > 0) {
    --rearm;
  } else if (diverging) {
    restore_good(kResetDiverged);
    return flags | kReset;
  }
  // 3. Excitation: without input power the update only winds P up.
  pow_short = pow_count == 0 ? z * z : pow_alpha * pow_short + (1.0 - pow_alpha) * z * z;
  ++pow_count;
  const bool low = pow_ref > 0.0 && pow_short < cfg.low_excitation_ratio * pow_ref;
  // The reference is the input power over a long window, learned while the
  // excitation is normal (seeded by the warm-up when there is one).
  if (!low) pow_ref = pow_ref > 0.0 ? pow_ref_alpha * pow_ref + (1.0 - pow_ref_alpha) * z * z : pow_short;
  status.low_excitation = low;
  if (low) {
    ++status.low_excitation_samples;
    flags |= kLowExcitation;
    update = false;
  }
  if (update && ++since_update < static_cast<std::uint64_t>(cfg.update_divisor)) update = false;
  if (!update) {
    for (auto& b : blocks) {
      b.filters.take(kY, y - (y_hat - b.xu));
      b.filters.take(kX, b.xz);
    }
    return flags;
  }
  since_update = 0;

  // 4. Algorithm 1: M_l block-coordinate iterations, M_s refinements per block.
  // Block i's residual output (eq. 15) is y minus the other blocks' outputs at
  // their latest theta: y - (xu_sum - b.xu), the sum kept up to date below.
  double xu_sum = y_hat;
  bool healthy = true;
  if (!refine) {
    // M_l = 1, M_s = 0 (the paper's setting): one update per block from
    // theta-bar, P-bar in place, and the block's prefilters re-discretised for
    // the next sample (this sample is done with them).
    for (auto& b : blocks) {
      const double y_tilde = y - (xu_sum - b.xu);
      const double* dy = b.filters.take(kY, y_tilde);
      const double* dx = b.filters.take(kX, b.xz);
      const double* du = b.filters.derivatives(kU);
      const double* dz = cfg.closed_loop ? b.filters.derivatives(kZ) : du;
      b.fill(dy, dx, du, dz);
      if (!update_block(b, dy[0])) {
        restore_good(kResetDegenerate);
        return flags | kReset;
      }
      const double xu = b.output(du);
      xu_sum += xu - b.xu;
      b.xu = xu;
      rediscretise(b);
    }
    return flags | finish_update();
  }
  for (int l = 0; l < cfg.block_iterations && healthy; ++l) {
    for (std::size_t i = 0; i < blocks.size() && healthy; ++i) {
      Block& b = blocks[i];
      const ThetaVec theta_bar = b.theta;
      const ThetaMat P_bar = b.P;
      ThetaVec theta_iter = theta_bar;
      ThetaMat P_iter = P_bar;
      for (int s_it = 0; s_it <= cfg.refinements; ++s_it) {
        // Residual output of this block (eq. 15), other blocks at their latest b.
        const double y_tilde = y - (xu_sum - b.xu);
        if (l > 0 || s_it > 0) {
          // Refinement: the prefilter is the latest iterate; redo this sample.
          b.filters = snapshot[i];
          b.theta = theta_iter;
          rediscretise(b);
          b.filters.begin_sample();
          b.filters.take_input(kU, s.u);
          if (cfg.closed_loop) b.filters.take_input(kZ, z);
          b.theta = theta_bar;
        }
        const double* dy = b.filters.take(kY, y_tilde);
        const double* dx = b.filters.take(kX, b.xz);
        const double* du = b.filters.derivatives(kU);
        const double* dz = cfg.closed_loop ? b.filters.derivatives(kZ) : du;
        b.fill(dy, dx, du, dz);
        b.theta = theta_bar;
        b.P = P_bar;
        if (!update_block(b, dy[0])) {
          healthy = false;
          break;
        }
        theta_iter = b.theta;
        P_iter = b.P;
      }
      if (!healthy) break;
      b.theta = theta_iter;
      b.P = P_iter;
      const double xu = b.output(b.filters.derivatives(kU));  // G_i(theta^{l+1}) u for the next blocks' residuals
      xu_sum += xu - b.xu;
      b.xu = xu;
    }
  }
  if (!healthy) {
    restore_good(kResetDegenerate);
    return flags | kReset;
  }
  for (auto& b : blocks) rediscretise(b);
  return flags | finish_update();
}

// After a healthy update of every block: counted, and now and then the last good state.
inline unsigned RecursiveEstimator::Impl::finish_update() {
  ++status.updates;
  if (++updates_since_good >= 256 && e_short < 4.0 * e_var) save_good();
  return kUpdated;
}

// The offline part of the initialisation (section 4.7): the fit on the window
// and theta(t0), P(t0) from it. No estimator state is touched here, so that it
// can run on another thread (WarmupFit).
void WarmupFit::run() noexcept {
  if (!context_ || done_) return;
  const AdditiveModel& initial = context_->initial;
  const EstimatorSettings& cfg = context_->cfg;
  try {
  const int N = n_;
  Record window;
  window.t = t_.head(N);
  window.u = u_.head(N);
  window.y = y_.head(N);
  if (cfg.closed_loop) window.r = r_.head(N);
  const double y_var = (window.y.array() - window.y.mean()).square().mean();
  AdditiveModel model = initial;
  std::vector<Eigen::MatrixXd> cov;
  double sigma2 = 0.0;
  bool fit_used = false;
  if (cfg.fit_on_warmup) {
    try {
      SrivcOptions o;
      o.closed_loop = cfg.closed_loop;
      o.controller = cfg.controller;
      o.output_hold = cfg.output_hold;
      o.max_iterations = cfg.warmup_iterations;
      const FitResult fit = fit_srivc(window, initial, o);
      bool ok = fit.model.beta().allFinite() && fit.covariance.allFinite() && fit.noise_variance > 0.0;
      for (const auto& s : fit.model.submodels) ok = ok && (s.n == 0 || s.a(s.n - 1) > 0.0);
      if (ok) {
        // theta(t0), P(t0): the configured model as a prior (relative std rho per
        // parameter) fused with the fit and its covariance C, per submodel:
        //   C0 = (Cp^-1 + C^-1)^-1,  theta0 = C0 (Cp^-1 theta_cfg + C^-1 theta_fit).
        // Where the window is informative the fit dominates; along directions it
        // leaves undetermined (a setpoint with few frequencies) the prior holds.
        sigma2 = fit.noise_variance;
        const double rho = cfg.initial_covariance_relative;
        for (std::size_t i = 0; i < model.submodels.size(); ++i) {
          const Eigen::VectorXd th_cfg = initial.submodels[i].theta(), th_fit = fit.model.submodels[i].theta();
          const Eigen::MatrixXd C = fit.theta_covariance(static_cast<int>(i));
          Eigen::VectorXd prior_var(th_cfg.size());
          for (Eigen::Index j = 0; j < th_cfg.size(); ++j) prior_var(j) = std::pow(rho * std::max(std::abs(th_cfg(j)), 1e-12), 2);
          const Eigen::MatrixXd Cinv = C.completeOrthogonalDecomposition().pseudoInverse();
          Eigen::MatrixXd info = Cinv;
          info.diagonal() += prior_var.cwiseInverse();
          const Eigen::MatrixXd C0 = info.inverse();
          Eigen::VectorXd th0 = C0 * (prior_var.cwiseInverse().cwiseProduct(th_cfg) + Cinv * th_fit);
          Submodel s = initial.submodels[i];
          s.set_theta(th0);
          if (s.n > 0) {
            Eigen::VectorXd a = s.a;
            project_stable(a);
            s.a = a;
          }
          model.submodels[i] = s;
          cov.push_back(0.5 * (C0 + C0.transpose()));
        }
        fit_used = true;
      }
    } catch (const std::exception&) {
      // Fall back to the configured model: reported through warmup_fit_used.
    }
  }
  model_ = std::move(model);
  covariance_ = std::move(cov);
  sigma2_ = sigma2;
  y_var_ = y_var;
  fit_used_ = fit_used;
  } catch (...) {
    failed_ = true;  // allocation: apply_warmup_fit() restarts the warm-up
  }
  done_ = true;
}

// The estimator's part: build from the fit's result, then run the filters over
// the window without updating (section 4.7).
void RecursiveEstimator::Impl::finish_warmup(const WarmupFit& fit) {
  const int N = buffered;
  const double sigma2 = fit.sigma2_;
  if (fit.fit_used_) status.warmup_fit_used = true;
  build(fit.model_, fit.covariance_.empty() ? nullptr : &fit.covariance_, sigma2, fit.y_var_);
  if (sigma2 > 0.0) {
    e_var = e_short = e_var_good = sigma2;
    e_count = 1000;
  }
  // Run the filters over the window with theta(t0), without updating (section 4.7).
  double p = 0.0;
  for (int k = 0; k < N; ++k) {
    advance({wt(k), wu(k), wy(k), cfg.closed_loop ? wr(k) : 0.0}, false);
    p += wu(k) * wu(k);
  }
  pow_ref = p / std::max(N, 1);
  status.warming_up = false;
}

RecursiveEstimator::RecursiveEstimator(const AdditiveModel& initial, const EstimatorSettings& settings)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.cfg = settings;
  m.initial = initial;
  m.select_kernel(StepKernel::avx2_fma);  // where the CPU has it; else portable
  if (!(settings.sample_time > 0.0)) throw std::invalid_argument("estimator: sample_time must be > 0");
  if (initial.submodels.empty()) throw std::invalid_argument("estimator: no submodels");
  for (const auto& s : initial.submodels) {
    s.check();
    if (s.n + s.rigid_poles > kMaxFilterOrder || s.n_theta() > kMaxTheta)
      throw std::invalid_argument("estimator: submodel '" + s.name + "' exceeds the maximum order");
  }
  if (!settings.forgetting.empty() && settings.forgetting.size() != initial.submodels.size())
    throw std::invalid_argument("estimator: one forgetting factor per submodel");
  for (double l : settings.forgetting)
    if (!(l > 0.0 && l <= 1.0)) throw std::invalid_argument("estimator: forgetting factor outside (0, 1]");
  if (!settings.random_walks.empty() && settings.random_walks.size() != initial.submodels.size())
    throw std::invalid_argument("estimator: one random walk per submodel (or none)");
  for (double q : settings.random_walks)
    if (!(q >= 0.0 && std::isfinite(q))) throw std::invalid_argument("estimator: random walk negative or not finite");
  if (settings.block_iterations < 1 || settings.refinements < 0 || settings.update_divisor < 1)
    throw std::invalid_argument("estimator: M_l >= 1, M_s >= 0 and the update divisor >= 1");
  if (settings.closed_loop && settings.controller.empty())
    throw std::invalid_argument("estimator: closed loop needs the controller");
  m.cfg.forgetting.resize(initial.submodels.size(), 1.0);
  if (settings.forgetting.empty()) std::fill(m.cfg.forgetting.begin(), m.cfg.forgetting.end(), 1.0);

  const double lambda_min = *std::min_element(m.cfg.forgetting.begin(), m.cfg.forgetting.end());
  const double T = settings.sample_time;
  const double e_window = settings.residual_window > 0.0 ? settings.residual_window / T
                                                          : (lambda_min < 1.0 ? 1.0 / (1.0 - lambda_min) : 1000.0);
  m.e_alpha = 1.0 - 1.0 / std::max(e_window, 2.0);
  m.e_short_alpha = 1.0 - 1.0 / std::max(0.05 * e_window, 2.0);
  double w_min = std::numeric_limits<double>::infinity();
  for (const auto& s : initial.submodels)
    if (s.n == 2 && s.a(1) > 0.0) w_min = std::min(w_min, 1.0 / std::sqrt(s.a(1)));
  const double pw = settings.low_excitation_window > 0.0
                        ? settings.low_excitation_window / T
                        : (std::isfinite(w_min) ? 2.0 * std::numbers::pi / w_min / T : 1000.0);
  m.pow_alpha = 1.0 - 1.0 / std::max(pw, 2.0);
  m.pow_ref_alpha = 1.0 - 1.0 / std::max(20.0 * pw, 2.0);

  if (settings.warmup_samples > 0) {
    m.fit_context = std::make_shared<const WarmupFit::Context>(WarmupFit::Context{initial, m.cfg});
    m.allocate_window();
    m.status.warming_up = true;
  } else {
    m.build(initial, nullptr, 0.0, 1.0);
    m.status.warming_up = false;
  }
}

RecursiveEstimator::~RecursiveEstimator() = default;
RecursiveEstimator::RecursiveEstimator(RecursiveEstimator&&) noexcept = default;
RecursiveEstimator& RecursiveEstimator::operator=(RecursiveEstimator&&) noexcept = default;

unsigned RecursiveEstimator::step(const Sample& s) noexcept {
  Impl& m = *impl_;
  if (m.fit_pending) return kWarmupFitPending;  // the caller holds the sample until apply_warmup_fit()
  if (!std::isfinite(s.t)) {
    ++m.status.rejected_nonfinite;
    return kRejectedNonFinite;
  }
  Sample sample = s;
  unsigned flags = 0;
  const bool bad_values =
      !std::isfinite(s.u) || !std::isfinite(s.y) || (m.cfg.closed_loop && !std::isfinite(s.r));
  if (bad_values) {
    // Keep the time slot so that the filters stay on the sample grid: hold the
    // inputs, let the model stand in for y, and do not update on it.
    ++m.status.rejected_nonfinite;
    flags |= kRejectedNonFinite;
    sample.u = m.last_u;
    sample.r = m.last_r;
    sample.y = std::numeric_limits<double>::quiet_NaN();  // replaced by y_hat in advance()
  }
  const double T = m.cfg.sample_time;
  if (m.have_prev) {
    const double dt = s.t - m.t_prev;
    // The first sample after restore() may come on another time base (a
    // restarted controller clock): earlier than the checkpoint is then a gap too.
    const bool restarted = m.just_restored;
    if (dt < 0.5 * T && !restarted) {  // duplicate or out of order
      ++m.status.rejected_out_of_order;
      return kRejectedOutOfOrder;
    }
    if (dt > m.cfg.gap_factor * T || restarted) {
      // The prefilter states no longer describe the signals: restart them, keep theta and P.
      ++m.status.gaps;
      flags |= kGap;
      if (m.status.warming_up) m.buffered = 0;
      else m.restart_filters();
    }
  }
  m.t_prev = s.t;
  m.have_prev = true;
  m.just_restored = false;
  if (bad_values && (m.status.warming_up || m.blocks.empty())) return flags;
  m.last_u = sample.u;
  m.last_r = sample.r;
  ++m.status.samples;
  if (m.status.warming_up) {
    m.wt(m.buffered) = s.t;
    m.wu(m.buffered) = s.u;
    m.wy(m.buffered) = s.y;
    m.wr(m.buffered) = s.r;
    if (++m.buffered == m.cfg.warmup_samples) {
      m.fit_pending = true;
      if (m.cfg.defer_warmup_fit) return flags | kWarmingUp | kWarmupFitPending;
      try {
        WarmupFit job = take_warmup_fit();
        job.run();
        apply_warmup_fit(std::move(job));
      } catch (...) {
        // Allocation failure: apply_warmup_fit() restarted the warm-up (or take failed before).
        m.fit_pending = m.fit_taken = false;
        m.buffered = 0;
      }
    }
    return flags | kWarmingUp;
  }
  return flags | m.advance(sample, !bad_values);
}

bool RecursiveEstimator::warmup_fit_pending() const noexcept { return impl_->fit_pending; }

WarmupFit RecursiveEstimator::take_warmup_fit() {
  Impl& m = *impl_;
  if (!m.fit_pending || m.fit_taken)
    throw std::logic_error("RecursiveEstimator::take_warmup_fit: no warm-up fit pending");
  WarmupFit job;
  job.context_ = m.fit_context;
  job.generation_ = m.fit_generation;
  job.n_ = m.buffered;
  job.t_.swap(m.wt);  // Eigen swaps the buffers: no copy, no allocation
  job.u_.swap(m.wu);
  job.y_.swap(m.wy);
  job.r_.swap(m.wr);
  m.fit_taken = true;
  return job;
}

void RecursiveEstimator::apply_warmup_fit(WarmupFit&& job) {
  Impl& m = *impl_;
  if (!m.fit_pending || !m.fit_taken || job.empty() || job.generation_ != m.fit_generation)
    throw std::logic_error("RecursiveEstimator::apply_warmup_fit: not this estimator's pending warm-up fit");
  if (!job.done_) throw std::logic_error("RecursiveEstimator::apply_warmup_fit: the job has not run");
  m.wt.swap(job.t_);
  m.wu.swap(job.u_);
  m.wy.swap(job.y_);
  m.wr.swap(job.r_);
  m.fit_pending = m.fit_taken = false;
  try {
    if (job.failed_) throw std::bad_alloc();
    m.finish_warmup(job);
  } catch (...) {
    m.blocks.clear();
    m.status.warming_up = true;
    m.buffered = 0;  // start the warm-up again
    throw;
  }
}

StepKernel RecursiveEstimator::step_kernel() const noexcept { return impl_->kernel_id; }
bool RecursiveEstimator::set_step_kernel(StepKernel kernel) noexcept { return impl_->select_kernel(kernel); }

int RecursiveEstimator::submodels() const { return static_cast<int>(impl_->initial.submodels.size()); }

Submodel RecursiveEstimator::submodel(int i) const {
  Submodel s = impl_->initial.submodels[i];
  if (impl_->blocks.empty()) return s;
  const Block& b = impl_->blocks[i];
  s.set_theta(Eigen::VectorXd(b.theta.cwiseQuotient(b.scale)));
  return s;
}

AdditiveModel RecursiveEstimator::model() const {
  AdditiveModel m = impl_->initial;
  for (int i = 0; i < submodels(); ++i) m.submodels[i] = submodel(i);
  return m;
}

ModeEstimate RecursiveEstimator::mode(int i) const noexcept {
  ModeEstimate est;
  const Impl& m = *impl_;
  if (m.blocks.empty()) {
    est.value = modal_parameters(m.initial.submodels[i]);
    return est;
  }
  const Block& b = m.blocks[i];
  est.value.gain = b.theta(b.n) / b.scale(b.n);
  const double s2 = m.e_var;
  est.std.gain = std::sqrt(std::max(0.0, s2 * b.P(b.n, b.n))) / b.scale(b.n);
  if (b.n == 2) {
    const double a1 = b.theta(0) / b.scale(0), a2 = b.theta(1) / b.scale(1);
    if (a2 > 0.0) {
      est.value.wn = 1.0 / std::sqrt(a2);
      est.value.zeta = 0.5 * a1 * est.value.wn;
      // First-order propagation of sigma^2 P through wn = a2^-1/2, zeta = a1/(2 sqrt a2).
      const double c11 = s2 * b.P(0, 0) / (b.scale(0) * b.scale(0));
      const double c22 = s2 * b.P(1, 1) / (b.scale(1) * b.scale(1));
      const double c12 = s2 * b.P(0, 1) / (b.scale(0) * b.scale(1));
      const double a2_32 = a2 * std::sqrt(a2);  // a2^1.5 (no pow: mode() runs per sample in `track`)
      const double dw2 = -0.5 / a2_32;
      const double dz1 = 0.5 / std::sqrt(a2), dz2 = -0.25 * a1 / a2_32;
      est.std.wn = std::sqrt(std::max(0.0, dw2 * dw2 * c22));
      est.std.zeta = std::sqrt(std::max(0.0, dz1 * dz1 * c11 + 2 * dz1 * dz2 * c12 + dz2 * dz2 * c22));
    }
  }
  return est;
}

Eigen::Matrix3d RecursiveEstimator::mode_covariance(int i) const noexcept {
  const Impl& m = *impl_;
  Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
  if (m.blocks.empty()) return c;
  const Block& b = m.blocks[i];
  if (b.n != 2) {
    c(2, 2) = m.e_var * b.P(b.n, b.n) / (b.scale(b.n) * b.scale(b.n));
    return c;
  }
  const std::array<int, 3> at = {0, 1, b.n};  // a1, a2, b0 inside theta
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k) c(r, k) = m.e_var * b.P(at[r], at[k]) / (b.scale(at[r]) * b.scale(at[k]));
  return modal_covariance(b.theta(0) / b.scale(0), b.theta(1) / b.scale(1), c);
}

Eigen::MatrixXd RecursiveEstimator::covariance(int i) const {
  const Impl& m = *impl_;
  const Block& b = m.blocks.at(i);
  Eigen::MatrixXd c = m.e_var * Eigen::MatrixXd(b.P);
  for (int j = 0; j < b.nt; ++j)
    for (int k = 0; k < b.nt; ++k) c(j, k) /= b.scale(j) * b.scale(k);
  return c;
}

double RecursiveEstimator::residual_rms() const noexcept { return std::sqrt(impl_->e_var); }
double RecursiveEstimator::noise_variance() const noexcept { return impl_->e_var; }
const EstimatorStatus& RecursiveEstimator::status() const noexcept { return impl_->status; }

EstimatorState RecursiveEstimator::state() const {
  const Impl& m = *impl_;
  EstimatorState st;
  st.warmed_up = !m.status.warming_up && !m.blocks.empty();
  st.model = model();
  if (st.warmed_up) {
    for (const Block& b : m.blocks) {
      st.P.emplace_back(b.P);
      st.time_scale.push_back(b.ws);
      st.P_bound.emplace_back(b.p_bound);
      st.good_theta.emplace_back(b.good_theta.cwiseQuotient(b.scale));
      st.good_P.emplace_back(b.good_P);
    }
  }
  st.noise_variance = m.e_var;
  st.residual_short = m.e_short;
  st.noise_variance_good = m.e_var_good;
  st.residual_count = m.e_count;
  st.rearm = m.rearm;
  st.input_power = m.pow_short;
  st.input_power_reference = m.pow_ref;
  st.input_power_count = m.pow_count;
  st.since_update = m.since_update;
  st.updates_since_good = m.updates_since_good;
  st.have_last_sample = m.have_prev;
  st.last_t = m.t_prev;
  st.last_u = m.last_u;
  st.last_r = m.last_r;
  st.status = m.status;
  return st;
}

void RecursiveEstimator::restore(const EstimatorState& st) {
  const Impl& m = *impl_;
  const auto fail = [](const std::string& what) { throw std::invalid_argument("estimator state: " + what); };
  const auto finite = [](double v) { return std::isfinite(v); };
  const std::size_t K = m.initial.submodels.size();
  if (st.model.submodels.size() != K)
    fail(std::to_string(st.model.submodels.size()) + " submodels, this estimator has " + std::to_string(K));
  for (std::size_t i = 0; i < K; ++i) {
    const Submodel& want = m.initial.submodels[i];
    const Submodel& got = st.model.submodels[i];
    const std::string where = "submodel " + std::to_string(i + 1) + " ('" + want.name + "'): ";
    if (got.name != want.name || got.n != want.n || got.m != want.m || got.rigid_poles != want.rigid_poles)
      fail(where + "name or orders (n, m, rigid poles) differ");
    if (got.a.size() != got.n || got.b.size() != got.m + 1) fail(where + "coefficient count differs from n, m");
    if (!got.a.allFinite() || !got.b.allFinite()) fail(where + "non-finite coefficient");
    if (got.n > 0 && got.a(got.n - 1) == 0.0) fail(where + "a_n = 0 (order drop)");
  }
  if (st.warmed_up) {
    if (st.P.size() != K || st.time_scale.size() != K || st.P_bound.size() != K || st.good_theta.size() != K ||
        st.good_P.size() != K)
      fail("per-submodel arrays (P, time_scale, P_bound, good_theta, good_P) do not have one entry per submodel");
    for (std::size_t i = 0; i < K; ++i) {
      const Eigen::Index nt = m.initial.submodels[i].n_theta();
      const std::string where = "submodel " + std::to_string(i + 1) + ": ";
      if (st.P[i].rows() != nt || st.P[i].cols() != nt || st.good_P[i].rows() != nt || st.good_P[i].cols() != nt ||
          st.P_bound[i].size() != nt || st.good_theta[i].size() != nt)
        fail(where + "P, P_bound, good_theta or good_P do not match n_theta = " + std::to_string(nt));
      if (!st.P[i].allFinite() || !st.good_P[i].allFinite() || !st.P_bound[i].allFinite() ||
          !st.good_theta[i].allFinite())
        fail(where + "non-finite P, P_bound, good_theta or good_P");
      if (!(st.time_scale[i] > 0.0) || !finite(st.time_scale[i])) fail(where + "time_scale must be finite and > 0");
      if ((st.P_bound[i].array() <= 0.0).any()) fail(where + "P_bound must be > 0");
    }
  }
  for (double v : {st.noise_variance, st.residual_short, st.noise_variance_good, st.input_power,
                   st.input_power_reference})
    if (!finite(v) || v < 0.0) fail("noise, residual or input-power statistic is negative or non-finite");
  if (!finite(st.last_t) || !finite(st.last_u) || !finite(st.last_r)) fail("non-finite last sample");
  const char* reason = "";
  if (st.status.last_reset_reason && *st.status.last_reset_reason) {
    reason = nullptr;
    for (const char* r : reset_reasons())
      if (std::string_view(r) == st.status.last_reset_reason) reason = r;
    if (!reason) fail("unknown last_reset_reason");
  }

  // Built in a copy and moved in at the end: a throw below (derived numbers out
  // of range, allocation) leaves this estimator as it was.
  Impl next = m;
  if (next.fit_taken) {  // the window is out in a job: a new one
    next.allocate_window();
  }
  next.fit_pending = next.fit_taken = false;
  ++next.fit_generation;
  if (st.warmed_up) {
    next.build(st.model, nullptr, 0.0, 1.0);  // structure, prefilters at rest; theta, P below
    for (std::size_t i = 0; i < K; ++i) {
      Block& b = next.blocks[i];
      b.ws = st.time_scale[i];
      for (int j = 1; j <= b.n; ++j) b.scale(j - 1) = std::pow(b.ws, j);
      for (int k = 0; k <= b.m; ++k) b.scale(b.n + k) = std::pow(b.ws, k - b.l);
      b.theta = st.model.submodels[i].theta().cwiseProduct(Eigen::VectorXd(b.scale));
      if (!b.scale.allFinite() || !b.theta.allFinite() || (b.scale.array() == 0.0).any())
        fail("submodel " + std::to_string(i + 1) + ": time_scale out of range for its coefficients");
      b.P = st.P[i];
      b.p_bound = st.P_bound[i];
      b.good_theta = st.good_theta[i].cwiseProduct(Eigen::VectorXd(b.scale));
      b.good_P = st.good_P[i];
      b.filters.init(b.a_poly(), b.denominator(), b.ws * next.cfg.sample_time, next.cfg.output_hold, b.biproper);
    }
    next.buffered = 0;
  } else {
    next.blocks.clear();
    next.buffered = 0;
  }
  next.reset_filters();
  next.e_var = st.noise_variance;
  next.e_short = st.residual_short;
  next.e_var_good = st.noise_variance_good;
  next.e_count = st.residual_count;
  next.rearm = st.rearm;
  next.outlier_run = 0;
  next.pow_short = st.input_power;
  next.pow_ref = st.input_power_reference;
  next.pow_count = st.input_power_count;
  next.since_update = st.since_update;
  next.updates_since_good = st.updates_since_good;
  next.have_prev = st.have_last_sample;
  next.just_restored = true;
  next.t_prev = st.last_t;
  next.last_u = st.last_u;
  next.last_r = st.last_r;
  next.status = st.status;
  next.status.last_reset_reason = reason;
  next.status.warming_up = !st.warmed_up && next.cfg.warmup_samples > 0;
  if (!st.warmed_up && next.cfg.warmup_samples == 0) {
    // No warm-up configured: the estimator starts from the configured model, as new.
    next.build(next.initial, nullptr, 0.0, 1.0);
  }
  *impl_ = std::move(next);
}

}  // namespace modalwatch
