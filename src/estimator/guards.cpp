// The guards of the recursive estimator that act on its whole state: the
// restart of the filters after a gap, and the last good state it saves now and
// then and returns to on a reset (a divergence, a non-finite model or update).
// The per-sample checks that trigger them (outliers, divergence, excitation)
// are steps 2 and 3 of step.cpp; the stability projection is update.hpp's.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "impl.hpp"

namespace modalwatch {

// At rest, and discretised for the current theta (after an update they may be
// one update behind it).
void RecursiveEstimator::Impl::reset_filters() {
  for (auto& b : blocks) {
    rediscretise(b);
    b.filters.reset();
    b.xu = b.xz = 0.0;
  }
  controller.reset();
}

// After a gap that is not bridged (or a reset) the filters restart from rest,
// and the model output needs a few time constants of the slowest mode to catch
// up with the data. That transient is neither a divergence nor information
// about theta: as in the warm-up (section 4.7), the filters run without updating theta, first until
// the modes' free response has died out (transient_samples()), then until the
// output error is back near the noise level (at most kSettleWindows residual
// windows more, after which updates resume so that a plant that changed during
// the gap can still be followed); the divergence detector is not consulted
// meanwhile. A gap within that time starts the wait again: a cluster of gaps
// is missing information, never new information.
void RecursiveEstimator::Impl::restart_filters() {
  reset_filters();
  loop_known = 0;  // the plant loop's history no longer runs up to the next sample
  // Unsettled until the short-term error, started at the divergence level, has
  // come down to near the noise level on the restarted filters' own output.
  e_short = cfg.divergence_ratio * cfg.divergence_ratio * e_var_good;
  constexpr double kSettleWindows = 4.0;
  transient = transient_samples();
  bridged = 0;
  settling = transient + static_cast<std::uint64_t>(kSettleWindows / (1.0 - e_alpha));
  outlier_run = 0;
  refit_armed = shadow_refit = false;
}

// In closed loop a gap short against the modes' decay times is bridged
// instead: over the missing samples the plant's own loop goes on, the
// controller from its state at the last sample (known from the last u and
// r - y) and the model standing in for the plant, with r interpolated
// linearly; the filters run through them without updating theta. What the
// stand-in misses (the noise over the gap, the model's error)
// disturbs the filter states by its response over the gap, against all of
// their content when they restart from rest; and the restart's wait (the
// slowest mode's decay, then the output error's) would hold every update for
// that long after each of the gaps a lossy link makes about once a second. In
// open loop nothing stands in for an unknown input, and the filters restart.
// false: not bridged, the filters must restart.
bool RecursiveEstimator::Impl::bridge(const Sample& next, double dt) {
  constexpr double kBridgeFraction = 0.25;  // of the shortest decay time
  const double T = cfg.sample_time;
  const double missing = std::round(dt / T) - 1.0;
  const std::size_t order = loop_u.size();
  if (!cfg.closed_loop || !(missing >= 1.0) || inputs_lost || loop_known < order) return false;
  if (dt > kBridgeFraction * shortest_decay_time()) return false;
  // C_d's state (direct form II transposed) after the last sample, from the
  // last inputs e = r - y and outputs u: z_i = sum_{j > i} b_j e_{k+i+1-j} - a_j u_{k+i+1-j}.
  const std::vector<double>& num = plant_loop.numerator();
  const std::vector<double>& den = plant_loop.denominator();
  for (std::size_t i = 0; i < order; ++i) {
    double zi = 0.0;
    for (std::size_t j = i + 1; j <= order; ++j) {
      const std::size_t back = j - i - 1;  // samples before the newest
      const std::size_t at = (loop_at + order - back) % order;
      zi += (num[j] * loop_e[at] - den[j] * loop_u[at]) / den[0];
    }
    loop_state[i] = zi;
  }
  plant_loop.set_state(loop_state);
  bridging = true;
  const auto n = static_cast<int>(missing);
  for (int k = 1; k <= n; ++k) {
    const double w = static_cast<double>(k) / (n + 1);
    Sample s;
    s.t = t_prev + w * dt;
    s.r = last_r + w * (next.r - last_r);
    s.u = last_u;                                   // not used while bridging
    s.y = std::numeric_limits<double>::quiet_NaN();  // the model stands in (advance())
    advance(s, false);
  }
  bridging = false;
  // Updates go on at once. For the slowest mode's decay time the residual is
  // on probation (advance()): what the stand-in missed would show there.
  bridged = std::max(bridged, transient_samples());
  return true;
}

// One bridged sample of the plant's own loop (the instrument's z_k already
// solved): u_k = C_d(q)(r_k - y_k), y_k the model's output, solved as eq. (29)
// is for a biproper controller.
void RecursiveEstimator::Impl::bridge_plant_loop(double r, double z) {
  using detail::kU;
  using detail::kZ;
  double free = 0.0, D = 0.0;
  for (auto& b : blocks) {
    const double* dz = b.filters.complete_input(kZ, z);
    if (b.biproper) b.xz = b.output(dz);
    b.filters.advance_held(kU);
    free += b.output(b.filters.complete_input(kU, 0.0));
    D += b.feedthrough();
  }
  const double c0 = plant_loop.feedthrough();
  const double u = (c0 * (r - free) + plant_loop.peek(0.0)) / (1.0 + c0 * D);
  const double y = free + D * u;
  plant_loop.step(r - y);
  for (auto& b : blocks) b.xu = b.output(b.filters.complete_input(kU, u));
  record_loop(u, r - y);
}

// The shortest time constant of the current model's free response (s): the
// fastest-decaying pole of any mode or first-order submodel; infinity without.
double RecursiveEstimator::Impl::shortest_decay_time() const {
  double rate = 0.0;  // fastest decay rate, 1/s
  for (const auto& b : blocks) rate = std::max(rate, b.decay_rate(detail::Block::Pole::fastest));
  return rate > 0.0 ? 1.0 / rate : std::numeric_limits<double>::infinity();
}

// Samples until the free response of the slowest mode (and first-order
// submodel) of the current model has decayed to kTransientDecay (a tenth) of
// its start:
// the restarted prefilters and the plant's response to the input before the gap
// differ by that response, and the output error can fall near the noise level
// while its part correlated with the instrument still biases theta. Submodels
// with poles at the origin or of other orders have no such bound (the output
// error alone decides for them).
std::uint64_t RecursiveEstimator::Impl::transient_samples(double decay) const {
  double rate = std::numeric_limits<double>::infinity();  // slowest decay rate, 1/s
  for (const auto& b : blocks) {
    const double r = b.decay_rate();
    if (r > 0.0) rate = std::min(rate, r);
  }
  if (!std::isfinite(rate) || !(rate > 0.0)) return 0;
  const double samples = std::ceil(-std::log(decay) / (rate * cfg.sample_time));
  return samples < 1e12 ? static_cast<std::uint64_t>(samples) : std::uint64_t{1000000000000};
}

namespace {

// The score test's bound for white noise: s^T F^-1 s / sigma^2 is then about
// chi-square with n_theta degrees of freedom over two (s and F sum with the
// same exponential weights), so t = that / n_theta stays below
// chi2_{n_theta}(1 - 1e-4) / (2 n_theta), the quantile by Wilson and Hilferty.
double explained_score(int n_theta) {
  constexpr double kZ = 3.719;  // the standard normal's 1 - 1e-4 quantile
  const double k = std::max(1, n_theta), c = 2.0 / (9.0 * k);
  const double q = k * std::pow(1.0 - c + kZ * std::sqrt(c), 3);
  return q / (2.0 * k);
}

}  // namespace

void RecursiveEstimator::Impl::save_good() {
  for (auto& b : blocks) {
    b.good_theta = b.theta;
    b.good_P = b.P;
  }
  joint.save_good();
  e_var_good = e_var;
  updates_since_good = 0;
}

// The CUSUM's alarm (step.cpp): the change is put on the submodels whose
// instrument the recent output error correlates with. Per block, over e_short's
// window, the score s = sum psi eps and its information F = sum psi psi^T give
// the score test t = s^T F^-1 s / (sigma^2 n_theta): how much of the error
// that block alone explains, per parameter. Blocks within half of the largest
// t get P multiplied by kChangeBoost (and the P bound, for one memory of the
// block: Block::lift_bound()): their estimate then
// rests on a tenth of a memory and follows the change. The others keep theirs
// for change_hold memories of the boosted blocks (no update at all): where two
// modes' instruments are nearly collinear (a few sines, close modes), the
// block-coordinate recursion would otherwise let a healthy neighbour absorb
// part of the change, a bias it then takes tens of memories to undo. A block
// boosted earlier in the same change (still within its change_hold) is not
// held by a later boost that names another one: it may be re-converging from
// a share it took at the first. The divergence test and the CUSUM wait a tenth
// of a memory, while the boosted blocks move.
// Where no block explains more of the error than white noise of its recent
// variance would (every t, taken with e_short for sigma^2, below
// explained_score()) at two alarms in a row, the noise level changed, not the
// plant: the current state is good at the new level, and nothing is boosted.
// One such alarm alone boosts as any other: it may be a change's onset, which
// the next alarm, a tenth of a memory on, explains (held back until then, the
// boost came 0.05 to 0.4 memories later on the bank, and one change was lost).
RecursiveEstimator::Impl::ChangeAnswer RecursiveEstimator::Impl::boost_changed_blocks() {
  constexpr double kChangeBoost = 10.0, kShareOfLargest = 0.5, kWait = 0.1;
  // A block at its memory floor is refitted beside the recursion (step.cpp)
  // only where it explains an order of magnitude more of the error than white
  // noise would: a healthy plant's coloured output error (the paper's, after
  // gaps) alarms the change test on such blocks every few tenths of a memory,
  // with scores up to four times that bound, where a change of a lightly
  // damped mode scores tens of times it.
  constexpr double kFloorChangeScore = 10.0;
  const auto score_test = [this](const detail::Block& b) {
    const detail::ThetaVec x = b.score_info.selfadjointView<Eigen::Upper>().ldlt().solve(b.score);
    const double t = b.score.dot(x) / (e_var_good * b.nt);
    return std::isfinite(t) ? t : 0.0;
  };
  // A block's score test t explains more of the recent error than `times`
  // what white noise would (explained_score()).
  const auto explains = [this](const detail::Block& b, double t, double times) {
    return t * e_var_good > times * explained_score(b.nt) * e_short;
  };
  double largest = 0.0;
  bool explained = false;
  for (const auto& b : blocks) {
    const double t = score_test(b);
    largest = std::max(largest, t);
    explained = explained || explains(b, t, 1.0);
  }
  const bool noise_changed = !explained && unexplained_alarm;  // twice in a row: the noise, not the plant
  unexplained_alarm = !explained && !noise_changed;
  if (noise_changed) {
    save_good();
    e_var_good = std::max(e_var, e_short);
    ++status.noise_changes;
  }
  bool boosted = false, floor_held = false;
  std::uint64_t hold = 0;  // updates the blocks not named keep their estimate
  for (auto& b : blocks) {
    // No shorter than the memory floor (min_memory decay times): faster, the
    // boosted mode winds up with its own prefilters (on the flexible beam's
    // lightly damped mode a 1 % step overshot to -8 %). Nor from the settled
    // floor (EstimatorSettings::settled_memory). An alarm that boosts no block
    // releases those held there that the error correlates with: their floor
    // is min_memory for as long as a boosted block would re-converge, with P
    // as it is, and they are neither held nor saved as good as the boosted
    // ones are (released so, a healthy mode of a poorly excited closed loop
    // took a share of its neighbour's stiffness loss). Beside a boosted block
    // they are held as the others.
    double boost = kChangeBoost, forget = 1.0 - b.lambda;
    bool release = false;
    const double rate = b.decay_rate();
    if (b.forget_per_decay > 0.0 && rate > 0.0) {
      const double floor_forget = b.forget_per_decay * rate;  // 1 - lambda at the floor
      const bool at_settled_floor = forget > b.settled_forget_per_decay * rate;
      release = at_settled_floor && b.settled_forget_per_decay < b.forget_per_decay;
      boost = at_settled_floor ? 1.0 : std::clamp(floor_forget / std::min(forget, floor_forget), 1.0, kChangeBoost);
      forget = std::min(forget, floor_forget);
    }
    const double t = noise_changed ? 0.0 : score_test(b);
    const bool scored = !noise_changed && t >= kShareOfLargest * largest;
    b.named = scored && boost > 1.0;
    floor_held = floor_held || (scored && !release && boost <= 1.0 && explains(b, t, kFloorChangeScore));
    if (scored && release)  // kept only if no block is boosted (below)
      b.min_floor_until =
          std::max(b.min_floor_until, status.updates + static_cast<std::uint64_t>(cfg.change_hold / forget));
    if (b.named) {
      boosted = true;
      b.P *= boost;
      // Without forgetting there is no memory to hold the others for, nor
      // one to lift the bound for (the boost is then bounded at once).
      const auto memory = forget > 0.0 ? static_cast<std::uint64_t>(1.0 / forget) : 0;
      b.lift_bound(boost, memory);
      detail::bound_covariance<0>(b.P.data(), b.p_limit.data(), b.nt);
      const auto own = forget > 0.0 ? static_cast<std::uint64_t>(cfg.change_hold / forget) : 0;
      b.held = 0;
      b.adapting = own;
      hold = std::max(hold, own);
    }
    b.score.setZero();
    b.score_info.setZero();
  }
  for (auto& b : blocks) {
    if (boosted) b.min_floor_until = status.updates + b.adapting;  // releases end, re-convergence does not
    if (!b.named && b.adapting == 0) b.held = std::max(b.held, hold);
  }
  if (boosted) joint.clear();
  rearm = static_cast<std::uint64_t>(kWait / (1.0 - e_alpha));
  if (boosted) ++status.boosts;
  return boosted ? ChangeAnswer::boosted : floor_held ? ChangeAnswer::floor_held : ChangeAnswer::none;
}

// A mode's gain does not change sign in a drift or a fault of that mode (a
// stiffness, damping or gain change moves it by tens of %). When one has, from
// a sign its last good estimate had to within kSignSigmas std, the mode no
// longer describes its physical mode: it has moved onto a neighbour and
// cancels part of that one's change (a weak mode beside a strong one whose
// gain stepped, both named by the change test). Only that block goes back to
// its last good estimate; it keeps it while the blocks that re-converge after
// the change still do, so that the change goes to them alone. Checked as
// often as the good state is saved, and before it is.
bool RecursiveEstimator::Impl::restore_sign_flipped_modes() {
  constexpr double kSignSigmas = 3.0;
  std::uint64_t adapting = 0;
  for (const auto& b : blocks) adapting = std::max(adapting, b.adapting);
  bool restored = false;
  for (auto& b : blocks) {
    if (b.n != 2 || b.m != 0 || b.l != 0) continue;  // modes only: b0 is the gain's sign
    const double gain = b.theta(b.n), good = b.good_theta(b.n);
    const double good_std = std::sqrt(std::max(0.0, e_var_good * b.good_P(b.n, b.n)));
    if (!(gain * good < 0.0 && std::abs(good) > kSignSigmas * good_std)) continue;
    b.theta = b.good_theta;
    b.P = b.good_P;
    b.adapting = b.min_floor_until = 0;
    b.drop_lift();
    b.held = std::max(b.held, adapting);
    rediscretise(b);
    ++status.sign_restores;
    restored = true;
  }
  return restored;
}

void RecursiveEstimator::Impl::restore_good(const char* reason) {
  if (refit_armed && shadow_refit) {
    // The window beside the recursion holds the ring's samples in order.
    ring_head = static_cast<Eigen::Index>(buffered) % wt.size();
    history = std::min<Eigen::Index>(buffered, wt.size());
  }
  for (auto& b : blocks) {
    b.held = b.adapting = b.min_floor_until = 0;
    b.drop_lift();
    b.theta = b.good_theta;
    b.P = b.good_P;
  }
  joint.restore_good();
  noise_at_reset = noise_at_reset > 0.0 ? std::min(noise_at_reset, e_var_good) : e_var_good;
  // The noise level goes back with the state. The first residuals on the
  // restarted filters are their transient, not noise: they must not set e_var
  // again (as the very first residual does), only the outlier test restarts
  // (after a hundred residuals, as at the start).
  e_var = e_var_good;
  e_count = 1;
  restart_filters();  // at rest, discretised for the restored theta
  // Give the restored state one residual window before judging it again.
  rearm = static_cast<std::uint64_t>(1.0 / (1.0 - e_alpha));
  if (reason == kResetDiverged && may_refit()) arm_refit(reason);
  ++status.resets;
  status.last_reset_reason = reason;
}

// The refit's window (restore_good, or beside the recursion after a change
// the memory floor holds: step.cpp).
void RecursiveEstimator::Impl::arm_refit(const char* reason) {
  // The window starts with the samples before the reset, as far back as the
  // ring holds beside the fitted part and the slowest mode's free response
  // needs to die out: the fit's filters start from rest, the plant did not,
  // and a tenth of a lightly damped mode's response left at the fit's start
  // biases it (its gain by tens of %). The fit's window is replayed into the
  // recursion's filters (finish_warmup), so the samples after the reset
  // need not wait out the restarted filters' transient and then a memory:
  // the fit comes when both have passed, the later of the two, the
  // transient still first giving the restored state the chance to settle (a
  // burst) and a change the time to end (a ramp).
  constexpr double kWindowDecay = 1e-3;
  const auto fitted = static_cast<Eigen::Index>(refit_samples());
  const auto settle = std::min(static_cast<Eigen::Index>(transient_samples(kWindowDecay)), wt.size() - fitted);
  const auto wait = std::min(std::max<Eigen::Index>(0, static_cast<Eigen::Index>(transient) - fitted), settle);
  const Eigen::Index before = std::max<Eigen::Index>(0, std::min(history, settle - wait));
  const Eigen::Index first = (ring_head - before + wt.size()) % wt.size();
  for_each_window_array([&](Eigen::VectorXd& w) { std::rotate(w.data(), w.data() + first, w.data() + w.size()); });
  refit_armed = true;
  refit_retries = 0;
  quick_refits = soon_after_fit() ? quick_refits + 1 : 0;
  buffered = static_cast<int>(before);
  // Where the ring holds less, the samples after the reset make up the
  // rest, up to the restarted filters' own transient (at least `wait`:
  // before <= settle - wait and wait <= transient).
  const Eigen::Index after = std::min(static_cast<Eigen::Index>(transient), settle - before);
  window_settle = static_cast<int>(before + after);
  window_samples = static_cast<int>(fitted) + window_settle;
  refit_trigger = reason;
  changing_refits = 0;
}

// A divergence on a model that has fitted the data for a while is a runaway of
// the estimate, an output burst, or the plant changing. restore_good() and the
// wait for the output error to settle handle the first two; for a change the
// wait is in vain (the restored state no longer fits) and forgetting then
// takes a memory to follow from there. So the samples from the reset on are
// kept, behind the ring's samples before it, and one memory after the reset
// that window is fitted as the warm-up is (section 4.7), from the last good
// state, which is also its prior; the samples before the reset only drive the
// fit's prefilters (the fit's simulation starts from rest, the plant did not).
// The fit decides whether the change was real (refit_verdict in
// warmup_fit.cpp: the restored state's misfit persists over the window, and
// the fit removes most of it);
// otherwise, and where the wait for the error to settle ends sooner, the wait
// stays. The window is the longest memory of the submodels (the data their
// recursive estimates rest on), at most the warm-up window. A divergence soon
// after the warm-up fit says that the fit itself did not describe the data (a
// model that lacks an effect, a fit that did not converge): a refit would
// repeat it, and the reset and wait stay. Soon after a refit it says more
// often that the change went on past the refit's window (a ramp longer than
// the transient and the memory after the reset, whose window the refit took
// as settled): up to kRefitRetries refits in a row are taken so. Waited out,
// the estimates stayed at the first window's compromise for the wait's four
// memories and more, and then converged from it at the memory floor's pace
// (a flexible mode's 2 s ramp: wn 1.6 % off 8 memories after the ramp's end).
int RecursiveEstimator::Impl::refit_samples() const {
  const double lambda = *std::max_element(cfg.forgetting.begin(), cfg.forgetting.end());
  const double memory = lambda < 1.0 ? 1.0 / (1.0 - lambda) : std::numeric_limits<double>::infinity();
  return static_cast<int>(std::min(memory, static_cast<double>(cfg.warmup_samples)));
}

bool RecursiveEstimator::Impl::soon_after_fit() const {
  constexpr double kFittedWindows = 4.0;  // as long as a restart may wait to settle
  return !(static_cast<double>(status.samples - warm_since_sample) > kFittedWindows / (1.0 - e_alpha));
}

bool RecursiveEstimator::Impl::may_refit() const {
  return refit_context && cfg.fit_on_warmup && !blocks.empty() &&
         (!soon_after_fit() || (last_fit_refit && quick_refits < kRefitRetries)) &&
         transient_samples() + static_cast<std::uint64_t>(refit_samples()) <= static_cast<std::uint64_t>(wt.size());
}

// Settling after a divergence (restore_good), the sample just taken: an error
// that settles ends the wait as usual; a complete window goes to a refit
// (true). A missing output or a gap cannot be fitted: the wait goes on as before.
bool RecursiveEstimator::Impl::keep_for_refit(const Sample& s, bool bad_values) {
  if ((settling == 0 && !shadow_refit) || bad_values) {
    refit_armed = shadow_refit = false;
    forget_history();
    return false;
  }
  buffer_window_sample(s);
  return buffered == window_samples;
}

// The window is complete: fit it from the last good state (theta is that
// state while settling: no update meanwhile).
void RecursiveEstimator::Impl::write_refit_start() {
  refit_context->noise_variance = e_var_good;
  AdditiveModel& start = refit_context->initial;
  for (std::size_t i = 0; i < blocks.size(); ++i) {
    const detail::Block& b = blocks[i];
    Submodel& s = start.submodels[i];
    for (int j = 0; j < s.n; ++j) s.a(j) = b.good_theta(j) / b.scale(j);
    for (int k = 0; k <= s.m; ++k) s.b(k) = b.good_theta(s.n + k) / b.scale(s.n + k);
  }
}

void RecursiveEstimator::Impl::begin_refit() {
  // Beside the recursion the good state goes on being saved: the start is the
  // one at the alarm (arm_refit), before the change, but in the window after
  // a compromise.
  if (!shadow_refit || changing_refits > 0) write_refit_start();
  const bool change = refit_trigger == kChangeRefit;
  refit_context->misfit_ratio =
      change ? kSettledRatio * kSettledRatio : 0.25 * cfg.divergence_ratio * cfg.divergence_ratio;
  refit_context->closer_ratio = change ? 1.0 / (kSettledRatio * kSettledRatio) : 0.25;
  refit_context->follow_up = changing_refits > 0;
  refit_armed = false;
  refitting = true;
  // Beside the recursion the estimates stand meanwhile: no warm-up to show.
  status.warming_up = !shadow_refit;
  reason_before_refit = status.last_reset_reason;
  status.last_reset_reason = refit_trigger == kChangeRefit ? kChangeRefit : kResetRefit;
}

}  // namespace modalwatch
