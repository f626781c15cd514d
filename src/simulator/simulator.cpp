#include "modalwatch/simulator.hpp"

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>

#include "modalwatch/prefilter.hpp"

namespace modalwatch {

double Trajectory::at(double t, double base) const {
  if (points.empty()) return base;
  if (t <= points.front().first) return points.front().second;
  if (t >= points.back().first) return points.back().second;
  // First point strictly after t; its predecessor is at or before t.
  const auto hi = std::upper_bound(points.begin(), points.end(), t,
                                   [](double x, const std::pair<double, double>& p) { return x < p.first; });
  const auto lo = hi - 1;
  const double s = (t - lo->first) / (hi->first - lo->first);
  return lo->second + s * (hi->second - lo->second);
}

namespace {

ModalParameters modal_at(const PlantMode& mode, double t) {
  ModalParameters p;
  p.wn = mode.wn.at(t, mode.modal.wn);
  p.zeta = mode.zeta.at(t, mode.modal.zeta);
  p.gain = mode.gain.at(t, mode.modal.gain);
  return p;
}

Submodel submodel_at(const PlantMode& mode, double t) {
  if (!mode.resonant) return mode.submodel;
  ModalParameters p = modal_at(mode, t);
  if (!(p.wn > 0.0) || !std::isfinite(p.wn) || !(p.zeta >= 0.0) || !std::isfinite(p.gain))
    throw std::invalid_argument("simulate: mode '" + mode.submodel.name + "' needs wn > 0, zeta >= 0, finite gain");
  return make_mode(mode.submodel.name, p, mode.submodel.output_derivatives);
}

// Coefficient j of a polynomial in p, times ws^(j-l): with p = ws p' the
// filter 1/D runs in normalised time t' = ws t, the lowest nonzero
// denominator coefficient (index l) keeps its size, and the same factor on
// B(p) leaves the output B(p)/D(p) u unchanged.
Eigen::VectorXd scale_coefficients(const Eigen::VectorXd& c, double ws, int l, Eigen::Index size) {
  Eigen::VectorXd s = Eigen::VectorXd::Zero(size);
  for (Eigen::Index j = 0; j < c.size(); ++j) s(j) = c(j) * std::pow(ws, static_cast<double>(j - l));
  return s;
}

// The time scale of a submodel: wn for a mode, |a_n|^(-1/n) otherwise.
double time_scale(const PlantMode& mode, const Submodel& s) {
  if (mode.resonant) return 1.0 / std::sqrt(s.a(1));
  if (s.n > 0 && s.a(s.n - 1) != 0.0) return std::pow(std::abs(s.a(s.n - 1)), -1.0 / s.n);
  return 1.0;
}

// One plant submodel simulated exactly under ZOH in normalised time. The
// filter 1/(p^l A) gives the measured output p^z B/(p^l A) u and, from the same
// states, the position B/(p^l A) u that the nonlinear effects act on.
class ModeSimulator {
 public:
  ModeSimulator(const PlantMode& mode, double T) : mode_(mode) {
    const Submodel s = submodel_at(mode, 0.0);
    s.check();
    l_ = s.rigid_poles;
    z_ = s.output_derivatives;
    order_ = s.n + s.rigid_poles;
    if (order_ > kMaxFilterOrder) throw std::invalid_argument("simulate: submodel '" + s.name + "' order too high");
    ws_ = time_scale(mode, s);
    current_ = modal_at(mode, 0.0);
    d_ = scale_coefficients(s.denominator(), ws_, l_, order_ + 1);
    b_ = scale_coefficients(s.output_numerator(), ws_, l_, order_ + 1);
    if (z_ > 0) x_ = scale_coefficients(s.b, ws_, l_, order_ + 1);
    filter_ = Prefilter(d_, ws_ * T, Hold::zoh);
  }

  // Parameters are piecewise constant: those at t_k hold over (t_{k-1}, t_k].
  void set_time(double t) {
    if (!mode_.resonant) return;
    const ModalParameters p = modal_at(mode_, t);
    if (p.wn != current_.wn || p.zeta != current_.zeta) {
      const Submodel s = submodel_at(mode_, t);
      d_ = scale_coefficients(s.denominator(), ws_, l_, order_ + 1);
      filter_.set_denominator(d_);
    }
    if (z_ == 0) {
      b_(0) = p.gain;
    } else {
      b_(z_) = p.gain * std::pow(ws_, z_);
      x_(0) = p.gain;
    }
    current_ = p;
  }

  // Output and position at t_k if the input sample were 0, leaving the state untouched.
  struct Free {
    double output, position;
  };
  Free free() const {
    Prefilter probe = filter_;
    probe.step(0.0);
    const double y = probe.combine(b_);
    return {y, z_ == 0 ? y : probe.combine(x_)};
  }
  // d output / d u_k: nonzero only for a biproper submodel.
  double feedthrough() const { return b_(order_) / d_(order_); }
  int input() const { return mode_.submodel.input; }
  double step(double u) {
    filter_.step(u);
    return filter_.combine(b_);
  }

 private:
  const PlantMode& mode_;
  int l_ = 0;
  int z_ = 0;  // derivatives of the position the sensor measures
  int order_ = 0;
  double ws_ = 1.0;
  ModalParameters current_;
  Eigen::VectorXd d_;  // scaled denominator, ascending
  Eigen::VectorXd b_;  // scaled output numerator p^z B, padded to order_ + 1
  Eigen::VectorXd x_;  // scaled position numerator B when z > 0
  Prefilter filter_;
};

struct Signals {
  Eigen::VectorXd u, y_clean, y;
};

std::vector<ModeSimulator> make_modes(const PlantSpec& plant, double T) {
  std::vector<ModeSimulator> modes;
  modes.reserve(plant.modes.size());
  for (const PlantMode& m : plant.modes) modes.emplace_back(m, T);
  return modes;
}

// The effects act on the first input; a mode on a further input takes that input as it is.
Signals run_open_loop(const PlantSpec& plant, const Eigen::VectorXd& t, double T, const Eigen::VectorXd& u,
                      const std::vector<Eigen::VectorXd>& further_u, const Eigen::VectorXd& noise) {
  std::vector<ModeSimulator> modes = make_modes(plant, T);
  EffectState effects(plant.effects);
  Signals s{u, Eigen::VectorXd::Zero(t.size()), Eigen::VectorXd()};
  const bool nonlinear = plant.effects.feeds_back();
  for (Eigen::Index k = 0; k < t.size(); ++k) {
    double x_free = 0.0;  // the position the effects act on
    for (ModeSimulator& m : modes) {
      m.set_time(t(k));
      if (nonlinear) x_free += m.free().position;
    }
    const double u_plant = effects.delayed(u(k)) + effects.branches(x_free);
    double y_plant = 0.0;
    for (ModeSimulator& m : modes)
      y_plant += m.step(m.input() == 0 ? u_plant : further_u[static_cast<std::size_t>(m.input() - 1)](k));
    effects.end_sample(u(k), x_free);
    s.y_clean(k) = y_plant + effects.output_terms(t(k) - t(0));
  }
  s.y = s.y_clean + noise;
  return s;
}

// u_k = C(r_k - y_k) with y_k = y_free + D u_k + v_k: the loop is algebraic only
// through the plant feedthrough D, so solve for u_k and then step every filter
// once with it.
Signals run_closed_loop(const PlantSpec& plant, const ExperimentSpec& ex, const Eigen::VectorXd& t,
                        const Eigen::VectorXd& r, const Eigen::VectorXd& noise) {
  std::vector<ModeSimulator> modes = make_modes(plant, ex.sample_time);
  DiscreteTransferFunction controller = ex.controller;
  controller.reset();
  const double c0 = controller.feedthrough();
  EffectState effects(plant.effects);
  Signals s{Eigen::VectorXd(t.size()), Eigen::VectorXd(t.size()), Eigen::VectorXd(t.size())};
  for (Eigen::Index k = 0; k < t.size(); ++k) {
    double y_free = 0.0, x_free = 0.0, feed = 0.0;
    for (ModeSimulator& m : modes) {
      m.set_time(t(k));
      const ModeSimulator::Free f = m.free();
      y_free += f.output;
      x_free += f.position;
      feed += m.feedthrough();
    }
    // With a delay u_k does not reach y_k; without, y_k depends on u_k through D.
    const double branches = effects.branches(x_free);
    y_free += feed * effects.known_input(branches);
    const double direct = effects.delays() ? 0.0 : feed;
    const double loop = 1.0 + c0 * direct;
    if (loop == 0.0) throw std::invalid_argument("simulate: ill-posed loop (1 + C(inf) G(inf) = 0)");
    const double y_out = effects.output_terms(t(k) - t(0));
    const double y_measured_free = y_free + y_out + noise(k);
    const double u = controller.peek(r(k) - y_measured_free) / loop;
    const double u_plant = effects.delayed(u) + branches;
    double y_plant = 0.0;
    for (ModeSimulator& m : modes) y_plant += m.step(u_plant);
    effects.end_sample(u, x_free);
    s.u(k) = u;
    s.y_clean(k) = y_plant + y_out;
    s.y(k) = s.y_clean(k) + noise(k);
    controller.step(r(k) - s.y(k));
  }
  return s;
}

// A signal on the time grid: its samples when given (a file's), else generated.
Eigen::VectorXd on_grid(const SignalSpec& spec, const Eigen::VectorXd& samples, const Eigen::VectorXd& t,
                        const char* samples_name) {
  if (samples.size() == 0) return generate(spec, t);
  if (samples.size() != t.size())
    throw std::invalid_argument(std::string("simulate: ") + samples_name + " must have one value per sample");
  return samples;
}

Eigen::VectorXd excitation(const ExperimentSpec& ex, const Eigen::VectorXd& t) {
  return on_grid(ex.excitation, ex.excitation_samples, t, "excitation_samples");
}

// Inputs 2, 3, ...
std::vector<Eigen::VectorXd> further_inputs(const ExperimentSpec& ex, const Eigen::VectorXd& t) {
  const Eigen::VectorXd none;
  std::vector<Eigen::VectorXd> inputs;
  for (std::size_t j = 0; j < static_cast<std::size_t>(ex.further_inputs()); ++j) {
    const Eigen::VectorXd& samples = j < ex.further_input_samples.size() ? ex.further_input_samples[j] : none;
    const bool has_signal = j < ex.further_excitations.size();
    if (samples.size() == 0 && !has_signal)
      throw std::invalid_argument("simulate: input " + std::to_string(j + 2) + " has neither samples nor a signal");
    inputs.push_back(on_grid(has_signal ? ex.further_excitations[j] : SignalSpec{}, samples, t,
                             "further_input_samples"));
  }
  return inputs;
}

// An unstable experiment (an unstable mode or loop, or a cubic stiffness whose
// local stiffness 3 c x^2 outgrows what the explicit sampled loop can carry)
// overflows; it is refused where it starts rather than written as NaN.
void check_bounded(const PlantSpec& plant, const ExperimentSpec& ex, const Eigen::VectorXd& t, const Signals& s) {
  for (Eigen::Index k = 0; k < t.size(); ++k) {
    if (std::isfinite(s.y_clean(k)) && std::isfinite(s.u(k))) continue;
    std::string cause = ex.closed_loop ? "an unstable mode or closed loop" : "an unstable mode";
    if (plant.effects.cubic != 0.0)
      cause +=
          ", or the cubic stiffness (explicit in the sampled loop: a stiffer cubic or a larger"
          " position needs a higher sample rate)";
    throw std::domain_error("simulate: the plant's output diverged at t = " + std::to_string(t(k)) + " s (sample " +
                            std::to_string(k) + "): " + cause);
  }
}

Signals run(const PlantSpec& plant, const ExperimentSpec& ex, const Eigen::VectorXd& t, const Eigen::VectorXd& w,
            const std::vector<Eigen::VectorXd>& further_u, const Eigen::VectorXd& noise) {
  Signals s = ex.closed_loop ? run_closed_loop(plant, ex, t, w, noise)
                             : run_open_loop(plant, t, ex.sample_time, w, further_u, noise);
  check_bounded(plant, ex, t, s);
  return s;
}

// Unit-variance white Gaussian samples; scaled by the caller.
Eigen::VectorXd standard_noise(std::uint64_t seed, Eigen::Index n) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::VectorXd v(n);
  for (Eigen::Index k = 0; k < n; ++k) v(k) = normal(rng);
  return v;
}

double centred_power(const Eigen::VectorXd& x) {
  if (x.size() == 0) return 0.0;
  return (x.array() - x.mean()).square().mean();
}

void check_specs(const PlantSpec& plant, const ExperimentSpec& ex) {
  if (plant.modes.empty()) throw std::invalid_argument("simulate: the plant has no modes");
  if (!(ex.sample_time > 0.0) || !std::isfinite(ex.sample_time))
    throw std::invalid_argument("simulate: sample_time must be > 0");
  if (!(ex.duration > 0.0) || !std::isfinite(ex.duration))
    throw std::invalid_argument("simulate: duration must be > 0");
  if (ex.closed_loop && ex.controller.empty()) throw std::invalid_argument("simulate: closed loop needs a controller");
  if (!(plant.noise_variance >= 0.0) || !std::isfinite(plant.noise_variance))
    throw std::invalid_argument("simulate: noise_variance must be >= 0");
  if (plant.snr_db && !std::isfinite(*plant.snr_db)) throw std::invalid_argument("simulate: snr_db must be finite");
  for (const PlantMode& m : plant.modes) {
    const int input = m.submodel.input;
    if (input < 0 || input > ex.further_inputs())
      throw std::invalid_argument("simulate: mode " + m.submodel.name + " is driven by input " +
                                  std::to_string(input + 1) + " of " + std::to_string(1 + ex.further_inputs()));
  }
  if (ex.further_inputs() > 0 && ex.closed_loop)
    throw std::invalid_argument("simulate: further inputs are for open loop only (the controller gives one u)");
  const PlantEffects& e = plant.effects;
  if (e.input_delay < 0) throw std::invalid_argument("simulate: input_delay must be >= 0");
  if (!std::isfinite(e.output_offset) || !std::isfinite(e.input_offset) || !std::isfinite(e.drift) ||
      !std::isfinite(e.cubic) || !(e.coulomb >= 0.0) || !std::isfinite(e.coulomb))
    throw std::invalid_argument("simulate: effects must be finite (coulomb >= 0)");
}

void fill_truth(const PlantSpec& plant, const Eigen::VectorXd& t, SimulationResult& out) {
  int cols = 0;
  for (const PlantMode& m : plant.modes) {
    const std::string& name = m.submodel.name;
    if (m.resonant) {
      out.truth_columns.insert(out.truth_columns.end(), {name + "_wn", name + "_zeta", name + "_gain"});
      cols += 3;
    } else {
      for (int j = 0; j < m.submodel.n_theta(); ++j) out.truth_columns.push_back(name + "_theta" + std::to_string(j));
      cols += m.submodel.n_theta();
    }
  }
  out.truth.resize(t.size(), cols);
  for (Eigen::Index k = 0; k < t.size(); ++k) {
    int c = 0;
    for (const PlantMode& m : plant.modes) {
      if (m.resonant) {
        const ModalParameters p = modal_at(m, t(k));
        out.truth.row(k).segment(c, 3) << p.wn, p.zeta, p.gain;
        c += 3;
      } else {
        out.truth.row(k).segment(c, m.submodel.n_theta()) = m.submodel.theta().transpose();
        c += m.submodel.n_theta();
      }
    }
  }
}

}  // namespace

SimulationResult simulate(const PlantSpec& plant, const ExperimentSpec& ex) {
  check_specs(plant, ex);
  const auto n = static_cast<Eigen::Index>(std::llround(ex.duration / ex.sample_time));
  if (n < 1) throw std::invalid_argument("simulate: duration shorter than one sample");
  const Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(n, 0.0, static_cast<double>(n - 1)) * ex.sample_time;
  const Eigen::VectorXd w = excitation(ex, t);
  const std::vector<Eigen::VectorXd> further_u = further_inputs(ex, t);

  SimulationResult out;
  out.noise_variance = plant.noise_variance;
  if (plant.snr_db) {
    // The SNR refers to the noise-free experiment's output power.
    const Signals clean = run(plant, ex, t, w, further_u, Eigen::VectorXd::Zero(n));
    out.noise_variance = centred_power(clean.y_clean) / std::pow(10.0, *plant.snr_db / 10.0);
  }
  const Eigen::VectorXd noise = out.noise_variance > 0.0
                                    ? Eigen::VectorXd(std::sqrt(out.noise_variance) * standard_noise(ex.seed, n))
                                    : Eigen::VectorXd(Eigen::VectorXd::Zero(n));
  Signals s = run(plant, ex, t, w, further_u, noise);

  out.record.t = t;
  out.record.u = std::move(s.u);
  out.record.y = std::move(s.y);
  if (ex.closed_loop) out.record.r = w;
  out.record.further_u = further_u;
  out.y_clean = std::move(s.y_clean);
  fill_truth(plant, t, out);
  return out;
}

AdditiveModel plant_model_at(const PlantSpec& plant, double t) {
  AdditiveModel model;
  model.submodels.reserve(plant.modes.size());
  for (const PlantMode& m : plant.modes) model.submodels.push_back(submodel_at(m, t));
  return model;
}

bool ExperimentSpec::operator==(const ExperimentSpec& other) const {
  return sample_time == other.sample_time && duration == other.duration && seed == other.seed &&
         closed_loop == other.closed_loop && controller == other.controller && excitation == other.excitation &&
         excitation_samples.size() == other.excitation_samples.size() &&
         excitation_samples == other.excitation_samples && further_excitations == other.further_excitations &&
         further_input_samples.size() == other.further_input_samples.size() &&
         std::equal(further_input_samples.begin(), further_input_samples.end(), other.further_input_samples.begin(),
                    [](const Eigen::VectorXd& a, const Eigen::VectorXd& b) { return a.size() == b.size() && a == b; });
}

}  // namespace modalwatch
