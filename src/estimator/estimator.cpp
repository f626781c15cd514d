// The recursive additive RSRIVC estimator: construction, the sample checks of
// step() before the per-sample path (step.cpp), and the estimate's views.
#include "modalwatch/estimator.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <stdexcept>
#include <string>

#include "impl.hpp"
#include "modalwatch/record.hpp"

namespace modalwatch {
namespace {

// Per-submodel time normalisation, as in the offline fit: t' = ws t with
// ws = a_n^(-1/n), which brings the coefficients of A near 1 (a mode's wn to 1).
double time_scale(const Submodel& s) {
  if (s.n > 0 && s.a(s.n - 1) != 0.0) return std::pow(std::abs(s.a(s.n - 1)), -1.0 / s.n);
  return 1.0;
}

}  // namespace

using namespace detail;

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
         output_hold == o.output_hold && block_iterations == o.block_iterations && refinements == o.refinements &&
         update_divisor == o.update_divisor && forgetting == o.forgetting && warmup_samples == o.warmup_samples &&
         fit_on_warmup == o.fit_on_warmup && warmup_iterations == o.warmup_iterations &&
         defer_warmup_fit == o.defer_warmup_fit && same_covariances() &&
         initial_covariance_relative == o.initial_covariance_relative && random_walk == o.random_walk &&
         random_walks == o.random_walks && covariance_bound == o.covariance_bound && stabilisation == o.stabilisation &&
         stabilisations == o.stabilisations && min_memory == o.min_memory && min_memories == o.min_memories &&
         settled_memory == o.settled_memory && damping_deadband == o.damping_deadband &&
         divergence_ratio == o.divergence_ratio && change_ratio == o.change_ratio &&
         change_threshold == o.change_threshold && change_hold == o.change_hold && gap_factor == o.gap_factor &&
         outlier_sigma == o.outlier_sigma && residual_window == o.residual_window &&
         low_excitation_ratio == o.low_excitation_ratio && low_excitation_window == o.low_excitation_window;
}

void RecursiveEstimator::Impl::build(const AdditiveModel& model, const std::vector<Eigen::MatrixXd>* fit_cov,
                                     double fit_sigma2, double y_var,
                                     const std::vector<Eigen::VectorXd>* fit_bound_variance) {
  blocks.clear();
  const double T = cfg.sample_time;
  for (std::size_t i = 0; i < model.submodels.size(); ++i) {
    const Submodel& s = model.submodels[i];
    Block b;
    b.n = s.n;
    b.m = s.m;
    b.l = s.rigid_poles;
    b.z = s.output_derivatives;
    b.input = s.input;
    b.nt = s.n_theta();
    b.biproper = b.m + b.z == b.n + b.l;
    b.b0_position = b.m == 0 && b.z == 0;
    b.position_mode = b.n == 2 && b.b0_position;
    b.ws = time_scale(s);
    b.lambda = cfg.forgetting.empty() ? 1.0 : cfg.forgetting[i];
    b.random_walk = cfg.random_walks.empty() ? cfg.random_walk : cfg.random_walks[i];
    const double min_memory = cfg.min_memories.empty() ? cfg.min_memory : cfg.min_memories[i];
    b.forget_per_decay = min_memory > 0.0 ? cfg.update_divisor * T / min_memory : 0.0;
    b.settled_forget_per_decay =
        min_memory > 0.0 ? cfg.update_divisor * T / std::max(min_memory, cfg.settled_memory) : 0.0;
    b.set_scale();
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
    // The bound's reference: diag(P(t0)), or where P(t0) is the warm-up fit's,
    // what one memory of its window gives (the recursion's steady state).
    b.p_bound = b.P.diagonal();
    const bool from_fit = i >= cfg.initial_covariance.size() || cfg.initial_covariance[i].size() != b.nt;
    if (from_fit && fit_cov && fit_sigma2 > 0.0 && fit_bound_variance) {
      const Eigen::VectorXd& v = (*fit_bound_variance)[i];
      for (int j = 0; j < b.nt; ++j) b.p_bound(j) = std::max(b.p_bound(j), v(j) * b.scale(j) * b.scale(j) / fit_sigma2);
    }
    b.p_bound = cfg.covariance_bound * b.p_bound.cwiseMax(1e-300);
    b.drop_lift();
    set_reference(b, cfg.stabilisations.empty() ? cfg.stabilisation : cfg.stabilisations[i]);
    b.filter_takes_damping();
    b.filters.init(b.filter_a_poly(), b.filter_denominator(), b.ws * T, cfg.output_hold, b.biproper);
    b.phi.resize(b.nt);
    b.psi.resize(b.nt);
    b.score = ThetaVec::Zero(b.nt);
    b.score_info = ThetaMat::Zero(b.nt, b.nt);
    b.cross = ThetaMat::Zero(b.nt, b.nt);
    b.sampling = ThetaMat::Zero(b.nt, b.nt);
    blocks.push_back(std::move(b));
  }
  snapshot.resize(blocks.size());
  controller = cfg.controller;
  controller.reset();
  plant_loop = cfg.controller;
  plant_loop.reset();
  const std::size_t order = cfg.controller.empty() ? 0 : cfg.controller.denominator().size() - 1;
  loop_u.assign(order, 0.0);
  loop_e.assign(order, 0.0);
  loop_state.assign(order, 0.0);
  joint.resize(blocks);
  save_good();
}

// Stabilised forgetting's reference: theta_ref is theta when the block is
// built (theta(t0), or the restored estimate, whose reference restore() sets);
// P_ref once sigma^2 is known (set_reference_variance).
void RecursiveEstimator::Impl::set_reference(Block& b, double stabilisation) const {
  const bool on = stabilisation > 0.0 && b.lambda < 1.0;
  b.stabilisation = on ? Block::Stabilisation::pending : Block::Stabilisation::off;
  b.stabilisation_ratio = stabilisation;
  b.theta_ref = b.theta;
  b.ref_var = ThetaVec::Zero(b.nt);
}

// P_ref = diag((stabilisation theta_ref)^2) / sigma^2 (P carries theta^2 per
// output^2), never below diag(P(t0)) (p_bound / covariance_bound): a parameter
// that is zero in theta_ref is not pinned there. Given back to one block per
// update and one coordinate per round in turn: K nt times the information
// (1 - lambda) / P_ref_j once every K nt updates.
void RecursiveEstimator::Impl::set_reference_variance(Block& b) const {
  const double rho2 = b.stabilisation_ratio * b.stabilisation_ratio;
  for (int j = 0; j < b.nt; ++j) {
    const double p_ref = std::max(rho2 * b.theta_ref(j) * b.theta_ref(j) / e_var, b.p_bound(j) / cfg.covariance_bound);
    b.ref_var(j) = p_ref / (static_cast<double>(blocks.size()) * b.nt * (1.0 - b.lambda));
  }
  b.stabilisation = Block::Stabilisation::on;
}

RecursiveEstimator::RecursiveEstimator(const AdditiveModel& initial, const EstimatorSettings& settings)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.cfg = settings;
  m.initial = initial;
  if (!(settings.sample_time > 0.0)) throw std::invalid_argument("estimator: sample_time must be > 0");
  if (initial.submodels.empty()) throw std::invalid_argument("estimator: no submodels");
  const int inputs = initial.n_inputs();
  if (inputs > kMaxInputs)
    throw std::invalid_argument("estimator: model.inputs names " + std::to_string(inputs) + " inputs, at most " +
                                std::to_string(kMaxInputs) + " are supported (a sample carries that many)");
  // The instrument's loop (eq. 29) has one plant input, the controller's u.
  if (inputs > 1 && settings.closed_loop)
    throw std::invalid_argument("estimator: a closed loop has one input (the controller's u); model.inputs names " +
                                std::to_string(inputs) + " (several inputs need loop: open)");
  m.further_inputs = inputs - 1;
  m.select_kernel(StepKernel::avx2_fma);  // where the CPU has it; else portable
  for (const auto& s : initial.submodels) {
    if (s.input < 0 || s.input >= inputs)
      throw std::invalid_argument("estimator: submodel '" + s.name + "' is driven by input " +
                                  std::to_string(s.input + 1) + " of " + std::to_string(inputs));
    s.check();
    if (s.n + s.rigid_poles > kMaxFilterOrder || s.n_theta() > kMaxTheta)
      throw std::invalid_argument("estimator: submodel '" + s.name + "' exceeds the maximum order");
  }
  if (!settings.forgetting.empty() && settings.forgetting.size() != initial.submodels.size())
    throw std::invalid_argument("estimator: one forgetting factor per submodel");
  for (double l : settings.forgetting)
    if (!(l > 0.0 && l <= 1.0)) throw std::invalid_argument("estimator: forgetting factor outside (0, 1]");
  // Settings >= 0 given for all submodels (value) or per submodel (values: one each, or none).
  const auto check_non_negative = [&](double value, const std::vector<double>& values, const std::string& what) {
    if (!values.empty() && values.size() != initial.submodels.size())
      throw std::invalid_argument("estimator: one " + what + " per submodel (or none)");
    for (double q : values)
      if (!(q >= 0.0 && std::isfinite(q))) throw std::invalid_argument("estimator: " + what + " negative or not finite");
    if (!(value >= 0.0 && std::isfinite(value)))
      throw std::invalid_argument("estimator: " + what + " negative or not finite");
  };
  check_non_negative(settings.random_walk, settings.random_walks, "random walk");
  check_non_negative(settings.stabilisation, settings.stabilisations, "stabilisation");
  check_non_negative(settings.min_memory, settings.min_memories, "min_memory");
  check_non_negative(settings.settled_memory, {}, "settled_memory");
  check_non_negative(settings.damping_deadband, {}, "damping_deadband");
  if (settings.block_iterations < 1 || settings.refinements < 0 || settings.update_divisor < 1)
    throw std::invalid_argument("estimator: M_l >= 1, M_s >= 0 and the update divisor >= 1");
  if (settings.closed_loop && settings.controller.empty())
    throw std::invalid_argument("estimator: closed loop needs the controller");
  if (!(settings.change_ratio == 0.0 || settings.change_ratio > 1.0) || !(settings.change_threshold > 0.0) ||
      !(settings.change_hold >= 0.0))
    throw std::invalid_argument("estimator: change_ratio 0 (off) or > 1, change_threshold > 0, change_hold >= 0");
  m.cfg.forgetting.resize(initial.submodels.size(), 1.0);
  if (settings.forgetting.empty()) std::fill(m.cfg.forgetting.begin(), m.cfg.forgetting.end(), 1.0);

  const double lambda_min = *std::min_element(m.cfg.forgetting.begin(), m.cfg.forgetting.end());
  const double T = settings.sample_time;
  const double e_window = settings.residual_window > 0.0 ? settings.residual_window / T
                                                         : (lambda_min < 1.0 ? 1.0 / (1.0 - lambda_min) : 1000.0);
  m.e_alpha = 1.0 - 1.0 / std::max(e_window, 2.0);
  m.e_short_alpha = 1.0 - 1.0 / std::max(0.05 * e_window, 2.0);
  if (settings.change_ratio > 1.0) {
    m.change_drift = -0.5 * std::log(settings.change_ratio);
    m.change_gain = 0.5 * (1.0 - 1.0 / settings.change_ratio);
  }
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
    m.refit_context = std::make_shared<WarmupFit::Context>(WarmupFit::Context{initial, m.cfg});
    m.keeps_history = m.cfg.fit_on_warmup;
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
  unsigned flags = 0;
  // A non-finite value is missing, like a gap, never information: no update
  // on it. Without y the model stands in for it (advance()) and the filters
  // stay on the sample grid with the true u and r; without u, any further
  // input of the model (a sample that carries fewer inputs than the model
  // has lacks them) or r in closed loop the filters cannot follow the data,
  // so the sample is skipped and the filters restart on the next one, as
  // after a gap.
  const bool inputs_missing = !std::isfinite(s.u) || (m.cfg.closed_loop && !std::isfinite(s.r)) ||
                              (m.further_inputs > 0 && m.further_inputs_missing(s));
  const bool bad_values = inputs_missing || !std::isfinite(s.y);
  const Sample* taken = &s;  // copied only to be patched: a sample is about a hundred bytes
  if (bad_values) {
    ++m.status.rejected_nonfinite;
    flags |= kRejectedNonFinite;
    m.patched = s;
    m.patched.y = std::numeric_limits<double>::quiet_NaN();   // replaced by y_hat in advance()
    if (!std::isfinite(m.patched.r)) m.patched.r = m.last_r;  // open loop: r is not used
    taken = &m.patched;
  }
  const Sample& sample = *taken;
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
      if (m.status.warming_up) {
        m.buffered = 0;
        m.loop_known = 0;
      } else if (restarted || bad_values || !m.bridge(sample, dt)) {
        m.restart_filters();
      }
    }
  }
  m.t_prev = s.t;
  m.have_prev = true;
  m.just_restored = false;
  if (bad_values && (m.status.warming_up || m.blocks.empty())) return flags;
  if (inputs_missing) {
    m.inputs_lost = true;
    return flags;
  }
  if (m.inputs_lost) {
    m.inputs_lost = false;
    if (!(flags & kGap)) m.restart_filters();
  }
  m.last_u = sample.u;
  m.last_r = sample.r;
  if (m.cfg.closed_loop) {
    if (bad_values)
      m.loop_known = 0;  // the controller saw a y we do not know
    else
      m.record_loop(sample.u, sample.r - sample.y);
  }
  ++m.status.samples;
  if (m.status.warming_up) {
    m.buffer_window_sample(s);
    if (m.buffered == m.cfg.warmup_samples) return flags | fit_window();
    return flags | kWarmingUp;
  }
  const bool armed = m.refit_armed;
  if (m.keeps_history) {
    if (flags & kGap || bad_values)
      m.forget_history();
    else if (!armed)
      m.keep_history(s);
  }
  // A window beside the recursion takes the sample before the update, so
  // that a divergence on it hands the window over whole (restore_good).
  const bool beside = armed && m.shadow_refit;
  const bool window_full = beside && m.keep_for_refit(s, bad_values);
  flags |= m.advance(sample, !bad_values);
  if (!armed || !m.refit_armed || (flags & kReset)) return flags;
  if (!(beside ? window_full && m.shadow_refit : m.keep_for_refit(s, bad_values))) return flags;
  m.begin_refit();
  return flags | fit_window();
}

// The window is complete: its fit, on another thread when deferred.
unsigned RecursiveEstimator::fit_window() noexcept {
  Impl& m = *impl_;
  m.fit_pending = true;
  if (m.cfg.defer_warmup_fit) return kWarmingUp | kWarmupFitPending;
  try {
    WarmupFit job = take_warmup_fit();
    job.run();
    apply_warmup_fit(std::move(job));
  } catch (...) {
    // Allocation failure: apply_warmup_fit() restarted the warm-up (or take failed before).
    m.fit_pending = m.fit_taken = false;
    m.buffered = 0;
  }
  return kWarmingUp;
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
  const ThetaMat P = m.reported_P(b);
  est.value.gain = b.theta(b.n) / b.scale(b.n);
  const double s2 = m.e_var;
  est.std.gain = std::sqrt(std::max(0.0, s2 * P(b.n, b.n))) / b.scale(b.n);
  if (b.n == 2) {
    const double a1 = b.theta(0) / b.scale(0), a2 = b.theta(1) / b.scale(1);
    if (a2 > 0.0) {
      est.value.wn = 1.0 / std::sqrt(a2);
      est.value.zeta = 0.5 * a1 * est.value.wn;
      // First-order propagation of sigma^2 P through wn = a2^-1/2, zeta = a1/(2 sqrt a2).
      const double c11 = s2 * P(0, 0) / (b.scale(0) * b.scale(0));
      const double c22 = s2 * P(1, 1) / (b.scale(1) * b.scale(1));
      const double c12 = s2 * P(0, 1) / (b.scale(0) * b.scale(1));
      const double a2_32 = a2 * std::sqrt(a2);  // a2^1.5 (no pow: mode() runs per sample in `track`)
      const double dw2 = -0.5 / a2_32;
      const double dz1 = 0.5 / std::sqrt(a2), dz2 = -0.25 * a1 / a2_32;
      est.std.wn = std::sqrt(std::max(0.0, dw2 * dw2 * c22));
      est.std.zeta = std::sqrt(std::max(0.0, dz1 * dz1 * c11 + 2 * dz1 * dz2 * c12 + dz2 * dz2 * c22));
    }
  }
  return est;
}

namespace {

// (a1, a2, b0) inside theta where the block is a mode; b0 alone otherwise.
int modal_index(const Block& b, int r) { return b.n == 2 ? std::array<int, 3>{0, 1, b.n}[r] : b.n; }

Eigen::Matrix3d jacobian_of(const Block& b) {
  return b.n == 2 ? modal_jacobian(b.theta(0) / b.scale(0), b.theta(1) / b.scale(1)) : modal_jacobian(0.0, 0.0);
}

// J_i (e_var C) J_j^T: the covariance of block i's (wn, zeta, gain) with block
// j's, C(r, k) the normalised covariance of theta_i(r) with theta_j(k).
template <class Entry>
Eigen::Matrix3d modal_block(const Block& bi, const Block& bj, double e_var, Entry C) {
  Eigen::Matrix3d c;
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k) {
      const int a = modal_index(bi, r), b = modal_index(bj, k);
      c(r, k) = e_var * C(a, b) / (bi.scale(a) * bj.scale(b));
    }
  return jacobian_of(bi) * c * jacobian_of(bj).transpose();
}

// modal_covariance() of e_var P (normalised) for block b.
Eigen::Matrix3d modal_covariance_of(const Block& b, const ThetaMat& P, double e_var) {
  const Eigen::Matrix3d out = modal_block(b, b, e_var, [&](int r, int k) { return P(r, k); });
  return 0.5 * (out + out.transpose());  // exactly symmetric, as a covariance
}

}  // namespace

Eigen::Matrix3d RecursiveEstimator::mode_covariance(int i) const noexcept {
  const Impl& m = *impl_;
  if (m.blocks.empty()) return Eigen::Matrix3d::Zero();
  const Block& b = m.blocks[static_cast<std::size_t>(i)];
  return modal_covariance_of(b, m.reported_P(b), m.e_var);
}

Eigen::Matrix3d RecursiveEstimator::mode_covariance_given_others(int i) const noexcept {
  const Impl& m = *impl_;
  if (m.blocks.empty()) return Eigen::Matrix3d::Zero();
  const Block& b = m.blocks[static_cast<std::size_t>(i)];
  return modal_covariance_of(b, b.P, m.e_var);
}

Eigen::Matrix3d RecursiveEstimator::mode_cross_covariance(int i, int j) const noexcept {
  const Impl& m = *impl_;
  if (m.blocks.empty() || i == j || !m.joint.solved()) return Eigen::Matrix3d::Zero();
  const Block& bi = m.blocks[static_cast<std::size_t>(i)];
  const Block& bj = m.blocks[static_cast<std::size_t>(j)];
  const int oi = m.joint.offset(static_cast<std::size_t>(i)), oj = m.joint.offset(static_cast<std::size_t>(j));
  return modal_block(bi, bj, m.e_var, [&](int r, int k) { return m.joint.inverse()(oi + r, oj + k); });
}

Eigen::Matrix3d RecursiveEstimator::mode_sampling_covariance(int i) const noexcept {
  const Impl& m = *impl_;
  if (m.blocks.empty() || !m.joint.current()) return mode_covariance(i);
  const Block& b = m.blocks[static_cast<std::size_t>(i)];
  return modal_covariance_of(b, b.sampling, m.e_var);
}

Eigen::MatrixXd RecursiveEstimator::covariance(int i) const {
  const Impl& m = *impl_;
  const Block& b = m.blocks.at(i);
  Eigen::MatrixXd c = m.e_var * Eigen::MatrixXd(m.reported_P(b));
  for (int j = 0; j < b.nt; ++j)
    for (int k = 0; k < b.nt; ++k) c(j, k) /= b.scale(j) * b.scale(k);
  return c;
}

double RecursiveEstimator::residual_rms() const noexcept { return std::sqrt(impl_->e_var); }
double RecursiveEstimator::noise_variance() const noexcept { return impl_->e_var; }
const EstimatorStatus& RecursiveEstimator::status() const noexcept { return impl_->status; }

}  // namespace modalwatch
