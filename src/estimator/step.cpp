// The per-sample path of the recursive estimator (Algorithm 1): one sample
// through the instrument, the guards' checks and the block updates, compiled
// once per instruction set (hot_path.hpp).
#include <algorithm>
#include <cmath>
#include <cstdint>

#include <Eigen/Core>

#include "impl.hpp"
#include "modalwatch/estimator.hpp"
#include "modalwatch/prefilter.hpp"
#include "update.hpp"

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

}  // namespace

using namespace detail;

// Out of line: its Eigen temporaries would otherwise cost every mode's
// rediscretise() a heavier call frame.
[[gnu::noinline]] void RecursiveEstimator::Impl::rediscretise_prefilters(Block& b, double Ts) {
  Prefilter* f = b.filters.f;
  const FilterVector a = b.filter_a_poly();
  const Discretization da = discretize(a, Ts, cfg.output_hold);
  f[kY].set_denominator(a, da);
  f[kX].set_denominator(a, da);
  if (b.l == 0 && cfg.output_hold == Hold::zoh) {  // p^l A = A: one discretisation serves all four
    f[kU].set_denominator(a, da);
    f[kZ].set_denominator(a, da);
    return;
  }
  const FilterVector den = b.filter_denominator();
  const Discretization dd = discretize(den, Ts, Hold::zoh);
  f[kU].set_denominator(den, dd);
  f[kZ].set_denominator(den, dd);
}

bool RecursiveEstimator::Impl::select_kernel(StepKernel k) noexcept {
  switch (k) {
    case StepKernel::portable:
      kernel = further_inputs > 0 ? &Impl::advance_portable<true> : &Impl::advance_portable<false>;
      break;
    case StepKernel::avx2_fma:
#if MODALWATCH_HAVE_AVX2_FMA
      if (!cpu_has_avx2_fma()) return false;
      kernel = further_inputs > 0 ? &Impl::advance_avx2_fma<true> : &Impl::advance_avx2_fma<false>;
      break;
#else
      return false;
#endif
  }
  kernel_id = k;
  return true;
}

template <bool kSeveralInputs>
unsigned RecursiveEstimator::Impl::advance_portable(const Sample& s, bool allow_update) {
  return advance_body<kSeveralInputs>(s, allow_update);
}

#if MODALWATCH_HAVE_AVX2_FMA
template <bool kSeveralInputs>
unsigned RecursiveEstimator::Impl::advance_avx2_fma(const Sample& s, bool allow_update) {
  return advance_body<kSeveralInputs>(s, allow_update);
}
#endif

// kSeveralInputs: each block takes the input its submodel names (open loop);
// without, every block takes u, and a single-input model runs the arithmetic
// it ran before several inputs existed, instruction for instruction.
template <bool kSeveralInputs>
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
    if (bridging) {
      bridge_plant_loop(s.r, z);
      for (auto& b : blocks) y_hat += b.xu;
    } else {
      for (auto& b : blocks) {
        const double* dz = b.filters.complete_input(kZ, z);
        // Strictly proper (m < n + l): the output uses the state alone, not z_k.
        if (b.biproper) b.xz = b.output(dz);
        b.xu = b.output(b.filters.take_input(kU, s.u));
        y_hat += b.xu;
      }
    }
  } else {
    for (auto& b : blocks) {
      b.xu = b.output(b.filters.take_input(kU, block_input<kSeveralInputs>(b, s)));
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
  // how y_hat was rounded (with FMA or without; round_off_level()).
  const auto above_round_off = [&] { return std::abs(e) > round_off_level(); };
  // While the restarted filters settle (settling > 0), the output error is
  // mostly their transient, not noise: e_var (and with it every std) keeps its
  // value, and e_short follows the error to tell when the transient has died out.
  // An outlier is then one far outside that transient (e_short) too: replacing
  // the transient itself by y_hat would feed the model to its own prefilters.
  // After a bridged gap (bridged > 0) the residual is on probation: one beyond
  // the outlier level says the stand-in missed what happened in the gap (a
  // setpoint step, a plant change), and the filters restart as after any gap.
  if (bridged > 0 && !bridging) {
    --bridged;
    if (std::isfinite(s.y) && e * e > cfg.outlier_sigma * cfg.outlier_sigma * e_var) restart_filters();
  }
  const bool in_transient = settling > 0;
  if (!std::isfinite(s.y)) {
    y = y_hat;
  } else if (e_count > 100 && outlier_run < kOutlierRun &&
             e * e > cfg.outlier_sigma * cfg.outlier_sigma * (in_transient ? std::max(e_var, e_short) : e_var) &&
             above_round_off()) {
    y = y_hat;
    ++outlier_run;
    ++status.outliers;
    flags |= kOutlier;
    update = false;
  } else {
    outlier_run = 0;
    if (e_count == 0)
      e_var = e * e;
    else if (settling == 0)
      e_var = e_alpha * e_var + (1.0 - e_alpha) * e * e;
    e_short = e_count == 0 ? e * e : e_short_alpha * e_short + (1.0 - e_short_alpha) * e * e;
    ++e_count;
  }
  // Divergence: the output error an order of magnitude above what it was when
  // the last good state was saved. Plant changes that the estimator can follow
  // raise it far less.
  // Settled (kSettledRatio): looser, the updates resume on what is left of the
  // transient, and e_var (every std) grows with it.
  const bool diverging =
      allow_update && e_var_good > 0.0 && e_short > cfg.divergence_ratio * cfg.divergence_ratio * e_var_good;
  // Misfit (EstimatorStatus::misfit): after a reset, until the output error is
  // back near the noise level before it. Not while the wait for that holds the
  // estimates (e_var keeps its value then), nor from a refit's window (e_var
  // is set to that level, e_short falls to it): from a wait that ends
  // unsettled, where the updates resume and e_var takes the misfit for noise.
  // Over, with e_short and e_var both back: e_short alone, over a fraction of a
  // slow sine's period, dips with it.
  const double noise_level = kSettledRatio * kSettledRatio * noise_at_reset;
  if (noise_at_reset > 0.0 && settling == 0 && !(std::max(e_short, e_var) > noise_level)) noise_at_reset = 0.0;
  status.misfit = noise_at_reset > 0.0 && e_var > noise_level;
  // A change below the divergence: the CUSUM's increment is the log-likelihood
  // ratio of e between N(0, kappa e_var_good) and N(0, e_var_good),
  // -ln(kappa)/2 + (1 - 1/kappa) e^2 / (2 e_var_good) (kappa = change_ratio), on the
  // samples an update may take (not an outlier, not while settling or rearming).
  // Not on a residual at round-off (noise-free data), whose ratio to e_var_good,
  // round-off too, says nothing about the plant.
  bool changed = false;
  if (cfg.change_ratio > 1.0 && settling == 0 && rearm == 0 && update && e_var_good > 0.0 && std::isfinite(s.y) &&
      above_round_off()) {
    change_cusum = std::max(0.0, change_cusum + change_drift + change_gain * e * e / e_var_good);
    changed = change_cusum > cfg.change_threshold;
  } else {
    change_cusum = 0.0;
  }
  if (settling > 0) {
    if (transient > 0) --transient;
    const bool settled = transient == 0 && !(e_short > kSettledRatio * kSettledRatio * e_var_good);
    settling = settled ? 0 : settling - 1;
    if (!settled) update = false;
  } else if (rearm > 0) {
    --rearm;
  } else if (diverging) {
    restore_good(kResetDiverged);
    return flags | kReset;
  } else if (changed) {
    change_cusum = 0.0;
    const ChangeAnswer answer = boost_changed_blocks();
    if (answer == ChangeAnswer::boosted) {
      flags |= kChangeBoost;
    } else if (answer == ChangeAnswer::floor_held && !refit_armed && may_refit()) {
      // The submodels the error names cannot follow faster than their memory
      // floor (a lightly damped mode, decaying over a good part of a memory):
      // the memory after the alarm is fitted as after a divergence, while the
      // recursion goes on. A fit the verdict does not take changes nothing.
      shadow_refit = true;
      arm_refit(kChangeRefit);
      write_refit_start();
    }
  }
  // 3. Excitation: without input power the update only winds P up. With
  //    several inputs, the power of all of them (input_power()).
  const double z2 = kSeveralInputs ? input_power(s) : z * z;
  pow_short = pow_count == 0 ? z2 : pow_alpha * pow_short + (1.0 - pow_alpha) * z2;
  ++pow_count;
  const bool low = pow_ref > 0.0 && pow_short < cfg.low_excitation_ratio * pow_ref;
  // The reference is the input power over a long window, learned while the
  // excitation is normal (seeded by the warm-up when there is one).
  if (!low) pow_ref = pow_ref > 0.0 ? pow_ref_alpha * pow_ref + (1.0 - pow_ref_alpha) * z2 : pow_short;
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
    // the next sample (this sample is done with them). Once the updates take a
    // small part of the error into theta (update_gain), every other update, the
    // blocks in turn: A then moves by a small part of its uncertainty over one
    // update, and the discretisation is the largest part of the per-sample
    // cost. While they take a large part (a start, a change boost) the prefilter
    // follows every update: a lagging one closes a delayed loop from theta back
    // into the regressors, which a lightly damped mode near the Nyquist rate
    // does not survive. Every reset or restore re-discretises at once.
    constexpr double kLaggingGain = 0.01;
    for (std::size_t i = 0; i < blocks.size(); ++i) {
      Block& b = blocks[i];
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
      if (std::abs(b.update_gain) > kLaggingGain || ((status.updates + i) & 1) == 0) follow(b);
    }
    return flags | finish_update();
  }
  for (int l = 0; l < cfg.block_iterations && healthy; ++l) {
    for (std::size_t i = 0; i < blocks.size() && healthy; ++i) {
      Block& b = blocks[i];
      const ThetaVec theta_bar = b.theta;
      const ThetaMat P_bar = b.P;
      // The score test's sums take this sample once, whatever the refinements.
      const ThetaVec score_bar = b.score;
      const ThetaMat score_info_bar = b.score_info;
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
          b.filters.take_input(kU, block_input<kSeveralInputs>(b, s));
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
        b.score = score_bar;
        b.score_info = score_info_bar;
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
  for (auto& b : blocks) {
    if (b.held > 0) --b.held;
    if (b.adapting > 0) --b.adapting;
    if (b.lifted > 0 && --b.lifted == 0) b.drop_lift();
  }
  if (++stabilise_block == blocks.size()) {
    stabilise_block = 0;
    ++stabilise_round;
  }
  if (joint.update(blocks)) joint.solve(blocks, e_var);
  unsigned flags = kUpdated;
  if (++updates_since_good >= 256) {
    if (restore_sign_flipped_modes()) flags |= kModeRestored;  // before a save could keep a flipped mode as good
    // After the warm-up, only a state that fits as well as the last good one
    // replaces it, but while boosted blocks follow a change the change test
    // found. A drift the updates lag (a lightly damped mode's gain ramping,
    // where the memory floor forbids a boost) would otherwise raise the good
    // noise level with the output error, hide from the change and divergence
    // tests measured against it, and wind the estimates along the mode's weak
    // direction. After a boost the error falls as the boosted blocks converge;
    // measured against the level before the change meanwhile, the change test
    // alarms again and boosts a neighbour too (a weak mode beside a gain step).
    // An output error at round-off (noise-free data) says nothing either way.
    const bool adapting = std::any_of(blocks.begin(), blocks.end(), [](const auto& b) { return b.adapting > 0; });
    const double round_off_level = this->round_off_level();
    const bool round_off = !(e_var > round_off_level * round_off_level);
    const bool as_good = status.warming_up || adapting || round_off || !(e_var_good > 0.0) ||
                         !(e_var > kSettledRatio * kSettledRatio * e_var_good);
    if (e_short < 4.0 * e_var && as_good) save_good();
  }
  return flags;
}

// Instantiated here for the other sources, which reach them through Impl::kernel.
template unsigned RecursiveEstimator::Impl::advance_portable<false>(const Sample&, bool);
template unsigned RecursiveEstimator::Impl::advance_portable<true>(const Sample&, bool);
#if MODALWATCH_HAVE_AVX2_FMA
template unsigned RecursiveEstimator::Impl::advance_avx2_fma<false>(const Sample&, bool);
template unsigned RecursiveEstimator::Impl::advance_avx2_fma<true>(const Sample&, bool);
#endif

}  // namespace modalwatch
