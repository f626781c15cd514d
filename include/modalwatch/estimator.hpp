#pragma once
// The recursive additive RSRIVC estimator (Algorithm 1 of the paper): per
// sample, M_l block-coordinate iterations over the K submodels, each with
// M_s SRIVC refinements, updating theta_i and P_i by eqs. (23)-(25) with a
// forgetting factor per submodel. Open loop (instrument eq. 28) or closed loop
// (instrument eq. 29 from z = S_uo(q, t_k) r, a noise-free simulation of the
// loop with the known controller and the current model); rigid-body submodels
// (eqs. 32-33); stability projection of every A_i before it is used as a
// prefilter or auxiliary model; output subsampling (section 4.7). A velocity
// or acceleration output (Submodel::output_derivatives = z) takes b_k's
// regressor from the prefiltered input's (k+z)-th derivative; an EstimatorState
// does not hold z, restore() takes it from this estimator's model.
//
// Several measured inputs (open loop, at most kMaxInputs): each block's
// prefilters take the input its submodel names (Submodel::input), so that its
// regressor and instrument (eq. 28) come from that input and the other blocks'
// outputs, each on its own input, are subtracted (eq. 15); the warm-up fit and
// a refit get the window's further inputs. A Sample carries them in its fixed
// array, in the model's order; a non-finite or missing one makes the sample a
// non-finite one. The low-excitation test takes the sum of the inputs' squares.
// A single-input model runs the same compilation of step() as before.
//
// A plain class: no I/O, no threads, no exceptions and no heap allocation in
// step() once warm-up is over. Everything a caller needs to know about bad
// input (NaN samples, gaps, outliers, low excitation, resets) is counted in
// status().
//
// The warm-up fit (section 4.7) is the one long computation: by default step()
// runs it when the warm-up window is full. With defer_warmup_fit a caller that
// must keep a deadline (modalwatchd's estimation loop) runs it elsewhere:
//   if (est.step(s) & kWarmupFitPending) {
//     WarmupFit job = est.take_warmup_fit();  // no copy, no allocation
//     job.run();                              // any thread; allocates, may take seconds
//     est.apply_warmup_fit(std::move(job));   // theta(t0), P(t0); filters over the window
//   }                                         // then step() the samples held meanwhile
// which gives the estimates of the synchronous path bit for bit.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "modalwatch/model.hpp"
#include "modalwatch/prefilter.hpp"
#include "modalwatch/record.hpp"
#include "modalwatch/transfer_function.hpp"

namespace modalwatch {

struct EstimatorSettings {
  double sample_time = 0.0;  // s
  bool closed_loop = false;
  DiscreteTransferFunction controller;  // closed loop: u = C_d(q)(r - y)
  Hold output_hold = Hold::zoh;         // intersample behaviour of y in the prefilters

  int block_iterations = 1;        // M_l
  int refinements = 0;             // M_s
  int update_divisor = 1;          // subsampling: update every n-th sample, filter every sample
  std::vector<double> forgetting;  // lambda_i in (0, 1], one per submodel

  // Initialisation (section 4.7). With warmup_samples > 0 the filters run over
  // the warm-up window and theta(t0), P(t0) come from the offline additive
  // SRIVC on that window (unless fit_on_warmup is false).
  int warmup_samples = 0;
  bool fit_on_warmup = true;
  int warmup_iterations = 50;
  // Not a config key: the caller runs the warm-up fit (see the top of this file).
  bool defer_warmup_fit = false;
  // P(t0) when not from the warm-up fit: given per submodel (diagonal, physical
  // units of theta_i^2 per output unit^2), or relative: diag((rho theta_j)^2)/var(y).
  std::vector<Eigen::VectorXd> initial_covariance;
  double initial_covariance_relative = 0.1;

  // Guards against what a recursive update cannot recover from by itself:
  // covariance wind-up, divergence, gaps, outliers, unexciting input.
  double random_walk = 0.0;  // Q = random_walk^2 diag(theta'^2) added to P at each update
  // Per submodel (empty: random_walk for every one): like the forgetting factor,
  // the drift a mode may follow is a property of that mode.
  std::vector<double> random_walks;
  // diag(P_i) is held below this times its reference: what one memory of the
  // warm-up window's data gives (the warm-up fit's covariance with the fit's
  // information scaled to one memory, the configured model as its prior),
  // else diag(P_i(t0)). Where the data leave a direction open, its std grows by
  // sqrt(covariance_bound) at most. A change boost (change_ratio) lifts the
  // bound by the boost for one memory of the submodel.
  double covariance_bound = 10.0;
  // Stabilised forgetting (Kulhavy & Zarrop 1993). Where the data leave a
  // direction of theta_i open (a setpoint with few frequencies, a closed loop
  // that filters them), exponential forgetting winds P_i up there and theta_i
  // wanders with the noise. Instead, the information forgotten at each update
  // is given back as (1 - lambda_i) R_ref toward theta_ref = theta_i(t0):
  //   R_i = lambda_i R_i + (1 - lambda_i) R_ref + psi phi^T,
  //   R_ref = diag(P_ref)^-1, P_ref = diag((stabilisation theta_ref)^2) / sigma^2
  // (never below diag(P_i(t0))). In an open direction P_i tends to P_ref and
  // theta_i returns to theta_ref within about one memory 1/(1 - lambda_i), so
  // its excursions stay within about stabilisation x |theta_ref|; where the
  // data inform theta_i, the pull is their information over R_ref times weaker.
  // 0: plain exponential forgetting. No effect on a submodel with lambda_i = 1.
  double stabilisation = 0.2;
  // Per submodel (empty: stabilisation for every one), as random_walks.
  std::vector<double> stabilisations;
  // The shortest memory, in decay times of the submodel's slowest pole. The
  // recursion filters the data with the current A_i as if it were fixed, but the
  // prefilters' states hold the data filtered over about one decay time
  // 1/(zeta_i wn_i) of A_i, with the theta_i of that time. Forgetting at a pace
  // comparable to that decay closes a loop theta -> prefilter -> regressor ->
  // theta that the update does not model: on a lightly damped mode its damping
  // and gain wind up together until the output error diverges. The memory
  // update_divisor / (1 - lambda_i) is therefore held at min_memory or more
  // decay times of the current A_i (lambda_i raised where it is shorter), which
  // restores the separation of time scales the recursion assumes
  // (damping_deadband opens that loop where it starts). First- and
  // second-order submodels without rigid poles (the modes); other submodels
  // keep lambda_i. 0: lambda_i as configured.
  double min_memory = 6.0;
  // Per submodel (empty: min_memory for every one), as random_walks.
  std::vector<double> min_memories;
  // The floor outside a change boost, in the same decay times (never below a
  // submodel's min_memory): min_memory is then the floor only of the
  // submodels a change boost names, while they re-converge. Six decay times
  // keep most modes still, but a mode as lightly damped as its input is
  // sparse (zeta 0.005 on one line of a multisine, the nearest others 45
  // half-power bandwidths away) can still wind up with its prefilters there,
  // and a longer min_memory slows every change's tracking. A submodel held
  // at this floor is not boosted (lifted from it to min_memory, a mode the
  // change test names beside the changed one wound up instead); an alarm that
  // boosts no submodel releases the ones it names to min_memory for as long as
  // a boosted one would re-converge. Off by default: the mode it holds still
  // follows a drift more slowly, and on the bank it traded one record's false
  // alarms for a longer tail of delays (README.md). 0: min_memory throughout.
  double settled_memory = 0.0;
  // The same loop, where it starts: a mode's prefilters (and its auxiliary
  // model) take the estimate's damping term a_1 only once the two differ by
  // more than this many of its standard deviations, and its a_2 (the
  // frequency) at every update; a_1 follows at once while a change boost
  // re-converges the submodel and where a random walk says it drifts. A
  // lightly damped mode on one line of its input leaves a_1 and b_0 open
  // together (the line fixes the peak height, their ratio), and a prefilter
  // whose damping follows the estimate along that direction scales the
  // filtered signals at the line by as much. With the paper's updates
  // (block_iterations 1, refinements 0; refinements re-filter each sample with
  // the latest iterate). 0: every update re-discretises the prefilters with
  // the estimate's A.
  double damping_deadband = 3.0;
  double divergence_ratio = 10.0;      // residual RMS this many times its last good value: reset
  // A change of the plant that the model no longer fits, long before the error
  // diverges: Page's CUSUM (Basseville & Nikiforov 1993, sec. 2.2) for the
  // output error's variance going from its last good value to change_ratio
  // times it, with the alarm at change_threshold h (the log-likelihood ratio;
  // on a white Gaussian residual about e^h / 0.32 samples between false alarms,
  // 2e8 at 18 for a ratio 4, whatever the plant). On the alarm the submodels the error correlates with
  // (their instruments' score test) get their covariance multiplied by
  // kChangeBoost, so that they follow within a tenth of a memory where
  // forgetting takes one. Where they are already at their memory floor
  // (min_memory) no boost can speed them up: where they explain an order of
  // magnitude more of the error than white noise would, the memory after the
  // alarm is fitted beside the recursion, as a refit after a divergence but
  // with no reset, and taken only where the fit finds a change. 0: off.
  double change_ratio = 4.0;
  double change_threshold = 18.0;
  // After such a boost, the submodels the score test did not name keep their
  // estimates (no update) for change_hold memories of the boosted ones, so
  // that a neighbour whose instrument is nearly collinear with the changed
  // mode's does not absorb part of the change. 0: they go on updating.
  double change_hold = 1.0;
  // A time step above gap_factor T is a gap. In closed loop, one shorter than
  // a quarter of the model's shortest decay time is bridged: the controller
  // and the model run the loop over the missing samples, and updates go on
  // unless a residual after it leaves the noise. Any other gap restarts the
  // filter states, and updates wait for them to settle.
  double gap_factor = 1.5;
  double outlier_sigma = 10.0;         // |y - y_hat| above this many residual std: sample replaced
  double residual_window = 0.0;        // s, residual RMS window (0: 1/(1 - min lambda) samples)
  double low_excitation_ratio = 0.05;  // input power below this fraction of its reference: no update
  double low_excitation_window = 0.0;  // s (0: one period of the slowest mode)

  bool operator==(const EstimatorSettings& other) const;
};

struct EstimatorStatus {
  std::uint64_t samples = 0;  // accepted samples
  std::uint64_t updates = 0;  // parameter updates
  std::uint64_t rejected_nonfinite = 0;
  std::uint64_t rejected_out_of_order = 0;
  std::uint64_t gaps = 0;
  std::uint64_t outliers = 0;
  std::uint64_t low_excitation_samples = 0;
  std::uint64_t projections = 0;
  std::uint64_t covariance_clamps = 0;
  std::uint64_t resets = 0;  // returns to the last good state
  std::uint64_t boosts = 0;  // covariance boosts after a change of the output error (change_ratio)
  std::uint64_t noise_changes = 0;  // changes of the output error no submodel explains: a new noise level
  // Modes returned to their last good estimate because their gain had changed
  // sign (a well-determined one): a mode that did so no longer describes its
  // physical mode but cancels a neighbour's change.
  std::uint64_t sign_restores = 0;
  const char* last_reset_reason = "";
  bool warming_up = true;
  bool low_excitation = false;
  // The model does not describe the data, and its estimates are no
  // measurement of the plant (a fault detector raises no flag on them): after
  // a reset whose wait to settle ended unsettled, the updates run again while
  // the output error is above 1.25x the RMS the last good state had before the
  // reset. The noise estimate then grows with the model's error, which it must
  // not hide. Over once the error (long and short term) is back there. Not
  // while the wait holds the estimates, nor after an accepted refit. Not
  // carried by a checkpoint.
  bool misfit = false;
  // Whether the estimates are a measurement a fault detector may act on (its
  // update()'s `valid`): not while warming up, with low excitation or misfit.
  bool estimates_measure_plant() const noexcept { return !warming_up && !low_excitation && !misfit; }
  bool warmup_fit_used = false;  // theta(t0) from the offline fit on the warm-up window (else kWarmupFitNotUsed)
  std::uint64_t fits = 0;  // windows whose fit has ended (the warm-up's, refits; used or not)
  // s of data the last (re)fit's estimate rests on, the fitted part of its
  // window; 0 before the first and after a refit that was refused. A fault detector may count a hold from its
  // start (FaultDetector::update's evidence_span).
  double fitted_window = 0.0;
};

// Why the estimator starts from the configured model although fit_on_warmup
// is on (EstimatorStatus::warmup_fit_used false): the fit failed or describes
// another plant than the configured one.
inline constexpr const char* kWarmupFitNotUsed =
    "the fit failed, or moved a mode by 2x or past another, or gave one no gain";
// What step() did with a sample (bit flags).
enum StepFlags : unsigned {
  kUpdated = 1u << 0,
  kRejectedNonFinite = 1u << 1,
  kRejectedOutOfOrder = 1u << 2,
  kGap = 1u << 3,
  kOutlier = 1u << 4,
  kLowExcitation = 1u << 5,
  kReset = 1u << 6,
  kWarmingUp = 1u << 7,
  // defer_warmup_fit: the warm-up window is complete and its fit pending. Until
  // apply_warmup_fit(), step() takes no sample (it returns this flag alone).
  kWarmupFitPending = 1u << 8,
  // The change test (change_ratio) alarmed and boosted the covariance of at
  // least one submodel (EstimatorStatus::boosts).
  kChangeBoost = 1u << 9,
  // A mode went back to its last good estimate because its gain had changed
  // sign (EstimatorStatus::sign_restores).
  kModeRestored = 1u << 10,
};

// The instruction set of step()'s arithmetic (RecursiveEstimator::set_step_kernel).
enum class StepKernel {
  portable,  // the build's target (x86-64 baseline by default)
  avx2_fma,  // x86-64 with AVX2 and fused multiply-add
};

struct ModeEstimate {
  ModalParameters value;
  ModalParameters std;
};

// The serialisation an EstimatorState is written through and read back from
// (the daemon's checkpoint file supplies one). The state writes its values in
// a fixed order and reads them back in the same order; `what` names each value
// for error messages.
class StateWriter {
 public:
  virtual ~StateWriter() = default;
  virtual void flag(bool value, const char* what) = 0;
  virtual void count(std::size_t value, const char* what) = 0;  // of the submodels that follow
  virtual void name(const std::string& value, const char* what) = 0;
  virtual void integer(std::int32_t value, const char* what) = 0;
  virtual void counter(std::uint64_t value, const char* what) = 0;
  virtual void real(double value, const char* what) = 0;
  virtual void reals(const Eigen::VectorXd& value, const char* what) = 0;
  virtual void matrix(const Eigen::MatrixXd& value, const char* what) = 0;  // square
};

// Every read throws (the reader's own exception type) on what it cannot read;
// fail() is how the state reports a value that is readable but not valid.
class StateReader {
 public:
  virtual ~StateReader() = default;
  virtual bool flag(const char* what) = 0;
  virtual std::size_t count(const char* what) = 0;
  virtual std::string name(const char* what) = 0;
  virtual std::int32_t integer(const char* what, std::int32_t lo, std::int32_t hi) = 0;  // in [lo, hi]
  virtual std::uint64_t counter(const char* what) = 0;
  virtual double real(const char* what) = 0;  // finite
  virtual Eigen::VectorXd reals(Eigen::Index size, const char* what) = 0;
  virtual Eigen::MatrixXd matrix(Eigen::Index size, const char* what) = 0;  // size x size
  [[noreturn]] virtual void fail(const std::string& what) = 0;
};

// Everything needed to resume estimation without a new warm-up (a checkpoint),
// as an opaque value: the estimate, its covariance as the estimator keeps it
// (normalised time), the last good state it returns to on a reset, the noise,
// residual and excitation statistics, the counters and the time of the last
// sample. Not the prefilter or controller states: after restore() they restart
// from rest, as after a gap. A state written while the estimator was still
// warming up carries only the counters and the time: the warm-up starts again
// after restore().
class EstimatorState {
 public:
  EstimatorState() = default;  // no submodels, not warmed up

  bool warmed_up() const noexcept { return warmed_up_; }
  // Current theta, physical units; without model.inputs and Submodel::input,
  // which are the configuration's (restore() takes them from the estimator).
  const AdditiveModel& model() const noexcept { return model_; }
  const EstimatorStatus& status() const noexcept { return status_; }
  double last_sample_time() const noexcept { return last_t_; }  // s

  // The values in a fixed order. read() checks what the state itself can
  // (orders, time scales, the reset reason); restore() checks the rest against
  // the estimator's structure.
  void write(StateWriter& out) const;
  static EstimatorState read(StateReader& in);

  bool operator==(const EstimatorState& other) const;  // exact, bit for bit

 private:
  friend class RecursiveEstimator;

  bool warmed_up_ = false;
  AdditiveModel model_;
  // Per submodel, when warmed up: the time scale (theta' = diag(ws^j) theta),
  // P-bar (normalised), the bound on its diagonal, the last good theta
  // (physical units) and P-bar; stabilised forgetting's reference theta
  // (physical units) and its pseudo-measurement variance (normalised, 0 while
  // sigma^2 is not known yet or without stabilisation).
  std::vector<double> time_scale_;
  std::vector<Eigen::MatrixXd> P_;
  std::vector<Eigen::VectorXd> P_bound_;
  std::vector<Eigen::VectorXd> good_theta_;
  std::vector<Eigen::MatrixXd> good_P_;
  std::vector<Eigen::VectorXd> reference_theta_;
  std::vector<Eigen::VectorXd> reference_variance_;
  // The instruments' joint information across submodels, when warmed up: per
  // submodel the term it adds to P-bar in the covariance reported
  // (RecursiveEstimator::mode_covariance), the information now and at the last
  // good state (normalised, over all submodels' theta), and where its sampling
  // stands.
  std::vector<Eigen::MatrixXd> cross_;
  Eigen::MatrixXd joint_, joint_good_;
  std::uint64_t joint_updates_ = 0, joint_good_updates_ = 0, joint_solved_at_ = 0, joint_rng_ = 0;
  std::int32_t joint_countdown_ = 1, joint_gap_ = 1;
  // Output-error statistics (variance over the residual window, short window
  // for divergence, its value at the last good state) and excitation power.
  double noise_variance_ = 0.0, residual_short_ = 0.0, noise_variance_good_ = 0.0;
  std::uint64_t residual_count_ = 0;
  std::uint64_t rearm_ = 0;
  double input_power_ = 0.0, input_power_reference_ = 0.0;
  std::uint64_t input_power_count_ = 0;
  std::uint64_t since_update_ = 0, updates_since_good_ = 0;
  bool have_last_sample_ = false;
  double last_t_ = 0.0;
  double last_u_ = 0.0, last_r_ = 0.0;  // held in place of a non-finite sample
  EstimatorStatus status_;              // last_reset_reason: one of the estimator's own, or ""
};

// The offline additive SRIVC on the warm-up window and the initial state it
// gives (section 4.7), as a job that can run on any thread. It holds the window
// (handed over from the estimator without a copy) and what it needs from the
// settings, never a reference into the estimator.
class WarmupFit {
 public:
  WarmupFit();  // empty
  ~WarmupFit();
  WarmupFit(WarmupFit&&) noexcept;
  WarmupFit& operator=(WarmupFit&&) noexcept;

  bool empty() const noexcept { return !context_; }
  bool done() const noexcept { return done_; }
  int samples() const noexcept { return n_; }  // in the window
  // The window is a refit's (after a divergence the restored state did not
  // settle from), not the warm-up's.
  bool refit() const noexcept { return refit_; }
  // The fit and theta(t0), P(t0) from it (allocates). A fit that fails or gives
  // an unusable model leaves the configured model, as the synchronous path does
  // (status().warmup_fit_used says which). Only allocation failure is left:
  // apply_warmup_fit() then restarts the warm-up.
  void run() noexcept;

 private:
  friend class RecursiveEstimator;
  struct Context;
  std::shared_ptr<const Context> context_;
  std::uint64_t generation_ = 0;
  Eigen::VectorXd t_, u_, y_, r_;
  std::vector<Eigen::VectorXd> further_u_;  // the inputs after u, with several
  int n_ = 0;
  int settle_ = 0;  // samples at the start that only drive the prefilters (a refit's)
  bool refit_ = false;
  bool done_ = false, failed_ = false;
  // The result: theta(t0) (physical units), its covariance per submodel when
  // the fit was used, the fit's noise variance, the window's output variance.
  AdditiveModel model_;
  std::vector<Eigen::MatrixXd> covariance_;
  std::vector<Eigen::VectorXd> bound_variance_;  // diag of the same from one memory of the window
  double sigma2_ = 0.0, y_var_ = 0.0;
  // A refit's window as its fit saw it (started_in_state): replayed, it
  // starts the filters in the state the fit estimated for the changed plant.
  Record replay_;
  bool fit_used_ = false;
  bool unsettled_ = false;  // a refit's: the change is real, but the window did not fit to the noise level
  bool changing_ = false;   // a refit's, used: the plant still changed in the window (a ramp)
};

class RecursiveEstimator {
 public:
  // Throws std::invalid_argument on an inconsistent configuration (also more
  // than kMaxInputs inputs, or several inputs in closed loop).
  RecursiveEstimator(const AdditiveModel& initial, const EstimatorSettings& settings);
  ~RecursiveEstimator();
  RecursiveEstimator(RecursiveEstimator&&) noexcept;
  RecursiveEstimator& operator=(RecursiveEstimator&&) noexcept;

  // One sample. No allocation, no exceptions after warm-up.
  unsigned step(const Sample& sample) noexcept;

  // defer_warmup_fit (see the top of this file). take_warmup_fit(): the job for
  // the pending fit, with the window moved into it (no allocation); throws
  // std::logic_error when no fit is pending or it was taken already.
  // apply_warmup_fit(): the estimate from the finished job, then the filters run
  // over the window (allocates); the estimator is then warmed up and step()
  // takes samples again. Throws std::logic_error for a job that is not this
  // estimator's pending one or not run; on allocation failure the warm-up
  // restarts with an empty window (and the exception propagates).
  bool warmup_fit_pending() const noexcept;
  WarmupFit take_warmup_fit();
  void apply_warmup_fit(WarmupFit&& job);

  // step() runs one of two compilations of the same arithmetic: AVX2 with fused
  // multiply-add where the CPU has it (chosen at construction), else portable.
  // Their estimates differ by round-off only; set_step_kernel() picks one, for
  // estimates that are bit-identical across machines or to compare the two.
  // Returns false, and changes nothing, for a kernel this CPU cannot run.
  StepKernel step_kernel() const noexcept;
  bool set_step_kernel(StepKernel kernel) noexcept;

  int submodels() const;
  // Current estimate of submodel i in physical units (allocates: call outside the hot path
  // or use mode()).
  Submodel submodel(int i) const;
  AdditiveModel model() const;
  // Modal view of submodel i and its standard deviations (sigma^2 (P_i + C_i), as
  // mode_covariance()). No allocation.
  ModeEstimate mode(int i) const noexcept;
  // Covariance of submodel i's (wn, zeta, gain): modal_covariance() of
  // sigma^2 (P_i + C_i), C_i what not knowing the other submodels adds to
  // P_i (the instruments' joint information; for one memory after the
  // warm-up C_i is zero, and from a change boost until one memory after it
  // C_i keeps its value from before). No allocation.
  Eigen::Matrix3d mode_covariance(int i) const noexcept;
  // The same from sigma^2 P_i alone: the other submodels taken as known, as
  // the block-coordinate recursion takes them.
  Eigen::Matrix3d mode_covariance_given_others(int i) const noexcept;
  // Covariance of submodel i's (wn, zeta, gain) with submodel j's (i != j):
  // sigma^2 times block (i, j) of the instruments' joint information's inverse,
  // mapped as mode_covariance() maps its diagonal block. Zero before that
  // information first holds a memory and after restore() until it is solved
  // again (every few hundred updates); from a change boost until one memory
  // after it, the value from before. No allocation.
  Eigen::Matrix3d mode_cross_covariance(int i, int j) const noexcept;
  // What a test for a change of the estimate needs: the covariance of its own
  // sampling fluctuation, sigma^2 ((J + R)^-1 J (J + R)^-1)_ii, mapped as
  // mode_covariance() maps its block. It leaves out the prior R's share of
  // mode_covariance(), the uncertainty about where the plant lies along a
  // direction the data leave open: along it the estimate does not move, so
  // what moves it there is a change of the plant. Equal to mode_covariance()
  // with one submodel, and from a change boost or a restore until the joint
  // information holds a memory again and is solved. No allocation.
  Eigen::Matrix3d mode_sampling_covariance(int i) const noexcept;
  // Covariance of theta_i (physical units), sigma^2 (P_i + C_i).
  Eigen::MatrixXd covariance(int i) const;
  double residual_rms() const noexcept;  // output error over the residual window
  double noise_variance() const noexcept;
  const EstimatorStatus& status() const noexcept;

  // A copy of the state (allocates: never inside the real-time loop's step()).
  EstimatorState state() const;
  // Continues from `state` as if it had run the samples itself, except that the
  // prefilter and controller states restart from rest: the first sample after
  // restore() counts as a gap (kGap), also when its time is not after the saved
  // last sample (a restarted controller clock); later samples are checked as
  // usual. Throws
  // std::invalid_argument when the state does not fit this estimator's structure
  // (submodel count, n, m, rigid poles, matrix sizes) or holds non-finite or
  // invalid numbers; the estimator is unchanged then. A pending warm-up fit is
  // dropped (a job taken before can no longer be applied).
  void restore(const EstimatorState& state);

 private:
  unsigned fit_window() noexcept;  // the (re)fit of a complete window: kWarmingUp [| kWarmupFitPending]
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace modalwatch
