#pragma once
// The recursive estimator's state (RecursiveEstimator::Impl), shared by its
// sources: estimator.cpp (construction, step(), the accessors), step.cpp (the
// per-sample path), guards.cpp, warmup_fit.cpp and state.cpp.
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "block.hpp"
#include "hot_path.hpp"
#include "joint_information.hpp"
#include "modalwatch/estimator.hpp"
#include "modalwatch/model.hpp"
#include "modalwatch/record.hpp"
#include "modalwatch/transfer_function.hpp"

namespace modalwatch {

// Why the estimator went back to its last good state (status().last_reset_reason):
// arrays, so that every source sees one address per reason.
inline constexpr char kResetNonFiniteModel[] = "non-finite auxiliary model or instrument output";
inline constexpr char kResetUnstableLoop[] = "the instrument's closed loop with the current model is unstable";
inline constexpr char kResetDiverged[] =
    "output error diverged (residual RMS above divergence_ratio x its last good value)";
inline constexpr char kResetDegenerate[] = "non-finite or degenerate update (NaN/Inf in theta, P or the gain)";
inline constexpr char kResetRefit[] =
    "output error diverged (residual RMS above divergence_ratio x its last good value): refit on a new warm-up window";
inline constexpr char kChangeRefit[] =
    "output error changed (change test) on submodels at their memory floor: the memory after the alarm refitted "
    "beside the recursion";

// Settled: the output error's RMS within this factor of its last good value
// (the state the estimates, and the tests of change and divergence, rest on).
inline constexpr double kSettledRatio = 1.25;
// An output error below this fraction of the outputs summed into y_hat is
// their round-off (10^4 times it, far below any sensor's resolution: a 24-bit
// converter resolves 6e-8 of its range), not noise.
inline constexpr double kRoundOff = 1e-12;

// The warm-up's buffer holds a refit's window too (may_refit()): the samples
// before the reset that drive its prefilters, then its fitted part (at most a
// warm-up window), up to this many warm-up windows more than the warm-up's.
inline constexpr int kRefitTransientWindows = 3;
// A refit whose window the plant still changed in is tried again on the next
// window this many times.
inline constexpr int kRefitRetries = 3;

struct WarmupFit::Context {
  AdditiveModel initial;
  EstimatorSettings cfg;
  double noise_variance = 0.0;  // a refit's: the output-error variance of the last good state
  // A refit's: the last good state's misfit that says the plant changed, and
  // the fit's that says it describes the window, times noise_variance; how
  // much closer to the window than that state the fit must be (refit_verdict).
  // After a divergence a quarter of its level and a quarter; after a change
  // the change test found, the settled level and its inverse.
  double misfit_ratio = 0.0;
  double closer_ratio = 0.25;
  // A refit's: the window after one whose plant still changed (a ramp), fitted
  // from that window's compromise: the change is established.
  bool follow_up = false;
};

struct RecursiveEstimator::Impl {
  EstimatorSettings cfg;
  AdditiveModel initial;
  std::shared_ptr<const WarmupFit::Context> fit_context;  // immutable, shared with the jobs
  // A refit's context: the last good state as the start and the prior, written
  // in place (no allocation) before the window fills; its job reads it only
  // while the estimator waits for the result.
  std::shared_ptr<WarmupFit::Context> refit_context;
  bool refit_armed = false;            // settling after a divergence, the samples buffered for a refit
  bool refitting = false;              // the window is a refit's
  bool shadow_refit = false;           // ... armed beside the recursion, not after a reset (arm_refit)
  const char* refit_trigger = kResetDiverged;  // kResetDiverged or kChangeRefit
  const char* reason_before_refit = "";        // restored where a refit beside the recursion is not taken
  int window_samples = 0;              // the window being filled is complete at this many samples ...
  int window_settle = 0;               // ... of which the first ones only drive the fit's prefilters
  int refit_retries = 0;               // windows tried again since the divergence
  int changing_refits = 0;             // refits in a row used while the plant still changed (WarmupFit::changing_)
  std::uint64_t warm_since_sample = 0;  // status.samples when the last (re)fit was applied
  bool last_fit_refit = false;          // that fit was a refit's (may_refit)
  int quick_refits = 0;                 // refits in a row armed soon after the one before (may_refit)
  std::vector<detail::Block> blocks;
  detail::JointInformation joint;  // the blocks' instruments together: the covariance reported
  // P_i + C_i (joint_information.hpp), bounded as P_i is: what mode() and the
  // covariances report.
  detail::ThetaMat reported_P(const detail::Block& b) const { return b.P + b.cross; }
  std::vector<detail::BlockFilters> snapshot;  // filters at t_{k-1}, for refinements
  DiscreteTransferFunction controller;         // C_d(q) of the instrument's loop (eqs. 9, 29)
  // The plant's own loop u = C_d(q)(r - y), on the measured samples: the last
  // (controller order) values of u and of r - y, newest at loop_at, give C_d's
  // state from which a bridged gap continues that loop, the model standing in
  // for y (bridge()). Sized once at construction.
  DiscreteTransferFunction plant_loop;
  std::vector<double> loop_u, loop_e, loop_state;
  std::size_t loop_at = 0;
  std::size_t loop_known = 0;  // consecutive samples recorded (up to the order)
  void record_loop(double u, double e) {
    if (loop_u.empty()) return;
    loop_at = loop_at + 1 == loop_u.size() ? 0 : loop_at + 1;
    loop_u[loop_at] = u;
    loop_e[loop_at] = e;
    if (loop_known < loop_u.size()) ++loop_known;
  }
  EstimatorStatus status;

  // Several measured inputs: the inputs after u (AdditiveModel::n_inputs() - 1).
  int further_inputs = 0;
  // Warm-up window, preallocated; a WarmupFit job holds it while it runs.
  // Between windows the same arrays keep the latest samples as a ring
  // (keep_history()): a refit's window starts with them (restore_good()).
  // wfu[j]: the further input j + 1.
  Eigen::VectorXd wt, wu, wy, wr;
  std::vector<Eigen::VectorXd> wfu;
  int buffered = 0;
  bool keeps_history = false;  // a refit is possible: the ring runs
  Eigen::Index ring_head = 0;  // where the next sample goes
  Eigen::Index history = 0;    // consecutive samples (no gap, none missing) that end before ring_head
  bool fit_pending = false;          // window full, its fit not applied yet (defer_warmup_fit)
  bool fit_taken = false;            // ... and the window is out in a job
  std::uint64_t fit_generation = 0;  // tells a stale job (restore() since) from the pending one

  Sample patched;  // a sample with a non-finite value, as advance() takes it (step())
  double t_prev = 0.0;
  bool have_prev = false;
  bool just_restored = false;         // restore() ran and no sample has come since
  double last_u = 0.0, last_r = 0.0;  // the last finite inputs (r held in place of a non-finite one in open loop)
  bool bridging = false;  // advance() runs the model's loop across a gap (bridge())
  std::uint64_t since_update = 0;
  std::uint64_t updates_since_good = 0;

  double e_var = 0.0;    // output-error variance (EWMA over the residual window)
  double e_alpha = 0.0;  // its forgetting
  std::uint64_t e_count = 0;
  double e_short = 0.0;  // the same over a few samples: divergence detector
  double noise_at_reset =
      0.0;  // e_var_good at the last reset, until e_short and e_var are back near it (status.misfit)
  double e_short_alpha = 0.0;
  double e_var_good = 0.0;      // e_var when the last good state was saved
  double change_cusum = 0.0;    // Page's CUSUM on e^2 / e_var_good (EstimatorSettings::change_ratio)
  double change_drift = 0.0, change_gain = 0.0;  // its increment: drift + gain e^2 / e_var_good
  bool unexplained_alarm = false;                // its last alarm was one no submodel explains (boost_changed_blocks)
  std::uint64_t rearm = 0;      // samples until the divergence detector is armed again
  std::uint64_t settling = 0;   // after a filter restart: samples left to catch up (no update meanwhile)
  std::uint64_t transient = 0;  // ... of which the first ones, while the modes' free response dies out
  std::uint64_t bridged = 0;    // after a bridged gap: samples while the modes' response to it dies out
  // Stabilised forgetting's turn (update.hpp): one block per update, and one of
  // its coordinates per round over the blocks; status.updates = K round + block.
  std::size_t stabilise_block = 0;
  std::uint64_t stabilise_round = 0;
  bool inputs_lost = false;  // a non-finite u or r was skipped: the filters restart on the next sample
  int outlier_run = 0;       // consecutive samples replaced as outliers
  double pow_short = 0.0, pow_ref = 0.0, pow_alpha = 0.0, pow_ref_alpha = 0.0;
  std::uint64_t pow_count = 0;

  // The per-sample path, one compilation per instruction set (hot_path.hpp),
  // chosen once: advance() calls through kernel.
  using Kernel = unsigned (Impl::*)(const Sample&, bool);
  Kernel kernel = &Impl::advance_portable<false>;
  StepKernel kernel_id = StepKernel::portable;

  // fit_bound_variance: per submodel, diag of the warm-up fit's covariance from
  // one memory of its window (WarmupFit::bound_variance_), the covariance bound's
  // reference; without it, diag(P(t0)).
  void build(const AdditiveModel& model, const std::vector<Eigen::MatrixXd>* fit_covariance, double fit_sigma2,
             double y_var, const std::vector<Eigen::VectorXd>* fit_bound_variance = nullptr);
  MODALWATCH_HOT void rediscretise(detail::Block& b);
  MODALWATCH_HOT void follow(detail::Block& b);
  void discretise(detail::Block& b);
  void rediscretise_prefilters(detail::Block& b, double Ts);
  void allocate_window() {
    const Eigen::Index n = (1 + kRefitTransientWindows) * cfg.warmup_samples;
    for (Eigen::VectorXd* w : {&wt, &wu, &wy, &wr}) w->resize(n);
    wfu.resize(static_cast<std::size_t>(further_inputs));
    for (Eigen::VectorXd& w : wfu) w.resize(n);
  }
  // Every array of the window: t, u, y, r and the further inputs.
  template <class F>
  void for_each_window_array(F&& f) {
    for (Eigen::VectorXd* w : {&wt, &wu, &wy, &wr}) f(*w);
    for (Eigen::VectorXd& w : wfu) f(w);
  }
  void set_reference(detail::Block& b, double stabilisation) const;
  void set_reference_variance(detail::Block& b) const;
  void reset_filters();
  void restart_filters();
  bool bridge(const Sample& next, double dt);
  void bridge_plant_loop(double r, double z);
  std::uint64_t transient_samples(double decay = 0.1) const;
  double shortest_decay_time() const;
  // The round-off of y_hat: kRoundOff of the outputs summed into it.
  double round_off_level() const {
    double outputs = 0.0;
    for (const auto& b : blocks) outputs += std::abs(b.xu);
    return kRoundOff * outputs;
  }
  void save_good();
  void restore_good(const char* reason);
  // What an alarm of the change test did: boosted a block, or none, where a
  // block the error names could not be (floor_held: its forgetting already
  // at the memory floor), or neither.
  enum class ChangeAnswer { none, boosted, floor_held };
  ChangeAnswer boost_changed_blocks();
  void arm_refit(const char* trigger);
  void write_refit_start();  // the last good state into refit_context: the refit's start and yardstick
  bool restore_sign_flipped_modes();  // true when a mode went back
  int refit_samples() const;
  void arm_next_window(int N);
  bool may_refit() const;
  bool soon_after_fit() const;  // a divergence now says the last (re)fit did not describe the data
  // Sample s into row i of the window's columns.
  void store_sample(Eigen::Index i, const Sample& s) {
    wt(i) = s.t;
    wu(i) = s.u;
    wy(i) = s.y;
    wr(i) = s.r;
    for (int j = 0; j < further_inputs; ++j)
      wfu[static_cast<std::size_t>(j)](i) = s.further_u[static_cast<std::size_t>(j)];
  }
  void buffer_window_sample(const Sample& s) { store_sample(buffered++, s); }
  void keep_history(const Sample& s) {
    store_sample(ring_head, s);
    if (++ring_head == wt.size()) ring_head = 0;
    if (history < wt.size()) ++history;
  }
  void forget_history() { ring_head = history = 0; }
  bool keep_for_refit(const Sample& s, bool bad_values);
  void begin_refit();
  unsigned advance(const Sample& s, bool allow_update) { return (this->*kernel)(s, allow_update); }
  // One compilation per instruction set and per input count (one, several).
  template <bool kSeveralInputs>
  unsigned advance_portable(const Sample& s, bool allow_update);
  template <bool kSeveralInputs>
  MODALWATCH_TARGET_AVX2_FMA unsigned advance_avx2_fma(const Sample& s, bool allow_update);
  template <bool kSeveralInputs>
  MODALWATCH_HOT unsigned advance_body(const Sample& s, bool allow_update);
  // The input that drives block b: the one its submodel names (open loop).
  template <bool kSeveralInputs>
  MODALWATCH_HOT static double block_input(const detail::Block& b, const Sample& s) {
    return kSeveralInputs ? s.input(b.input) : s.u;
  }
  // The excitation with several inputs: the sum of their squares.
  MODALWATCH_HOT double input_power(const Sample& s) const {
    double p = s.u * s.u;
    for (int j = 0; j < further_inputs; ++j) {
      const double v = s.further_u[static_cast<std::size_t>(j)];
      p += v * v;
    }
    return p;
  }
  // Whether an input of the model is missing or not finite in s.
  bool further_inputs_missing(const Sample& s) const {
    if (s.further_inputs < further_inputs) return true;
    for (int j = 0; j < further_inputs; ++j)
      if (!std::isfinite(s.further_u[static_cast<std::size_t>(j)])) return true;
    return false;
  }
  bool select_kernel(StepKernel k) noexcept;
  MODALWATCH_HOT unsigned finish_update();
  MODALWATCH_HOT bool update_block(detail::Block& b, double y_f);
  template <int N>
  MODALWATCH_HOT bool update_block_n(detail::Block& b, double y_f);
  void finish_warmup(const WarmupFit& fit);
};

// The prefilters (and the auxiliary model) for the current theta.
inline void RecursiveEstimator::Impl::rediscretise(detail::Block& b) {
  b.filter_takes_damping();
  discretise(b);
}

// The same after an update, with a mode's damping term a_1 held within
// EstimatorSettings::damping_deadband of its std.
inline void RecursiveEstimator::Impl::follow(detail::Block& b) {
  const double k = cfg.damping_deadband;
  if (b.n == 2 && k > 0.0 && b.adapting == 0 && b.random_walk == 0.0) {
    const double d = b.theta(0) - b.filter_a1;
    if (!(d * d > k * k * e_var * b.P(0, 0))) {
      discretise(b);
      return;
    }
  }
  rediscretise(b);
}

inline void RecursiveEstimator::Impl::discretise(detail::Block& b) {
  const double Ts = b.ws * cfg.sample_time;
  if (b.filters.shared) {  // a mode, ZOH: A = 1 + a1 p + a2 p^2 for all four
    const double a1 = b.filter_a1, a2 = b.theta(1);
    b.filters.mode.set_denominator(1.0, a1, a2, discretize_second_order(1.0, a1, a2, Ts));
    return;
  }
  rediscretise_prefilters(b, Ts);
}

}  // namespace modalwatch
