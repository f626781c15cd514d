// modalwatch diagnose: fit, test the residual, trace it to an effect, add the
// best effect, refit, repeat.
//
// Fitting. The configured structure starts from the additive SRIVC of the
// paper (fit_srivc; open or closed loop) and from the configured values; each
// start is refined by output-error Levenberg-Marquardt on the simulated
// augmented model (simulate_augmented), which also fits the effects: the
// effects enter the simulated output, not the SRIVC regressors, because the
// nonlinear branches are fed by the simulated output. A candidate effect starts
// from one Gauss-Newton step from zero on the current residual (its
// least-squares size), an extra mode from the peak of the residual-to-input
// spectrum (then SRIVC of the enlarged additive model), a delay by a scan of
// whole samples with a short refit each (the cross-correlation lag is reported),
// complex modes (a numerator b0 + b1 p for every mode) from their SRIVC refit.
//
// Ranking. Each step refits the current model alone, from the same start and
// with the same iterations as each candidate; a candidate's credit is the
// validation RMS of that refit minus its own, so an effect is not credited with
// what more refinement of the model gives anyway. Candidates are ranked by
// credit (the order of the validation RMS they leave); the Bayesian information
// criterion BIC = N ln(MSE_est) + k ln N on the estimation part is reported,
// and the best candidate is added only when its credit is more than
// DiagnoseOptions::min_improvement of the refit's validation RMS and it lowers
// the refit's BIC. The added step is the candidate made physical
// (physical.hpp), which must still earn that much: a merge or a removal can
// undo what the candidate gained, and the next candidate is tried instead.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>

#include <Eigen/Cholesky>
#include <Eigen/QR>

#include "modalwatch/diagnose.hpp"
#include "modalwatch/initial_modes.hpp"
#include "modalwatch/physical.hpp"
#include "modalwatch/srivc.hpp"
#include "output_error.hpp"

namespace modalwatch {

SrivcOptions LoopSpec::srivc_options() const {
  SrivcOptions o;
  o.closed_loop = closed;
  o.controller = controller;
  o.input_hold = input_hold();
  o.best_cycle = true;
  return o;
}

namespace {

using namespace diagnose_detail;

double rms(const Eigen::VectorXd& x) { return x.size() ? std::sqrt(x.squaredNorm() / x.size()) : 0.0; }

// ------------------------------------------------------------ starts

// SRIVC of the linear part on the record with the output terms removed; only
// for models whose effects do not act on the plant input.
bool srivc_start(const AdditiveModel& linear, const ModelEffects& e, const Record& data, const LoopSpec& loop,
                 const DiagnoseOptions& options, AdditiveModel& out) {
  if (e.input_offset_on || e.coulomb_on || e.cubic_on || e.input_delay > 0) return false;
  Record corrected = data;
  if (e.output_offset_on) corrected.y.array() -= e.output_offset;
  if (e.drift_on) corrected.y.array() -= e.drift * (data.t.array() - data.t(0));
  SrivcOptions so = loop.srivc_options();
  so.output_hold = options.output_hold;
  so.max_iterations = 60;
  try {
    out = fit_srivc(corrected, linear, so).model;
    return out.beta().allFinite();
  } catch (const std::exception&) {
    return false;
  }
}

// The best of: the given model refined, and its SRIVC refit refined.
Refined fit_structure(const AugmentedModel& start, const Problem& pb, const DiagnoseOptions& options, bool try_srivc) {
  Refined best = refine(start, pb, options.oe_iterations);
  AdditiveModel srivc;
  if (try_srivc && srivc_start(start.linear, start.effects, pb.data, pb.loop, options, srivc)) {
    AugmentedModel s = start;
    s.linear = srivc;
    Refined r = refine(s, pb, options.oe_iterations);
    if (r.cost < best.cost) best = r;
  }
  return best;
}

// Covariance of the linear part's beta at the model (empty when unknown).
Eigen::MatrixXd beta_covariance(const AugmentedModel& m, const Problem& pb) {
  const Eigen::MatrixXd E = free_beta_map(m.linear);  // beta = E * free parameters
  const Eigen::Index nf = E.cols();
  const Eigen::MatrixXd all = refine(m, pb, 0, true).covariance;
  if (all.rows() < nf) return Eigen::MatrixXd();
  if (nf == m.linear.n_beta()) return all.topLeftCorner(nf, nf);  // no shared poles: E = I
  return E * all.topLeftCorner(nf, nf) * E.transpose();
}

// The physical check (physical.hpp) on a fitted structure: its verdicts
// recorded, the projected model rescored, and a refit when the structure
// changed. stds: the modal standard deviations of the returned model's submodels.
Refined make_physical(Refined r, const Problem& pb, const DiagnoseOptions& options, std::vector<ModeFinding>& findings,
                      std::vector<ModalParameters>& stds) {
  stds.clear();
  for (std::size_t round = 0; round <= r.model.linear.submodels.size(); ++round) {
    const PhysicalCheck check = check_physical(r.model.linear, beta_covariance(r.model, pb), pb.data.sample_time());
    for (const auto& f : check.findings)
      if (f.verdict != ModeVerdict::physical) findings.push_back(f);
    if (!check.changed()) {
      for (const auto& f : check.findings) stds.push_back(f.fitted_std);
      break;
    }
    AugmentedModel m = r.model;
    m.linear = check.model;
    if (check.refit) {
      r = fit_structure(m, pb, options, true);
      continue;
    }
    r.model = m;
    r.cost = cost_of(output(m, pb), pb.data.y);
    break;
  }
  if (stds.empty()) {  // the model changed after its last check
    const Eigen::MatrixXd cov = beta_covariance(r.model, pb);
    const AdditiveModel& lin = r.model.linear;
    for (std::size_t i = 0; i < lin.submodels.size(); ++i) {
      const int o = lin.offset(static_cast<int>(i)), n = lin.submodels[i].n_theta();
      stds.push_back(cov.rows() == lin.n_beta() ? modal_std(lin.submodels[i], cov.block(o, o, n, n))
                                                : ModalParameters{});
    }
  }
  return r;
}

// Least-squares size of one new scalar parameter from zero: one Gauss-Newton
// step with the sensitivity (y(h) - y(0)) / h.
double gauss_newton_start(const AugmentedModel& with_h, const Eigen::VectorXd& y0, double h, const Problem& pb) {
  const Eigen::VectorXd yh = output(with_h, pb);
  if (yh.size() != y0.size()) return 0.0;
  const Eigen::VectorXd J = (yh - y0) / h;
  const double jj = J.squaredNorm();
  if (!(jj > 0.0) || !std::isfinite(jj)) return 0.0;
  return J.dot(pb.data.y - y0) / jj;
}

// ------------------------------------------------------------ evaluation

struct Scored {
  double estimation_rms = kInf, validation_rms = kInf, fit_percent = -kInf, bic = kInf;
  Eigen::VectorXd validation_output;
};

Scored score(const AugmentedModel& m, double est_cost, const Problem& est, const Problem& val, Eigen::Index lead_in) {
  Scored s;
  const double N = static_cast<double>(est.data.size());
  if (!std::isfinite(est_cost)) return s;
  s.estimation_rms = std::sqrt(est_cost / N);
  s.bic = N * std::log(std::max(est_cost / N, 1e-300)) + m.n_params() * std::log(N);
  s.validation_output = output(m, val);
  if (s.validation_output.size() != val.data.size()) return s;
  const Eigen::Index n = val.data.size() - lead_in;
  s.validation_rms = rms(val.data.y.tail(n) - s.validation_output.tail(n));
  s.fit_percent = fit_percent(val.data.y.tail(n), s.validation_output.tail(n));
  return s;
}

double rms_or_one(const Eigen::VectorXd& x) {
  const double r = rms(x.array() - x.mean());
  return r > 0.0 ? r : 1.0;
}

// ------------------------------------------------------------ candidates

struct Context {
  const Problem& est;
  const Problem& val;
  const DiagnoseOptions& options;
  const AdditiveModel& configured;  // the configured starting values
};

Candidate finish(EffectKind kind, const Refined& r, const Context& ctx) {
  Candidate c;
  c.kind = kind;
  c.model = r.model;
  const Scored s = score(r.model, r.cost, ctx.est, ctx.val, ctx.options.validation_lead_in);
  c.estimation_rms = s.estimation_rms;
  c.validation_rms = s.validation_rms;
  c.fit_percent = s.fit_percent;
  c.bic = s.bic;
  c.valid = std::isfinite(s.validation_rms);
  if (!c.valid) c.note = "fit failed or diverged on validation";
  return c;
}

Refit refit_alone(const AugmentedModel& current, const Context& ctx) {
  const Refined r = fit_structure(current, ctx.est, ctx.options, true);
  const Scored s = score(r.model, r.cost, ctx.est, ctx.val, ctx.options.validation_lead_in);
  Refit out;
  out.model = r.model;
  out.estimation_rms = s.estimation_rms;
  out.validation_rms = s.validation_rms;
  out.fit_percent = s.fit_percent;
  out.bic = s.bic;
  out.valid = std::isfinite(s.validation_rms);
  return out;
}

Candidate invalid(EffectKind kind, const std::string& why) {
  Candidate c;
  c.kind = kind;
  c.valid = false;
  c.note = why;
  c.estimation_rms = c.validation_rms = c.bic = kInf;
  return c;
}

std::string next_mode_name(const AdditiveModel& m) {
  for (int i = 1;; ++i) {
    const std::string name = "added" + std::to_string(i);
    bool used = false;
    // With several inputs a mode's submodels are name_<input>.
    for (const auto& s : m.submodels) used = used || s.name == name || s.name.rfind(name + "_", 0) == 0;
    if (!used) return name;
  }
}

// An added mode the fit puts at or above the Nyquist frequency is no
// resonance of the record (the physical check would take it out again).
bool above_nyquist(const AugmentedModel& m, const Context& ctx) {
  const Submodel& s = m.linear.submodels.back();
  return s.is_mode() && !(modal_parameters(s).wn < std::numbers::pi / ctx.est.data.sample_time());
}

// Several inputs: the residual's response to every input (H = S_eu S_uu^-1,
// initial_modes.hpp) at its largest |H| over the excited band; one mode per
// input there, each with that input's residue.
Candidate candidate_modes_per_input(const AugmentedModel& current, const Eigen::VectorXd& y0, const Context& ctx) {
  Record residual = ctx.est.data;
  residual.y -= y0;
  const FrequencyResponse h = frequency_response(
      residual, false, static_cast<int>(std::min<Eigen::Index>(2048, residual.size() / 4)), Hold::zoh);
  const double excited = 1e-3 * h.excitation.maxCoeff();
  Eigen::Index peak = -1;
  for (Eigen::Index f = 2; f < h.frequency_hz.size(); ++f)
    if (h.excitation(f) > excited && (peak < 0 || h.magnitude(f) > h.magnitude(peak))) peak = f;
  if (peak < 0) return invalid(EffectKind::mode, "no excited frequency");
  AugmentedModel m = current;
  const std::string name = next_mode_name(current.linear);
  std::string leader;  // one resonance, one A: every input's view shares the first's
  for (int j = 0; j < current.linear.n_inputs(); ++j) {
    ModalParameters start;
    start.wn = 2.0 * std::numbers::pi * h.frequency_hz(peak);
    start.zeta = 0.05;
    start.gain = resonance_gain(h.input_response(j)(peak), start.wn, start.zeta, current.linear.output_derivatives());
    if (start.gain == 0.0) continue;
    m.linear.submodels.push_back(
        make_mode(name + "_" + current.linear.input_name(j), start, current.linear.output_derivatives()));
    m.linear.submodels.back().input = j;
    if (leader.empty())
      leader = m.linear.submodels.back().name;
    else
      m.linear.submodels.back().poles_of = leader;
  }
  Candidate c = finish(EffectKind::mode, fit_structure(m, ctx.est, ctx.options, true), ctx);
  if (c.valid && above_nyquist(c.model, ctx))
    return invalid(EffectKind::mode, "the residual's peak was fitted above the Nyquist frequency");
  if (c.valid) {
    const ModalParameters p = modal_parameters(c.model.linear.submodels.back());
    c.params = {{"wn", p.wn}, {"zeta", p.zeta}, {"hz", p.hz()}};
  }
  return c;
}

Candidate candidate_mode(const AugmentedModel& current, const Eigen::VectorXd& y0, const Context& ctx) {
  const Record& d = ctx.est.data;
  if (current.linear.n_inputs() > 1) return candidate_modes_per_input(current, y0, ctx);
  const double T = d.sample_time();
  // The input is the measured u in both loops: in closed loop S_eu/S_uu is
  // only a start, the fit decides.
  const Spectra sp = welch_spectra(d.y - y0, d.u, T, static_cast<int>(std::min<Eigen::Index>(2048, d.size() / 4)));
  const double excited = 1e-3 * sp.input_psd.maxCoeff();
  Eigen::Index peak = -1;
  for (Eigen::Index f = 2; f < sp.frequency_hz.size(); ++f)
    if (sp.input_psd(f) > excited && (peak < 0 || sp.residual_to_input(f) > sp.residual_to_input(peak))) peak = f;
  if (peak < 0) return invalid(EffectKind::mode, "no excited frequency");
  ModalParameters start;
  start.wn = 2.0 * std::numbers::pi * sp.frequency_hz(peak);
  start.zeta = 0.05;
  // At resonance (j wn)^z b0 / (j 2 zeta) = H.
  const int z = current.linear.output_derivatives();
  start.gain = resonance_gain(sp.cross(peak), start.wn, start.zeta, z);
  if (start.gain == 0.0) start.gain = 2.0 * start.zeta * sp.residual_to_input(peak) / std::pow(start.wn, z);
  AugmentedModel m = current;
  m.linear.submodels.push_back(make_mode(next_mode_name(current.linear), start, z));
  Candidate c = finish(EffectKind::mode, fit_structure(m, ctx.est, ctx.options, true), ctx);
  if (c.valid && above_nyquist(c.model, ctx))
    return invalid(EffectKind::mode, "the residual's peak was fitted above the Nyquist frequency");
  if (c.valid) {
    const ModalParameters p = modal_parameters(c.model.linear.submodels.back());
    c.params = {{"wn", p.wn}, {"zeta", p.zeta}, {"gain", p.gain}, {"hz", p.hz()}};
  }
  return c;
}

Candidate candidate_rigid_body(const AugmentedModel& current, const Eigen::VectorXd& y0, const Context& ctx) {
  for (const auto& s : current.linear.submodels)
    if (s.rigid_poles > 0) return invalid(EffectKind::rigid_body, "the model has a rigid body");
  const int z = current.linear.output_derivatives();
  if (z == 2) return invalid(EffectKind::rigid_body, "an accelerometer sees a rigid body as the feedthrough b0");
  const Record& d = ctx.est.data;
  const double D = d.t(d.size() - 1) - d.t(0);
  // b0 / p^2 measured as p^z: a response growing as t^(2-z).
  const double h = 1e-3 * rms_or_one(d.y) / (rms_or_one(d.u) * std::max(z == 0 ? D * D : std::pow(D, 2 - z), 1e-12));
  AugmentedModel m = current;
  m.linear.submodels.push_back(make_rigid_body("rigid", h, 2, z));
  double g = gauss_newton_start(m, y0, h, ctx.est);
  if (g == 0.0) return invalid(EffectKind::rigid_body, "no sensitivity");
  m.linear.submodels.back().b(0) = g;
  Candidate c = finish(EffectKind::rigid_body, fit_structure(m, ctx.est, ctx.options, true), ctx);
  if (c.valid) c.params = {{"gain", c.model.linear.submodels.back().b(0)}};
  return c;
}

// Every plain mode with a numerator b0 + b1 p, b1 from the SRIVC refit (linear in it).
Candidate candidate_complex_modes(const AugmentedModel& current, const Context& ctx) {
  AugmentedModel m = current;
  int modes = 0;
  for (Submodel& s : m.linear.submodels) {
    // (b0 + b1 p) p^z / A must stay proper: not for an acceleration.
    if (!s.is_mode() || 1 + s.output_derivatives > s.n) continue;
    s.m = 1;
    s.b.conservativeResize(2);
    s.b(1) = 0.0;
    ++modes;
  }
  if (modes == 0)
    return invalid(EffectKind::complex_modes, "no mode with a real residue that may take b1 p (none as acceleration)");
  Candidate c = finish(EffectKind::complex_modes, fit_structure(m, ctx.est, ctx.options, true), ctx);
  if (c.valid) c.params = {{"modes", static_cast<double>(modes)}};
  return c;
}

Candidate candidate_feedthrough(const AugmentedModel& current, const Eigen::VectorXd& y0, const Context& ctx) {
  for (const auto& s : current.linear.submodels)
    if (s.is_feedthrough()) return invalid(EffectKind::feedthrough, "the model has a feedthrough");
  const double h = 1e-3 * rms_or_one(ctx.est.data.y) / rms_or_one(ctx.est.data.u);
  AugmentedModel m = current;
  // A constant measured response: with a derivative output, b0 / p^z.
  const int z = current.linear.output_derivatives();
  m.linear.submodels.push_back(make_rigid_body(next_mode_name(current.linear), h, z, z));
  const double g = gauss_newton_start(m, y0, h, ctx.est);
  if (g == 0.0) return invalid(EffectKind::feedthrough, "no sensitivity");
  m.linear.submodels.back().b(0) = g;
  Candidate c = finish(EffectKind::feedthrough, fit_structure(m, ctx.est, ctx.options, true), ctx);
  if (c.valid) c.params = {{"gain", c.model.linear.submodels.back().b(0)}};
  return c;
}

// A scalar effect switched on at h, started by Gauss-Newton and refined with the rest.
template <class Set>
Refined scalar_effect(const AugmentedModel& current, const Eigen::VectorXd& y0, double h, Set set, const Context& ctx) {
  AugmentedModel m = current;
  set(m.effects, h);
  const double start = gauss_newton_start(m, y0, h, ctx.est);
  if (start == 0.0) return {};
  set(m.effects, start);
  return fit_structure(m, ctx.est, ctx.options, true);
}

Candidate candidate_offset(const AugmentedModel& current, const Eigen::VectorXd& y0, const Context& ctx) {
  const Record& d = ctx.est.data;
  Refined out, in;
  if (!current.effects.output_offset_on)
    out = scalar_effect(
        current, y0, 1e-3 * rms_or_one(d.y),
        [](ModelEffects& e, double v) {
          e.output_offset_on = true;
          e.output_offset = v;
        },
        ctx);
  if (!current.effects.input_offset_on)
    in = scalar_effect(
        current, y0, 1e-3 * rms_or_one(d.u),
        [](ModelEffects& e, double v) {
          e.input_offset_on = true;
          e.input_offset = v;
        },
        ctx);
  if (!std::isfinite(out.cost) && !std::isfinite(in.cost)) return invalid(EffectKind::offset, "already in the model");
  // Output (sensor) or input (force) offset: the one with the lower estimation error.
  const bool input = in.cost < out.cost;
  Candidate c = finish(EffectKind::offset, input ? in : out, ctx);
  if (c.valid)
    c.params = {{"value", input ? c.model.effects.input_offset : c.model.effects.output_offset},
                {"input", input ? 1.0 : 0.0}};
  return c;
}

Candidate candidate_drift(const AugmentedModel& current, const Eigen::VectorXd& y0, const Context& ctx) {
  if (current.effects.drift_on) return invalid(EffectKind::drift, "already in the model");
  const Record& d = ctx.est.data;
  const double D = std::max(d.t(d.size() - 1) - d.t(0), 1e-12);
  const Refined r = scalar_effect(
      current, y0, 1e-3 * rms_or_one(d.y) / D,
      [](ModelEffects& e, double v) {
        e.drift_on = true;
        e.drift = v;
      },
      ctx);
  if (!std::isfinite(r.cost)) return invalid(EffectKind::drift, "no sensitivity");
  Candidate c = finish(EffectKind::drift, r, ctx);
  if (c.valid) c.params = {{"slope", c.model.effects.drift}};
  return c;
}

Candidate candidate_coulomb(const AugmentedModel& current, const Eigen::VectorXd& y0, const Context& ctx) {
  if (current.effects.coulomb_on) return invalid(EffectKind::coulomb, "already in the model");
  const Refined r = scalar_effect(
      current, y0, 1e-3 * rms_or_one(ctx.est.data.u),
      [](ModelEffects& e, double v) {
        e.coulomb_on = true;
        e.coulomb = v;
      },
      ctx);
  if (!std::isfinite(r.cost)) return invalid(EffectKind::coulomb, "no sensitivity");
  Candidate c = finish(EffectKind::coulomb, r, ctx);
  if (c.valid) c.params = {{"fc", c.model.effects.coulomb}};
  if (c.valid && !(c.model.effects.coulomb > 0.0)) {
    c.valid = false;  // friction that pushes: not a physical effect
    c.note = "negative friction level";
  }
  return c;
}

Candidate candidate_cubic(const AugmentedModel& current, const Eigen::VectorXd& y0, const Context& ctx) {
  if (current.effects.cubic_on) return invalid(EffectKind::cubic, "already in the model");
  const Record& d = ctx.est.data;
  const double sy = rms_or_one(d.y);
  const Refined r = scalar_effect(
      current, y0, 1e-3 * rms_or_one(d.u) / (sy * sy * sy),
      [](ModelEffects& e, double v) {
        e.cubic_on = true;
        e.cubic = v;
      },
      ctx);
  if (!std::isfinite(r.cost)) return invalid(EffectKind::cubic, "no sensitivity");
  Candidate c = finish(EffectKind::cubic, r, ctx);
  if (c.valid) c.params = {{"c", c.model.effects.cubic}};
  return c;
}

// Lag of the largest |cross-correlation| of the residual with past input.
int correlation_lag(const Eigen::VectorXd& e, const Eigen::VectorXd& u, int max_lag) {
  const Eigen::VectorXd ec = e.array() - e.mean(), uc = u.array() - u.mean();
  int best = 0;
  double best_value = -1.0;
  for (int tau = 0; tau <= max_lag; ++tau) {
    double s = 0.0;
    for (Eigen::Index k = tau; k < e.size(); ++k) s += ec(k) * uc(k - tau);
    if (std::abs(s) > best_value) {
      best_value = std::abs(s);
      best = tau;
    }
  }
  return best;
}

Candidate candidate_delay(const AugmentedModel& current, const Eigen::VectorXd& y0, const Context& ctx) {
  if (current.effects.input_delay > 0) return invalid(EffectKind::delay, "already in the model");
  const int lag = correlation_lag(ctx.est.data.y - y0, ctx.est.data.u, ctx.options.max_delay);
  // Whole samples 1..max_delay, each with a short refit from the current model
  // and from the configured values (the current fit has bent its modes to
  // mimic the delay); the best gets the full refit.
  Refined best;
  int best_d = 0;
  for (int d = 1; d <= ctx.options.max_delay; ++d) {
    for (int from = 0; from < 2; ++from) {
      AugmentedModel m = current;
      if (from == 1) m.linear = ctx.configured;
      m.effects.input_delay = d;
      const Refined r = refine(m, ctx.est, std::min(8, ctx.options.oe_iterations));
      if (r.cost < best.cost) {
        best = r;
        best_d = d;
      }
    }
  }
  if (best_d == 0) return invalid(EffectKind::delay, "no delay could be fitted");
  Candidate c = finish(EffectKind::delay, refine(best.model, ctx.est, ctx.options.oe_iterations), ctx);
  if (c.valid) c.params = {{"samples", static_cast<double>(best_d)}, {"xcorr_lag", static_cast<double>(lag)}};
  return c;
}

// 0.1 -> "10 %", 0.025 -> "2.5 %".
std::string percent(double fraction) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g %%", 100.0 * fraction);
  return text;
}

// 0.0123456 -> "0.01235".
std::string number(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%.4g", v);
  return text;
}

// Resonances added: with several inputs one has a submodel per input, and
// the further ones share the first's poles.
int added_modes(const AugmentedModel& m) {
  int n = 0;
  for (const auto& s : m.linear.submodels) n += s.name.rfind("added", 0) == 0 && s.poles_of.empty() ? 1 : 0;
  return n;
}

DiagnoseStep make_step(const std::string& effect, const EffectParams& params, const AugmentedModel& m, double cost,
                       const Problem& est, const Problem& val, const DiagnoseOptions& options) {
  DiagnoseStep s;
  s.effect = effect;
  s.params = params;
  s.model = m;
  const Scored sc = score(m, cost, est, val, options.validation_lead_in);
  s.estimation_rms = sc.estimation_rms;
  s.validation_rms = sc.validation_rms;
  s.fit_percent = sc.fit_percent;
  s.bic = sc.bic;
  s.validation_output = sc.validation_output;
  const Eigen::Index n = val.data.size() - options.validation_lead_in;
  if (s.validation_output.size() == val.data.size())
    s.residual = analyse_residual(val.data.y.tail(n) - s.validation_output.tail(n), val.data.u.tail(n),
                                  val.data.sample_time(), options.max_lag);
  return s;
}

// The refit alone of the last step, measured when the augmentation stopped, is
// the same structure closer to the data (more refinement from a fresh SRIVC
// start): where it earns what an effect must (more than min_improvement of
// the validation RMS, made physical), it is the result, as a last step
// "refit", rather than the less refined model it improves on.
void adopt_refit(DiagnoseResult& result, const Problem& est, const Problem& val, const DiagnoseOptions& options) {
  const DiagnoseStep& last = result.steps.back();
  const double base = last.validation_rms;
  const double needed = (1.0 - options.min_improvement) * base;
  if (!last.refit.valid || !(last.refit.validation_rms < needed) || !(last.refit.estimation_rms <= last.estimation_rms))
    return;
  std::vector<ModeFinding> findings;
  std::vector<ModalParameters> modal_std;
  const double n = static_cast<double>(est.data.size());
  const Refined chosen =
      make_physical({last.refit.model, last.refit.estimation_rms * last.refit.estimation_rms * n, {}}, est, options,
                    findings, modal_std);
  DiagnoseStep s = make_step("refit", {}, chosen.model, chosen.cost, est, val, options);
  if (!std::isfinite(s.estimation_rms) || !(s.validation_rms < needed)) return;
  s.physical = std::move(findings);
  s.modal_std = std::move(modal_std);
  s.refit_validation_rms = base;
  s.credit = base - s.validation_rms;
  result.stop_reason += "; the last model refitted alone lowers the validation RMS " + number(base) + " -> " +
                        number(s.validation_rms) + " and is the result";
  result.steps.push_back(std::move(s));
}

}  // namespace

const char* stop_name(DiagnoseStop stop) {
  switch (stop) {
    case DiagnoseStop::residual_passes:
      return "residual_passes";
    case DiagnoseStop::diverges:
      return "diverges";
    case DiagnoseStop::max_steps:
      return "max_steps";
    case DiagnoseStop::min_improvement:
      return "min_improvement";
    case DiagnoseStop::bic:
      return "bic";
    case DiagnoseStop::mode_cap:
      return "mode_cap";
    case DiagnoseStop::not_fitted:
      return "not_fitted";
  }
  return "?";
}

DiagnoseResult diagnose(const Record& estimation, const Record& validation, const AdditiveModel& initial,
                        const LoopSpec& loop, const DiagnoseOptions& options) {
  const int min_samples = std::max(8 * options.max_lag, 4 * initial.n_beta() + 16);
  if (options.validation_lead_in < 0 || options.validation_lead_in >= validation.size())
    throw std::invalid_argument("diagnose: validation_lead_in outside the validation record");
  if (estimation.size() < min_samples || validation.size() - options.validation_lead_in < min_samples)
    throw std::invalid_argument("diagnose: estimation and validation parts need at least " +
                                std::to_string(min_samples) + " samples each");
  if (loop.closed && (!estimation.has_reference() || !validation.has_reference()))
    throw std::invalid_argument("diagnose: closed loop needs the reference r in both parts");
  if (loop.closed && loop.controller.empty()) throw std::invalid_argument("diagnose: closed loop needs a controller");
  const Problem est{estimation, loop};
  const Problem val{validation, loop};
  std::vector<ModeFinding> findings;
  const AdditiveModel start = physical_start(initial, estimation.sample_time(), findings);
  const Context ctx{est, val, options, start};

  DiagnoseResult result;
  AugmentedModel configured;
  configured.linear = start;
  std::vector<ModalParameters> modal_std;
  Refined current = make_physical(fit_structure(configured, est, options, true), est, options, findings, modal_std);
  if (!std::isfinite(current.cost)) throw std::runtime_error("diagnose: the configured model cannot be fitted");
  result.steps.push_back(make_step("none", {}, current.model, current.cost, est, val, options));
  result.steps.back().physical = findings;
  result.steps.back().modal_std = modal_std;
  if (options.progress) options.progress({0, "none", result.steps.back().validation_rms, true, {}});

  auto enabled = [&](EffectKind k) {
    return std::find(options.library.begin(), options.library.end(), k) != options.library.end();
  };
  auto stop = [&](DiagnoseStop rule, std::string why) {
    result.stop = rule;
    result.stop_reason = std::move(why);
  };
  for (int step = 0;; ++step) {
    DiagnoseStep& now = result.steps.back();
    if (!std::isfinite(now.validation_rms)) {
      stop(DiagnoseStop::diverges, "the model diverges on the validation part");
      break;
    }
    if (now.residual.pass()) {
      stop(DiagnoseStop::residual_passes, "residual tests pass");
      break;
    }
    if (step >= options.max_steps) {
      stop(DiagnoseStop::max_steps, std::to_string(step) + " effects added, the most allowed");
      break;
    }
    const Eigen::VectorXd y0 = output(now.model, est);
    const bool mode_capped = enabled(EffectKind::mode) && added_modes(now.model) >= options.max_modes_added;
    // The refit alone only when a candidate will be measured against it.
    const bool any_candidate = std::any_of(options.library.begin(), options.library.end(),
                                           [&](EffectKind k) { return k != EffectKind::mode || !mode_capped; });
    if (any_candidate) {
      now.refit = refit_alone(now.model, ctx);
      if (options.progress)
        options.progress({step + 1, "refit", now.refit.validation_rms, now.refit.valid,
                          now.refit.valid ? "" : "diverged on validation"});
    }
    // The yardstick of the credit; the model as it stands when its refit diverges on validation.
    const double base_rms = now.refit.valid ? now.refit.validation_rms : now.validation_rms;
    const double base_bic = now.refit.valid ? now.refit.bic : now.bic;
    std::vector<Candidate> candidates;
    auto tried = [&](Candidate c) {
      if (options.progress) options.progress({step + 1, effect_name(c.kind), c.validation_rms, c.valid, c.note});
      candidates.push_back(std::move(c));
    };
    if (enabled(EffectKind::mode) && !mode_capped) tried(candidate_mode(now.model, y0, ctx));
    if (enabled(EffectKind::rigid_body)) tried(candidate_rigid_body(now.model, y0, ctx));
    if (enabled(EffectKind::offset)) tried(candidate_offset(now.model, y0, ctx));
    if (enabled(EffectKind::drift)) tried(candidate_drift(now.model, y0, ctx));
    if (enabled(EffectKind::delay)) tried(candidate_delay(now.model, y0, ctx));
    if (enabled(EffectKind::coulomb)) tried(candidate_coulomb(now.model, y0, ctx));
    if (enabled(EffectKind::cubic)) tried(candidate_cubic(now.model, y0, ctx));
    if (enabled(EffectKind::complex_modes)) tried(candidate_complex_modes(now.model, ctx));
    if (enabled(EffectKind::feedthrough)) tried(candidate_feedthrough(now.model, y0, ctx));
    for (Candidate& c : candidates)
      if (c.valid) c.credit = base_rms - c.validation_rms;
    std::stable_sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
      if (a.valid != b.valid) return a.valid;
      return a.credit > b.credit;
    });
    now.ranking = candidates;
    // Why no candidate qualifies; with the mode left out by the cap, the cap is the rule that stopped it.
    std::string why;
    DiagnoseStop rule = DiagnoseStop::not_fitted;
    if (candidates.empty() || !candidates.front().valid) {
      why = "no candidate could be fitted";
      for (std::size_t i = 0; i < candidates.size(); ++i)
        why += std::string(i == 0 ? ": " : ", ") + effect_name(candidates[i].kind) + " (" + candidates[i].note + ")";
    } else if (const Candidate& best = candidates.front(); !(best.credit > options.min_improvement * base_rms)) {
      rule = DiagnoseStop::min_improvement;
      const double drop = best.credit / base_rms;
      const std::string against =
          "the refit without it (" + number(base_rms) + " -> " + number(best.validation_rms) + ")";
      why = std::string("best candidate (") + effect_name(best.kind) + ") " +
            (drop > 0.0 ? "lowers the validation RMS by " + percent(drop) + " beyond " + against + ", less than the "
                        : "does not lower the validation RMS beyond " + against + ", against the ") +
            percent(options.min_improvement) + " asked";
    } else if (!(best.bic < base_bic)) {
      rule = DiagnoseStop::bic;
      why =
          std::string("best candidate (") + effect_name(best.kind) + ") does not lower the BIC of the refit without it";
    }
    if (!why.empty()) {
      if (mode_capped && candidates.empty())
        stop(DiagnoseStop::mode_cap,
             std::to_string(options.max_modes_added) + " modes added, the most allowed, and no other effect to try");
      else if (mode_capped)
        stop(DiagnoseStop::mode_cap,
             std::to_string(options.max_modes_added) + " modes added, the most allowed; of the other effects, " + why);
      else
        stop(rule, why);
      break;
    }
    // The physical check can change a candidate's model (an unstable mode
    // projected) so that it no longer simulates: such a candidate is not added,
    // and the next one the rules admit is.
    std::optional<DiagnoseStep> next;
    std::string rejected;  // the admitted candidates that failed once made physical, and why
    for (Candidate& c : candidates) {
      if (!c.valid) continue;
      if (!(c.credit > options.min_improvement * base_rms)) break;
      if (!(c.bic < base_bic)) continue;
      findings.clear();
      const double cost = c.estimation_rms * c.estimation_rms * static_cast<double>(estimation.size());
      const Refined chosen = make_physical({c.model, cost, {}}, est, options, findings, modal_std);
      DiagnoseStep s = make_step(effect_name(c.kind), c.params, chosen.model, chosen.cost, est, val, options);
      // The step is the physical model, and it earns its credit as such: a
      // merge or a removal can undo what the candidate gained.
      std::string failed;
      if (!std::isfinite(s.estimation_rms) || !std::isfinite(s.validation_rms))
        failed = "diverges once made physical";
      else if (!(base_rms - s.validation_rms > options.min_improvement * base_rms))
        failed = "made physical, validation RMS " + number(s.validation_rms) + " against " + number(base_rms) +
                 " without it";
      if (!failed.empty()) {
        c.valid = false;
        c.credit = std::numeric_limits<double>::quiet_NaN();
        c.note = failed + " (" + (findings.empty() ? std::string("refitted") : findings.front().reason) + ")";
        rejected += std::string(rejected.empty() ? ": " : ", ") + effect_name(c.kind) + " (" + c.note + ")";
        continue;
      }
      s.physical = findings;
      s.modal_std = modal_std;
      s.refit_validation_rms = base_rms;
      s.credit = base_rms - s.validation_rms;
      next = std::move(s);
      break;
    }
    now.ranking = candidates;
    if (!next) {
      stop(DiagnoseStop::not_fitted,
           "no candidate the rules admit simulates and keeps its credit once made physical" + rejected);
      break;
    }
    result.steps.push_back(std::move(*next));
  }
  adopt_refit(result, est, val, options);
  return result;
}

}  // namespace modalwatch
