// The augmented model on a record (include/modalwatch/diagnose.hpp): the
// submodels exactly discretised under ZOH in normalised time, the effects
// (include/modalwatch/effects.hpp) around them, open or closed loop.
#include "modalwatch/diagnose.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace modalwatch {

const char* effect_name(EffectKind kind) {
  switch (kind) {
    case EffectKind::mode:
      return "mode";
    case EffectKind::rigid_body:
      return "rigid_body";
    case EffectKind::offset:
      return "offset";
    case EffectKind::drift:
      return "drift";
    case EffectKind::delay:
      return "delay";
    case EffectKind::coulomb:
      return "coulomb";
    case EffectKind::cubic:
      return "cubic";
    case EffectKind::complex_modes:
      return "complex_modes";
    case EffectKind::feedthrough:
      return "feedthrough";
  }
  return "?";
}

std::vector<EffectKind> all_effects() {
  return {EffectKind::mode,    EffectKind::rigid_body, EffectKind::offset,        EffectKind::drift,      EffectKind::delay,
          EffectKind::coulomb, EffectKind::cubic,      EffectKind::complex_modes, EffectKind::feedthrough};
}

int ModelEffects::n_params() const {
  return int(output_offset_on) + int(input_offset_on) + int(drift_on) + int(coulomb_on) + int(cubic_on) +
         (input_delay > 0 ? 1 : 0);
}

namespace {

// The effects the model carries.
PlantEffects carried(const ModelEffects& e) {
  PlantEffects p;
  if (e.output_offset_on) p.output_offset = e.output_offset;
  if (e.input_offset_on) p.input_offset = e.input_offset;
  if (e.drift_on) p.drift = e.drift;
  p.input_delay = std::max(e.input_delay, 0);
  if (e.coulomb_on) p.coulomb = e.coulomb;
  if (e.cubic_on) p.cubic = e.cubic;
  return p;
}

// The time scale of a submodel: |a_n|^(-1/n) (wn for a mode), 1 without A.
double time_scale(const Submodel& s) {
  if (s.n > 0 && s.a(s.n - 1) != 0.0) return std::pow(std::abs(s.a(s.n - 1)), -1.0 / s.n);
  return 1.0;
}

// p^z B(p)/(p^l A(p)) under ZOH. With p = ws p' the filter runs in t' = ws t and
// coefficient j is multiplied by ws^(j-l), which leaves the output unchanged.
// The position B/(p^l A), which the effects act on, comes from the same states.
class SubmodelRunner {
 public:
  SubmodelRunner(const Submodel& s, double T) {
    const int l = s.rigid_poles;
    order_ = s.n + l;
    // Order 0 is a feedthrough: the filter passes w through and b_0 scales it.
    if (order_ < 0 || order_ > kMaxFilterOrder) throw std::invalid_argument("diagnose: submodel order out of range");
    s.check();
    const double ws = time_scale(s);
    const Eigen::VectorXd den = s.denominator(), num = s.output_numerator();
    Eigen::VectorXd d = Eigen::VectorXd::Zero(order_ + 1);
    b_ = Eigen::VectorXd::Zero(order_ + 1);
    for (Eigen::Index j = 0; j < den.size(); ++j) d(j) = den(j) * std::pow(ws, double(j - l));
    for (Eigen::Index j = 0; j < num.size(); ++j) b_(j) = num(j) * std::pow(ws, double(j - l));
    if (s.output_derivatives > 0) {
      x_ = Eigen::VectorXd::Zero(order_ + 1);
      for (Eigen::Index j = 0; j < s.b.size(); ++j) x_(j) = s.b(j) * std::pow(ws, double(j - l));
    }
    filter_ = Prefilter(d, ws * T, Hold::zoh);
    feed_ = b_(order_) / d(order_);
  }
  // Output at t_k for a zero input sample, after moving the state to t_k.
  double advance() {
    filter_.advance();
    filter_.complete(0.0);
    return filter_.combine(b_);
  }
  // The position at t_k for a zero input sample (after advance()); the output itself for z = 0.
  double position(double output) const { return x_.size() == 0 ? output : filter_.combine(x_); }
  // Output for the input sample w at t_k (after advance()).
  double complete(double w) {
    filter_.complete(w);
    return filter_.combine(b_);
  }
  double feedthrough() const { return feed_; }

 private:
  int order_ = 0;
  Prefilter filter_;
  Eigen::VectorXd b_;
  Eigen::VectorXd x_;  // the position's numerator when z > 0
  double feed_ = 0.0;
};

}  // namespace

Eigen::VectorXd simulate_augmented(const AugmentedModel& model, const Record& data, const LoopSpec& loop,
                                   Eigen::VectorXd* u_sim) {
  const Eigen::Index N = data.size();
  const double T = data.sample_time();
  if (N < 2 || !(T > 0.0)) throw std::invalid_argument("diagnose: record too short");
  if (loop.closed && !data.has_reference()) throw std::invalid_argument("diagnose: closed loop needs r");
  std::vector<SubmodelRunner> runners;
  const int substeps = std::max(1, loop.substeps);
  // Several inputs: a submodel on a further input takes that input as
  // measured (the effects act on the first input, the one a closed loop has).
  std::vector<const Eigen::VectorXd*> further;  // per runner: its input, or null for the first
  bool several = false;
  for (const Submodel& s : model.linear.submodels) {
    runners.emplace_back(s, T / substeps);
    if (s.input < 0 || s.input >= data.inputs())
      throw std::invalid_argument("diagnose: submodel " + s.name + " is driven by an input the record lacks");
    further.push_back(s.input == 0 ? nullptr : &data.input(s.input));
    several = several || s.input != 0;
  }
  if (several && loop.closed)
    throw std::invalid_argument("diagnose: a closed loop has the controller's one input; several inputs are open loop");
  const PlantEffects e = carried(model.effects);
  EffectState effects(e);

  // Closed loop: the excitation besides the controller, from the measured signals.
  Eigen::VectorXd u_ext;
  DiscreteTransferFunction controller = loop.controller;
  if (loop.closed) {
    controller.reset();
    u_ext.resize(N);
    for (Eigen::Index k = 0; k < N; ++k) u_ext(k) = data.u(k) - controller.step(data.r(k) - data.y(k));
    controller.reset();
  }
  const double c0 = loop.closed ? controller.feedthrough() : 0.0;

  Eigen::VectorXd y(N);
  if (u_sim) u_sim->resize(N);
  const double t0 = data.t(0);
  const bool interpolate = loop.interpolate_input && !loop.closed;
  for (Eigen::Index k = 0; k < N; ++k) {
    // Move every submodel to t_k: for strictly proper submodels their output
    // y_k is then known before the input sample u_k, which the nonlinear
    // branches use (sampled and held like the input).
    double y_free = 0.0, x_free = 0.0, feed = 0.0;
    for (SubmodelRunner& r : runners) {
      const double y_r = r.advance();
      y_free += y_r;
      x_free += r.position(y_r);
      feed += r.feedthrough();
    }
    const double branches = effects.branches(x_free);
    const double out_terms = effects.output_terms(data.t(k) - t0);
    double u = data.u(k);
    if (loop.closed) {
      // y_k = y_free + D u_p + out_terms, u_p = (u_k or u_{k-d}) + branches.
      const double y_known = y_free + feed * effects.known_input(branches) + out_terms;
      const double gain = 1.0 + c0 * (effects.delays() ? 0.0 : feed);
      u = (controller.peek(data.r(k) - y_known) + u_ext(k)) / gain;
    }
    // The input over [t_k, t_k+1): held, or (open loop, band-limited input)
    // linear towards the next sample, at the middle of each substep.
    const double u_a = effects.delayed(u);
    double u_b = u_a;
    if (interpolate) {
      const Eigen::Index j = k + 1 - e.input_delay;
      u_b = j < 0 ? 0.0 : (j < N ? data.u(j) : u_a);
    }
    auto held = [&](int sub) { return interpolate ? u_a + (u_b - u_a) * (sub + 0.5) / substeps : u_a; };
    // A further input over the substep `sub`, held or interpolated like u.
    auto further_held = [&](const Eigen::VectorXd& w, int sub) {
      const double a = w(k), b = k + 1 < N ? w(k + 1) : a;
      return interpolate ? a + (b - a) * (sub + 0.5) / substeps : a;
    };
    double y_plant = 0.0;
    for (std::size_t i = 0; i < runners.size(); ++i)
      y_plant += runners[i].complete(further[i] ? further_held(*further[i], 0) : held(0) + branches);
    y(k) = y_plant + out_terms;
    if (loop.closed) controller.step(data.r(k) - y(k));
    if (u_sim) (*u_sim)(k) = u;
    effects.end_sample(u, x_free);
    for (int sub = 1; sub < substeps; ++sub) {
      double x_sub = 0.0;
      for (SubmodelRunner& r : runners) x_sub += r.position(r.advance());
      const double b = effects.branches(x_sub);
      for (std::size_t i = 0; i < runners.size(); ++i)
        runners[i].complete(further[i] ? further_held(*further[i], sub) : held(sub) + b);
      effects.end_substep(x_sub);
    }
  }
  return y;
}

}  // namespace modalwatch
