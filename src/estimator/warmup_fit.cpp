// The warm-up fit (section 4.7): the offline additive SRIVC on the warm-up
// window as a job that may run on another thread (WarmupFit), and the
// estimator's part, taking the job and applying its result.
#include <algorithm>
#include <cmath>
#include <exception>
#include <new>
#include <stdexcept>
#include <utility>
#include <vector>

#include <Eigen/LU>
#include <Eigen/QR>

#include "impl.hpp"
#include "modalwatch/polynomial.hpp"
#include "modalwatch/record.hpp"
#include "modalwatch/srivc.hpp"

namespace modalwatch {

namespace {

// A refit replaces a state that tracked the plant until the divergence, so it
// must earn it (a window that leaves a direction of the model open, a setpoint
// with too few frequencies, is no reason to refuse: the fusion with the
// restored state in run() keeps that state along the open direction):
// - a refit follows the modes it had, it does not identify the structure
//   anew: each resonance keeps its place in frequency order and moves by less
//   than kRefitFrequencyRatio (a fault of a third of the stiffness moves wn by
//   18 %); a fit that moves one further has taken another mode's place or
//   the noise's;
// - the last good state's misfit must persist: a changed plant leaves an
//   output error that stays (or grows, on a ramp) at half the divergence
//   ratio times the noise level or more over the fitted part's second half;
//   an output burst's after-effect dies down with the modes' decay instead;
// - a fit no closer to the data than the last good state says nothing new:
//   its output error on the fitted part must be below a quarter of that
//   state's (half its RMS), where a change that tripped the divergence reset
//   left ten times the noise level or more. After a change the change test
//   found where the memory floor allows no boost (a refit beside the
//   recursion: step.cpp), the misfit is smaller: it must persist at the
//   settled level (kSettledRatio times the noise RMS), and the fit's RMS be
//   kSettledRatio times smaller than the last good state's;
// - the window after a compromise (below) is fitted to leave that
//   compromise: the change is established, and a fit closer to the window
//   than the compromise is taken;
// - a window the plant still changed in (a ramp) has no single model: the
//   restored state's misfit still grows (by more than a quarter from the
//   first half to the second), or the fit does not describe the window to
//   the level at which the restored state would count as settled. Where its
//   fit is still closer than the restored state (as above), it is taken
//   (`accepted_changing`): its estimates follow the change, and the next
//   window is fitted from it (finish_warmup), so that the compromise, which
//   lands in whichever directions the excitation leaves loose, does not
//   stay. Otherwise the window is `unsettled`, and the next one is fitted
//   instead. Waiting for a window clear of the ramp held the estimates at
//   the plant before it for as long as the ramp lasted (four windows on a
//   ramp of 2.4 memories).
enum class RefitVerdict { accepted, accepted_changing, refused, unsettled };

// How far a fit's modes may move from its start: a refit's start is the last
// good state (a third of the stiffness moves wn by 18 %); the warm-up fit's is
// the configured model, rougher (a start 50 % off the plant's frequency
// converges).
constexpr double kRefitFrequencyRatio = 1.5;
constexpr double kWarmupFrequencyRatio = 2.0;

// Each resonance of `after` keeps its place in frequency order among the
// resonances of `before` on its input and moves by less than `ratio` either way.
bool keeps_the_modes(const AdditiveModel& before_model, const AdditiveModel& after_model, double ratio) {
  const auto& before = before_model.submodels;
  const auto& after = after_model.submodels;
  for (std::size_t i = 0; i < before.size(); ++i) {
    if (!before[i].is_resonance() || !after[i].is_resonance()) continue;
    const ModalParameters p0 = modal_parameters(before[i]), p1 = modal_parameters(after[i]);
    const double w0 = p0.wn, w1 = p1.wn;
    if (!(w1 < ratio * w0 && w0 < ratio * w1)) return false;
    // A gain of zero or of the other sign: the fit dropped the mode (an
    // unfactored start splits the plant into fewer modes than configured).
    if (!(p1.gain * p0.gain > 0.0)) return false;
    // Among the resonances of one input: submodels on different inputs cannot
    // take each other's place (each sees its own input), and the start gives
    // one resonance the same frequency on every input it drives.
    for (std::size_t j = 0; j < i; ++j)
      if (before[j].input == before[i].input && before[j].is_resonance() && after[j].is_resonance() &&
          (modal_parameters(before[j]).wn < w0) != (modal_parameters(after[j]).wn < w1))
        return false;
  }
  return true;
}

// The restored state's simulation over the window, the yardstick of every
// candidate fit.
Eigen::VectorXd simulate_start(const Record& window, const AdditiveModel& start, const EstimatorSettings& cfg) {
  Eigen::VectorXd y_start;
  if (cfg.closed_loop) {
    Eigen::VectorXd z;
    simulate_loop(start, cfg.controller, window.r, window.sample_time(), z, y_start);
  } else {
    y_start = simulate_model(start, window);  // each submodel on its own input
  }
  return y_start;
}

// The output error of `model` over the fitted part (after `settle`) started
// in the state that best explains it (started_in_state), on the measured
// inputs as the estimator's own residual is: the simulation from rest lacks
// the plant's state, and where the plant changed during the settling part (the
// change that tripped the reset happens there), the fitted part begins with
// the changed plant's response to a state the simulation does not have. That
// response decays with the modes (a third of a memory for a lightly damped
// one), and is not a misfit of the model.
double misfit_in_state(const Record& window, Eigen::Index settle, const AdditiveModel& model) {
  const Eigen::Index n = window.y.size() - settle;
  const Record started = started_in_state(window, model, settle);
  return (window.y.tail(n) - simulate_model(model, started).tail(n)).squaredNorm();
}

// y_start: the restored state's simulation over the window (simulate_start);
// e_start: its misfit_in_state.
RefitVerdict refit_verdict(const Record& window, Eigen::Index settle, const AdditiveModel& start,
                           const Eigen::VectorXd& y_start, double e_start, double noise_variance,
                           double misfit_ratio, double closer_ratio, bool follow_up, const FitResult& fit) {
  constexpr auto refused = RefitVerdict::refused;
  if (!keeps_the_modes(start, fit.model, kRefitFrequencyRatio)) return refused;
  const Eigen::Index n = window.y.size() - settle;
  if (n < 2 || fit.simulated.size() != window.y.size() || y_start.size() != window.y.size()) return refused;
  const Eigen::Index half = n / 2;
  const double e_first = (window.y.segment(settle, half) - y_start.segment(settle, half)).squaredNorm() / half;
  const double e_second = (window.y.tail(n - half) - y_start.tail(n - half)).squaredNorm() / (n - half);
  const double settled = misfit_ratio * noise_variance;
  if (!follow_up && !(e_second > settled && e_second > 0.5 * e_first)) return refused;
  const double e_fit = misfit_in_state(window, settle, fit.model);
  constexpr double kStillChanging = 1.25;  // the misfit's growth from the first half to the second
  const bool changing = !(e_fit < settled * n) || e_second > kStillChanging * e_first;
  if (e_fit < (follow_up ? 1.0 : closer_ratio) * e_start)
    return changing ? RefitVerdict::accepted_changing : RefitVerdict::accepted;
  return changing ? RefitVerdict::unsettled : refused;
}

}  // namespace

WarmupFit::WarmupFit() = default;
WarmupFit::~WarmupFit() = default;
WarmupFit::WarmupFit(WarmupFit&&) noexcept = default;
WarmupFit& WarmupFit::operator=(WarmupFit&&) noexcept = default;

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
    for (const Eigen::VectorXd& v : further_u_) window.further_u.emplace_back(v.head(N));
    const auto fitted = window.y.tail(N - settle_);
    const double y_var = (fitted.array() - fitted.mean()).square().mean();
    AdditiveModel model = initial;
    std::vector<Eigen::MatrixXd> cov;
    std::vector<Eigen::VectorXd> bound;
    double sigma2 = 0.0;
    bool fit_used = false;
    if (cfg.fit_on_warmup) {
      try {
        SrivcOptions o;
        o.closed_loop = cfg.closed_loop;
        o.controller = cfg.controller;
        o.output_hold = cfg.output_hold;
        o.max_iterations = cfg.warmup_iterations;
        o.settle_samples = settle_;
        // A refit's settling part holds the change that tripped the reset.
        o.free_initial_state = refit_;
        Eigen::VectorXd y_start;  // the restored state's, once, for the first candidate that gets that far
        double e_start = 0.0;
        bool last_changing = false;  // the last candidate's verdict: accepted_changing
        const auto usable = [&](const FitResult& f) {
          bool ok = f.model.beta().allFinite() && f.covariance.allFinite() && f.noise_variance > 0.0;
          for (const auto& s : f.model.submodels) ok = ok && (s.n == 0 || s.a(s.n - 1) > 0.0);
          if (!ok) return false;
          // The configured modes name the plant's: a fit that puts one of them
          // on another's frequency (or on none) describes a different plant,
          // and every estimate and flag of that mode would be another's.
          if (!refit_) return keeps_the_modes(initial, f.model, kWarmupFrequencyRatio);
          if (y_start.size() == 0) {
            y_start = simulate_start(window, initial, cfg);
            e_start = misfit_in_state(window, settle_, initial);
          }
          const RefitVerdict v =
              refit_verdict(window, settle_, initial, y_start, e_start, context_->noise_variance,
                            context_->misfit_ratio, context_->closer_ratio, context_->follow_up, f);
          unsettled_ = unsettled_ || v == RefitVerdict::unsettled;
          last_changing = v == RefitVerdict::accepted_changing;
          return v == RefitVerdict::accepted || v == RefitVerdict::accepted_changing;
        };
        // A refit starts from the state that tracked each mode; the unfactored
        // start (which may find the changed plant where that start does not)
        // only where it does not give a usable fit.
        if (refit_) o.unfactored_start = false;
        FitResult fit;
        bool ok = false;
        const auto fit_with = [&](const SrivcOptions& opts) {
          fit = fit_srivc(window, initial, opts);
          ok = usable(fit);
          changing_ = ok && last_changing;
        };
        if (refit_ && initial.submodels.size() >= 2) {
          // A change of one submodel first (isolation, as a GLR test picks the
          // hypothesis of one changed mode): each submodel fitted alone, the
          // others held at the last good state. Where the excitation leaves a
          // direction open (a square wave below a mode, a few sines), a fit of
          // every submodel moves the healthy ones along it to absorb what the
          // window's onset of the change leaves, and flags them; held, they
          // cannot. Of the fits the verdict accepts, the closest to the window.
          // A wrong submodel's fit leaves the change unexplained: that says
          // nothing of whether the plant still changed (unsettled_).
          const bool unsettled_before = unsettled_;
          double best = std::numeric_limits<double>::infinity();
          const auto& subs = initial.submodels;
          for (std::size_t i = 0; i < subs.size(); ++i) {
            if (!subs[i].poles_of.empty()) continue;  // one resonance on several inputs: freed with its lead
            SrivcOptions alone = o;
            alone.frozen.assign(subs.size(), true);
            for (std::size_t j = 0; j < subs.size(); ++j)
              if (j == i || subs[j].poles_of == subs[i].name) alone.frozen[j] = false;
            FitResult f = fit_srivc(window, initial, alone);
            if (!usable(f)) continue;
            const double e = (window.y.tail(N - settle_) - f.simulated.tail(N - settle_)).squaredNorm();
            if (e < best) {
              best = e;
              fit = std::move(f);
              ok = true;
              changing_ = last_changing;
            }
          }
          unsettled_ = unsettled_before;
        }
        if (!ok) {
          fit_with(o);
        }
        if (!ok && o.free_initial_state) {
          // Where the window leaves directions open (a few sines), the free
          // state can take the place of what the excitation does not show,
          // and the fit wanders off: the fit from rest instead.
          o.free_initial_state = false;
          fit_with(o);
        }
        if (!ok && refit_ && initial.submodels.size() >= 2) {
          o.unfactored_start = true;
          fit_with(o);
        } else if (!ok && !refit_ && fit.start == "unfactored") {
          // The unfactored start won on output error but moved the modes: the
          // start from the configured modes alone.
          o.unfactored_start = false;
          fit_with(o);
        }
        if (ok) {
          // theta(t0), P(t0): the configured model as a prior (relative std rho per
          // parameter) fused with the fit and its covariance C, per submodel:
          //   C0 = (Cp^-1 + C^-1)^-1,  theta0 = C0 (Cp^-1 theta_cfg + C^-1 theta_fit).
          // Where the window is informative the fit dominates; along directions it
          // leaves undetermined (a setpoint with few frequencies) the prior holds.
          // Computed in units of the prior's std (Cp = S^2): the parameters span
          // many decades (a_2 = 1/wn^2 beside b_0), and the pseudo-inverse of C in
          // physical units would drop the small ones' directions as rank-deficient,
          // leaving the prior there whatever the data say.
          sigma2 = fit.noise_variance;
          const double rho = cfg.initial_covariance_relative;
          for (std::size_t i = 0; i < model.submodels.size(); ++i) {
            const Eigen::VectorXd th_cfg = initial.submodels[i].theta(), th_fit = fit.model.submodels[i].theta();
            const Eigen::MatrixXd C = fit.theta_covariance(static_cast<int>(i));
            Eigen::VectorXd prior_std(th_cfg.size());
            for (Eigen::Index j = 0; j < th_cfg.size(); ++j) prior_std(j) = rho * std::max(std::abs(th_cfg(j)), 1e-12);
            const Eigen::VectorXd inv_std = prior_std.cwiseInverse();
            const Eigen::MatrixXd Cs = inv_std.asDiagonal() * C * inv_std.asDiagonal();
            const Eigen::MatrixXd Cs_inv = Cs.completeOrthogonalDecomposition().pseudoInverse();
            Eigen::MatrixXd info = Cs_inv;
            info.diagonal().array() += 1.0;
            const Eigen::MatrixXd C0s = info.inverse();
            const Eigen::VectorXd th0s =
                C0s * (inv_std.cwiseProduct(th_cfg) + Cs_inv * inv_std.cwiseProduct(th_fit));
            const Eigen::MatrixXd C0 = prior_std.asDiagonal() * C0s * prior_std.asDiagonal();
            // The same with one memory of the window's data (the recursion's
            // steady state), the reference of the covariance bound: where the
            // window is longer than the memory, its fit holds more
            // information than the recursion will keep.
            const double lambda = cfg.forgetting.empty() ? 1.0 : cfg.forgetting[i];
            const double memories = std::max(1.0, static_cast<double>(N - settle_) * (1.0 - lambda));
            Eigen::MatrixXd info_memory = Cs_inv / memories;
            info_memory.diagonal().array() += 1.0;
            bound.push_back(prior_std.cwiseAbs2().cwiseProduct(info_memory.inverse().diagonal()));
            Eigen::VectorXd th0 = prior_std.cwiseProduct(th0s);
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
          if (refit_) replay_ = started_in_state(window, model, settle_);
        }
      } catch (const std::exception&) {
        // Fall back to the configured model: reported through warmup_fit_used.
      }
    }
    model_ = std::move(model);
    covariance_ = std::move(cov);
    bound_variance_ = std::move(bound);
    sigma2_ = sigma2;
    y_var_ = y_var;
    fit_used_ = fit_used;
  } catch (...) {
    failed_ = true;  // allocation: apply_warmup_fit() restarts the warm-up
  }
  done_ = true;
}

// The next memory after a window of N samples is the next refit's window;
// this one's end drives its prefilters.
void RecursiveEstimator::Impl::arm_next_window(int N) {
  const Eigen::Index keep = std::min<Eigen::Index>(window_settle, N);
  for_each_window_array([&](Eigen::VectorXd& w) { std::copy(w.data() + N - keep, w.data() + N, w.data()); });
  buffered = static_cast<int>(keep);
  window_settle = static_cast<int>(keep);
  window_samples = window_settle + refit_samples();
  refit_armed = true;
}

// The estimator's part: build from the fit's result, then run the filters over
// the window without updating (section 4.7). A refit that did not earn its
// place changes nothing: the restored state goes on waiting for its error to
// settle, as without a refit.
void RecursiveEstimator::Impl::finish_warmup(const WarmupFit& fit) {
  const int N = buffered;
  const double sigma2 = fit.sigma2_;
  ++status.fits;
  if (refitting) changing_refits = fit.fit_used_ && fit.changing_ ? changing_refits + 1 : 0;
  if (refitting && !fit.fit_used_) {
    status.warming_up = false;
    refitting = false;
    status.fitted_window = 0.0;
    status.last_reset_reason = shadow_refit ? reason_before_refit : kResetDiverged;
    if (fit.unsettled_ && refit_retries < kRefitRetries && (settling > 0 || shadow_refit)) {
      ++refit_retries;
      arm_next_window(N);
      return;
    }
    shadow_refit = false;
    window_samples = window_settle = 0;
    forget_history();
    return;
  }
  shadow_refit = false;
  settling = transient = bridged = rearm = 0;
  outlier_run = 0;
  if (fit.fit_used_) {
    status.warmup_fit_used = true;
    status.fitted_window = (N - fit.settle_) * cfg.sample_time;
  }
  // A refit's P_i(t0) is the restored state's, carried to the refit's time
  // scale. The recursion updates each submodel with the others held (eq. 15),
  // so its P_i is the inverse of that submodel's own information; the window
  // after a reset has the same excitation and the plant moved little (less
  // than kRefitFrequencyRatio), so that information is what the recursion
  // would have gathered there. The fit's covariance is not: its block for
  // submodel i also holds what the window cannot tell apart between
  // submodels (two gains that trade against each other at a setpoint's lowest
  // frequency), and as P_i it makes each submodel's update answer for the
  // other's share, so that the two run apart along that direction.
  std::vector<detail::Block> restored;  // a refit's: the last good state, restored at the reset
  if (refitting) restored = std::exchange(blocks, {});
  build(fit.model_, fit.covariance_.empty() ? nullptr : &fit.covariance_, sigma2, fit.y_var_,
        fit.bound_variance_.empty() ? nullptr : &fit.bound_variance_);
  for (std::size_t i = 0; i < restored.size(); ++i) {
    detail::Block& b = blocks[i];
    const detail::ThetaVec r = b.scale.cwiseQuotient(restored[i].scale);
    b.P = b.good_P = r.asDiagonal() * restored[i].good_P * r.asDiagonal();
    b.p_bound = restored[i].p_bound.cwiseProduct(r).cwiseProduct(r);
    b.drop_lift();
  }
  if (sigma2 > 0.0) {
    e_var = e_short = e_var_good = sigma2;
    e_count = 1000;
  }
  // A refit's window was cut from a running plant: the replay's filters start
  // from rest, and their transient is neither noise nor outliers. The replay
  // waits it out as a restart does (restart_filters()), and the noise level
  // afterwards is the last good state's: the sensor's noise did not change
  // with the plant, and the fit's own output error holds its simulation's
  // start from rest.
  const double noise_before = refitting ? refit_context->noise_variance : 0.0;
  if (noise_before > 0.0) {
    e_var = e_var_good = noise_before;
    e_short = cfg.divergence_ratio * cfg.divergence_ratio * e_var_good;
    transient = static_cast<std::uint64_t>(N);
    settling = transient + 1;
  }
  // Run the filters over the window with theta(t0), without updating (section
  // 4.7); a refit's window as its fit saw it, to start in the fit's state.
  const Record& as_fitted = fit.replay_;
  const bool replay_as_fitted = as_fitted.y.size() == N && as_fitted.inputs() == 1 + further_inputs;
  double p = 0.0;
  Sample s;
  s.further_inputs = further_inputs;
  for (int k = 0; k < N; ++k) {
    s.t = wt(k);
    s.u = wu(k);
    s.r = cfg.closed_loop ? wr(k) : 0.0;
    for (int j = 0; j < further_inputs; ++j)
      s.further_u[static_cast<std::size_t>(j)] = wfu[static_cast<std::size_t>(j)](k);
    p += further_inputs > 0 ? input_power(s) : wu(k) * wu(k);  // as advance() measures it
    if (replay_as_fitted) {
      s.u = as_fitted.u(k);
      for (int j = 0; j < further_inputs; ++j)
        s.further_u[static_cast<std::size_t>(j)] = as_fitted.further_u[static_cast<std::size_t>(j)](k);
    }
    s.y = replay_as_fitted ? as_fitted.y(k) : wy(k);
    advance(s, false);
  }
  if (noise_before > 0.0) {
    settling = transient = 0;
    e_var = e_short = e_var_good = noise_before;
  }
  pow_ref = p / std::max(N, 1);
  status.warming_up = false;
  warm_since_sample = status.samples;
  last_fit_refit = refitting;
  if (refitting && fit.changing_ && changing_refits <= kRefitRetries) {
    // The plant still changed in the window: its fit is a compromise, closer
    // to the plant than the restored state but biased where the window leaves
    // directions loose. The next memory is fitted from it, its updates held
    // until then, as after an unsettled window.
    arm_next_window(N);
    transient = static_cast<std::uint64_t>(refit_samples());
    settling = transient + 1;
    refitting = false;
    return;
  }
  refitting = false;
  window_samples = window_settle = 0;
  forget_history();
}

bool RecursiveEstimator::warmup_fit_pending() const noexcept { return impl_->fit_pending; }

WarmupFit RecursiveEstimator::take_warmup_fit() {
  Impl& m = *impl_;
  if (!m.fit_pending || m.fit_taken)
    throw std::logic_error("RecursiveEstimator::take_warmup_fit: no warm-up fit pending");
  WarmupFit job;
  job.context_ = m.refitting ? m.refit_context : m.fit_context;
  job.generation_ = m.fit_generation;
  job.n_ = m.buffered;
  job.settle_ = m.refitting ? m.window_settle : 0;
  job.refit_ = m.refitting;
  job.t_.swap(m.wt);  // Eigen swaps the buffers: no copy, no allocation
  job.u_.swap(m.wu);
  job.y_.swap(m.wy);
  job.r_.swap(m.wr);
  job.further_u_.swap(m.wfu);
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
  m.wfu.swap(job.further_u_);
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

}  // namespace modalwatch
