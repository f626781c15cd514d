// The estimator's state as a value (EstimatorState): taken, restored, and
// written through or read from a StateWriter / StateReader.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "impl.hpp"
#include "modalwatch/estimator.hpp"

namespace modalwatch {
namespace {

using detail::Block;

// The reasons status().last_reset_reason can hold (besides ""): a state
// carries them as an index into this list.
const std::vector<const char*>& reset_reasons() {
  static const std::vector<const char*> reasons = {kResetNonFiniteModel, kResetUnstableLoop, kResetDiverged,
                                                   kResetDegenerate, kResetRefit, kChangeRefit};
  return reasons;
}

}  // namespace

bool EstimatorState::operator==(const EstimatorState& o) const {
  const auto same = [](const auto& x, const auto& y) {  // vectors of Eigen objects, sizes first
    if (x.size() != y.size()) return false;
    for (std::size_t i = 0; i < x.size(); ++i)
      if (x[i].rows() != y[i].rows() || x[i].cols() != y[i].cols() || x[i] != y[i]) return false;
    return true;
  };
  const EstimatorStatus &a = status_, &b = o.status_;
  const bool same_status =
      a.samples == b.samples && a.updates == b.updates && a.rejected_nonfinite == b.rejected_nonfinite &&
      a.rejected_out_of_order == b.rejected_out_of_order && a.gaps == b.gaps && a.outliers == b.outliers &&
      a.low_excitation_samples == b.low_excitation_samples && a.projections == b.projections &&
      a.covariance_clamps == b.covariance_clamps && a.resets == b.resets &&
      std::string_view(a.last_reset_reason) == b.last_reset_reason && a.warming_up == b.warming_up &&
      a.low_excitation == b.low_excitation && a.warmup_fit_used == b.warmup_fit_used;
  return warmed_up_ == o.warmed_up_ && model_ == o.model_ && time_scale_ == o.time_scale_ && same(P_, o.P_) &&
         same(P_bound_, o.P_bound_) && same(good_theta_, o.good_theta_) && same(good_P_, o.good_P_) &&
         same(reference_theta_, o.reference_theta_) && same(reference_variance_, o.reference_variance_) &&
         same(cross_, o.cross_) && joint_.rows() == o.joint_.rows() && joint_ == o.joint_ &&
         joint_good_.rows() == o.joint_good_.rows() && joint_good_ == o.joint_good_ &&
         joint_updates_ == o.joint_updates_ && joint_good_updates_ == o.joint_good_updates_ &&
         joint_solved_at_ == o.joint_solved_at_ && joint_rng_ == o.joint_rng_ &&
         joint_countdown_ == o.joint_countdown_ && joint_gap_ == o.joint_gap_ &&
         noise_variance_ == o.noise_variance_ && residual_short_ == o.residual_short_ &&
         noise_variance_good_ == o.noise_variance_good_ && residual_count_ == o.residual_count_ && rearm_ == o.rearm_ &&
         input_power_ == o.input_power_ && input_power_reference_ == o.input_power_reference_ &&
         input_power_count_ == o.input_power_count_ && since_update_ == o.since_update_ &&
         updates_since_good_ == o.updates_since_good_ && have_last_sample_ == o.have_last_sample_ &&
         last_t_ == o.last_t_ && last_u_ == o.last_u_ && last_r_ == o.last_r_ && same_status;
}

void EstimatorState::write(StateWriter& out) const {
  out.flag(warmed_up_, "warmed_up");
  out.count(model_.submodels.size(), "submodel count");
  for (const Submodel& s : model_.submodels) {
    out.name(s.name, "submodel name");
    out.integer(s.n, "submodel order n");
    out.integer(s.m, "submodel order m");
    out.integer(s.rigid_poles, "submodel rigid poles");
    out.reals(s.a, "coefficients a");
    out.reals(s.b, "coefficients b");
  }
  if (warmed_up_) {
    for (std::size_t i = 0; i < model_.submodels.size(); ++i) {
      out.real(time_scale_.at(i), "time scale");
      out.matrix(P_.at(i), "P");
      out.reals(P_bound_.at(i), "P bound");
      out.reals(good_theta_.at(i), "last good theta");
      out.matrix(good_P_.at(i), "last good P");
      out.reals(reference_theta_.at(i), "reference theta");
      out.reals(reference_variance_.at(i), "reference variance");
      out.matrix(cross_.at(i), "joint covariance term");
    }
    out.matrix(joint_, "joint information");
    out.matrix(joint_good_, "last good joint information");
    for (std::uint64_t v : {joint_updates_, joint_good_updates_, joint_solved_at_, joint_rng_})
      out.counter(v, "joint information counter");
    out.integer(joint_countdown_, "joint information countdown");
    out.integer(joint_gap_, "joint information gap");
  }
  out.real(noise_variance_, "noise variance");
  out.real(residual_short_, "short residual variance");
  out.real(noise_variance_good_, "last good noise variance");
  out.real(input_power_, "input power");
  out.real(input_power_reference_, "input power reference");
  out.counter(residual_count_, "residual count");
  out.counter(rearm_, "rearm");
  out.counter(input_power_count_, "input power count");
  out.counter(since_update_, "samples since update");
  out.counter(updates_since_good_, "updates since good");
  out.flag(have_last_sample_, "have_last_sample");
  out.real(last_t_, "last sample time");
  out.real(last_u_, "last u");
  out.real(last_r_, "last r");
  const EstimatorStatus& st = status_;
  for (std::uint64_t v : {st.samples, st.updates, st.rejected_nonfinite, st.rejected_out_of_order, st.gaps, st.outliers,
                          st.low_excitation_samples, st.projections, st.covariance_clamps, st.resets})
    out.counter(v, "status counter");
  std::int32_t reason = -1;  // none
  const auto& reasons = reset_reasons();
  for (std::size_t i = 0; i < reasons.size(); ++i)
    if (st.last_reset_reason && std::strcmp(reasons[i], st.last_reset_reason) == 0)
      reason = static_cast<std::int32_t>(i);
  out.integer(reason, "last reset reason");
  out.flag(st.warming_up, "warming_up");
  out.flag(st.low_excitation, "low_excitation");
  out.flag(st.warmup_fit_used, "warmup_fit_used");
}

EstimatorState EstimatorState::read(StateReader& in) {
  EstimatorState e;
  e.warmed_up_ = in.flag("warmed_up");
  const std::size_t K = in.count("submodel count");
  for (std::size_t i = 0; i < K; ++i) {
    Submodel s;
    s.name = in.name("submodel name length");
    s.n = in.integer("submodel order n", 0, kMaxFilterOrder);
    s.m = in.integer("submodel order m", 0, kMaxFilterOrder);
    s.rigid_poles = in.integer("submodel rigid poles", 0, kMaxFilterOrder);
    if (s.n + s.rigid_poles > kMaxFilterOrder || s.m > s.n + s.rigid_poles)
      in.fail("submodel '" + s.name + "': orders n=" + std::to_string(s.n) + ", m=" + std::to_string(s.m) +
              ", l=" + std::to_string(s.rigid_poles) + " are not a valid submodel");
    s.a = in.reals(s.n, "coefficients a");
    s.b = in.reals(s.m + 1, "coefficients b");
    e.model_.submodels.push_back(std::move(s));
  }
  if (e.warmed_up_) {
    for (const Submodel& s : e.model_.submodels) {
      const Eigen::Index nt = s.n_theta();
      e.time_scale_.push_back(in.real("time scale"));
      if (!(e.time_scale_.back() > 0.0)) in.fail("time scale must be > 0");
      e.P_.push_back(in.matrix(nt, "P"));
      e.P_bound_.push_back(in.reals(nt, "P bound"));
      e.good_theta_.push_back(in.reals(nt, "last good theta"));
      e.good_P_.push_back(in.matrix(nt, "last good P"));
      e.reference_theta_.push_back(in.reals(nt, "reference theta"));
      e.reference_variance_.push_back(in.reals(nt, "reference variance"));
      e.cross_.push_back(in.matrix(nt, "joint covariance term"));
    }
    Eigen::Index n = 0;
    for (const Submodel& s : e.model_.submodels) n += s.n_theta();
    e.joint_ = in.matrix(n, "joint information");
    e.joint_good_ = in.matrix(n, "last good joint information");
    for (std::uint64_t* v : {&e.joint_updates_, &e.joint_good_updates_, &e.joint_solved_at_, &e.joint_rng_})
      *v = in.counter("joint information counter");
    e.joint_countdown_ = in.integer("joint information countdown", 1, std::numeric_limits<std::int32_t>::max());
    e.joint_gap_ = in.integer("joint information gap", 1, std::numeric_limits<std::int32_t>::max());
  }
  e.noise_variance_ = in.real("noise variance");
  e.residual_short_ = in.real("short residual variance");
  e.noise_variance_good_ = in.real("last good noise variance");
  e.input_power_ = in.real("input power");
  e.input_power_reference_ = in.real("input power reference");
  e.residual_count_ = in.counter("residual count");
  e.rearm_ = in.counter("rearm");
  e.input_power_count_ = in.counter("input power count");
  e.since_update_ = in.counter("samples since update");
  e.updates_since_good_ = in.counter("updates since good");
  e.have_last_sample_ = in.flag("have_last_sample");
  e.last_t_ = in.real("last sample time");
  e.last_u_ = in.real("last u");
  e.last_r_ = in.real("last r");
  EstimatorStatus& st = e.status_;
  for (std::uint64_t* v :
       {&st.samples, &st.updates, &st.rejected_nonfinite, &st.rejected_out_of_order, &st.gaps, &st.outliers,
        &st.low_excitation_samples, &st.projections, &st.covariance_clamps, &st.resets})
    *v = in.counter("status counter");
  const std::int32_t reason = in.integer("last reset reason", std::numeric_limits<std::int32_t>::min(),
                                         std::numeric_limits<std::int32_t>::max());
  const auto& reasons = reset_reasons();
  if (reason < -1 || reason >= static_cast<std::int32_t>(reasons.size()))
    in.fail("last reset reason " + std::to_string(reason) + " unknown");
  st.last_reset_reason = reason < 0 ? "" : reasons[static_cast<std::size_t>(reason)];
  st.warming_up = in.flag("warming_up");
  st.low_excitation = in.flag("low_excitation");
  st.warmup_fit_used = in.flag("warmup_fit_used");
  return e;
}

EstimatorState RecursiveEstimator::state() const {
  const Impl& m = *impl_;
  EstimatorState st;
  st.warmed_up_ = !m.status.warming_up && !m.blocks.empty();
  st.model_ = model();
  // The inputs are the configuration's, as the sensor is: the state, written
  // and read back, carries the estimate, not which input drives what.
  st.model_.inputs.clear();
  for (Submodel& s : st.model_.submodels) s.input = 0;
  if (st.warmed_up_) {
    for (const Block& b : m.blocks) {
      st.P_.emplace_back(b.P);
      st.time_scale_.push_back(b.ws);
      st.P_bound_.emplace_back(b.p_bound);
      st.good_theta_.emplace_back(b.good_theta.cwiseQuotient(b.scale));
      st.good_P_.emplace_back(b.good_P);
      st.reference_theta_.emplace_back(b.theta_ref.cwiseQuotient(b.scale));
      st.reference_variance_.emplace_back(b.ref_var);
      st.cross_.emplace_back(b.cross);
    }
    const detail::JointInformation::Saved j = m.joint.saved();
    st.joint_ = j.information;
    st.joint_good_ = j.good_information;
    st.joint_updates_ = j.updates;
    st.joint_good_updates_ = j.good_updates;
    st.joint_solved_at_ = j.solved_at;
    st.joint_rng_ = j.rng;
    st.joint_countdown_ = j.countdown;
    st.joint_gap_ = j.gap;
  }
  st.noise_variance_ = m.e_var;
  st.residual_short_ = m.e_short;
  st.noise_variance_good_ = m.e_var_good;
  st.residual_count_ = m.e_count;
  st.rearm_ = m.rearm;
  st.input_power_ = m.pow_short;
  st.input_power_reference_ = m.pow_ref;
  st.input_power_count_ = m.pow_count;
  st.since_update_ = m.since_update;
  st.updates_since_good_ = m.updates_since_good;
  st.have_last_sample_ = m.have_prev;
  st.last_t_ = m.t_prev;
  st.last_u_ = m.last_u;
  st.last_r_ = m.last_r;
  st.status_ = m.status;
  return st;
}

void RecursiveEstimator::restore(const EstimatorState& st) {
  const Impl& m = *impl_;
  const auto fail = [](const std::string& what) { throw std::invalid_argument("estimator state: " + what); };
  const auto finite = [](double v) { return std::isfinite(v); };
  const std::size_t K = m.initial.submodels.size();
  if (st.model_.submodels.size() != K)
    fail(std::to_string(st.model_.submodels.size()) + " submodels, this estimator has " + std::to_string(K));
  for (std::size_t i = 0; i < K; ++i) {
    const Submodel& want = m.initial.submodels[i];
    const Submodel& got = st.model_.submodels[i];
    const std::string where = "submodel " + std::to_string(i + 1) + " ('" + want.name + "'): ";
    if (got.name != want.name || got.n != want.n || got.m != want.m || got.rigid_poles != want.rigid_poles)
      fail(where + "name or orders (n, m, rigid poles) differ");
    if (got.a.size() != got.n || got.b.size() != got.m + 1) fail(where + "coefficient count differs from n, m");
    if (!got.a.allFinite() || !got.b.allFinite()) fail(where + "non-finite coefficient");
    if (got.n > 0 && got.a(got.n - 1) == 0.0) fail(where + "a_n = 0 (order drop)");
  }
  if (st.warmed_up_) {
    if (st.P_.size() != K || st.time_scale_.size() != K || st.P_bound_.size() != K || st.good_theta_.size() != K ||
        st.good_P_.size() != K || st.reference_theta_.size() != K || st.reference_variance_.size() != K ||
        st.cross_.size() != K)
      fail(
          "per-submodel arrays (P, time_scale, P_bound, good_theta, good_P, reference theta and variance, joint "
          "covariance term) do not have one entry per submodel");
    for (std::size_t i = 0; i < K; ++i) {
      const Eigen::Index nt = m.initial.submodels[i].n_theta();
      const std::string where = "submodel " + std::to_string(i + 1) + ": ";
      if (st.P_[i].rows() != nt || st.P_[i].cols() != nt || st.good_P_[i].rows() != nt || st.good_P_[i].cols() != nt ||
          st.P_bound_[i].size() != nt || st.good_theta_[i].size() != nt || st.reference_theta_[i].size() != nt ||
          st.reference_variance_[i].size() != nt)
        fail(where + "P, P_bound, good_theta, good_P or the reference do not match n_theta = " + std::to_string(nt));
      if (!st.P_[i].allFinite() || !st.good_P_[i].allFinite() || !st.P_bound_[i].allFinite() ||
          !st.good_theta_[i].allFinite() || !st.reference_theta_[i].allFinite() ||
          !st.reference_variance_[i].allFinite())
        fail(where + "non-finite P, P_bound, good_theta, good_P or reference");
      if ((st.reference_variance_[i].array() < 0.0).any()) fail(where + "reference variance must be >= 0");
      if (!(st.time_scale_[i] > 0.0) || !finite(st.time_scale_[i])) fail(where + "time_scale must be finite and > 0");
      if ((st.P_bound_[i].array() <= 0.0).any()) fail(where + "P_bound must be > 0");
    }
  }
  for (double v :
       {st.noise_variance_, st.residual_short_, st.noise_variance_good_, st.input_power_, st.input_power_reference_})
    if (!finite(v) || v < 0.0) fail("noise, residual or input-power statistic is negative or non-finite");
  if (!finite(st.last_t_) || !finite(st.last_u_) || !finite(st.last_r_)) fail("non-finite last sample");
  const char* reason = "";
  if (st.status_.last_reset_reason && *st.status_.last_reset_reason) {
    reason = nullptr;
    for (const char* r : reset_reasons())
      if (std::string_view(r) == st.status_.last_reset_reason) reason = r;
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
  if (st.warmed_up_) {
    // What the sensor measures and which input drives each submodel are the
    // configuration's, as the forgetting factors are (the checkpoint's
    // fingerprint holds them): the state keeps none.
    AdditiveModel restored = st.model_;
    restored.inputs = m.initial.inputs;
    for (std::size_t i = 0; i < K; ++i) {
      restored.submodels[i].output_derivatives = m.initial.submodels[i].output_derivatives;
      restored.submodels[i].input = m.initial.submodels[i].input;
    }
    next.build(restored, nullptr, 0.0, 1.0);  // structure, prefilters at rest; theta, P below
    for (std::size_t i = 0; i < K; ++i) {
      Block& b = next.blocks[i];
      b.ws = st.time_scale_[i];
      b.set_scale();
      b.theta = st.model_.submodels[i].theta().cwiseProduct(Eigen::VectorXd(b.scale));
      if (!b.scale.allFinite() || !b.theta.allFinite() || (b.scale.array() == 0.0).any())
        fail("submodel " + std::to_string(i + 1) + ": time_scale out of range for its coefficients");
      b.P = st.P_[i];
      b.p_bound = st.P_bound_[i];
      b.drop_lift();
      b.good_theta = st.good_theta_[i].cwiseProduct(Eigen::VectorXd(b.scale));
      b.good_P = st.good_P_[i];
      // Stabilised forgetting goes on toward the saved reference (theta(t0) of
      // the run that wrote the state, P_ref once it was set), not the restored theta.
      b.theta_ref = st.reference_theta_[i].cwiseProduct(Eigen::VectorXd(b.scale));
      if (b.stabilisation != Block::Stabilisation::off && (st.reference_variance_[i].array() > 0.0).all()) {
        b.ref_var = st.reference_variance_[i];
        b.stabilisation = Block::Stabilisation::on;
      }
      b.filter_takes_damping();
      b.filters.init(b.filter_a_poly(), b.filter_denominator(), b.ws * next.cfg.sample_time, next.cfg.output_hold,
                     b.biproper);
      if (st.cross_[i].rows() != b.nt || st.cross_[i].cols() != b.nt || !st.cross_[i].allFinite())
        fail("submodel " + std::to_string(i + 1) + ": joint covariance term does not match n_theta or is not finite");
      b.cross = st.cross_[i];
    }
    detail::JointInformation::Saved joint;
    joint.information = st.joint_;
    joint.good_information = st.joint_good_;
    joint.updates = st.joint_updates_;
    joint.good_updates = st.joint_good_updates_;
    joint.solved_at = st.joint_solved_at_;
    joint.rng = st.joint_rng_;
    joint.countdown = st.joint_countdown_;
    joint.gap = st.joint_gap_;
    if (!next.joint.load(joint))
      fail("joint information: not of the submodels' size, not finite, or its counters out of range");
    next.buffered = 0;
  } else {
    next.blocks.clear();
    next.buffered = 0;
  }
  next.reset_filters();
  next.e_var = st.noise_variance_;
  next.e_short = st.residual_short_;
  next.e_var_good = st.noise_variance_good_;
  next.e_count = st.residual_count_;
  next.rearm = st.rearm_;
  next.outlier_run = 0;
  next.pow_short = st.input_power_;
  next.pow_ref = st.input_power_reference_;
  next.pow_count = st.input_power_count_;
  next.since_update = st.since_update_;
  next.updates_since_good = st.updates_since_good_;
  next.have_prev = st.have_last_sample_;
  next.just_restored = true;
  next.t_prev = st.last_t_;
  next.last_u = st.last_u_;
  next.last_r = st.last_r_;
  next.status = st.status_;
  next.stabilise_block = static_cast<std::size_t>(next.status.updates % K);
  next.stabilise_round = next.status.updates / K;
  next.status.last_reset_reason = reason;
  next.status.warming_up = !st.warmed_up_ && next.cfg.warmup_samples > 0;
  if (!st.warmed_up_ && next.cfg.warmup_samples == 0) {
    // No warm-up configured: the estimator starts from the configured model, as new.
    next.build(next.initial, nullptr, 0.0, 1.0);
  }
  *impl_ = std::move(next);
}

}  // namespace modalwatch
