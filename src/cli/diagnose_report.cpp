// `modalwatch diagnose`'s report (diagnose_report.hpp): the files, the plot
// script run on them, and the steps on stdout.
#include "diagnose_report.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <complex>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <numbers>
#include <sstream>
#include <vector>

#include "json_writer.hpp"
#include "modalwatch/initial_modes.hpp"
#include "modalwatch/io/atomic_file.hpp"
#include "modalwatch/io/csv.hpp"
#include "plot_script.hpp"

namespace modalwatch::cli {

std::string format_number(double v, int precision) { return json_number(v, precision); }

namespace {

// ------------------------------------------------------------ summary.json

void write_test(JsonWriter& j, const ResidualTest& t) {
  j.begin_object();
  j.key("statistic").value(t.statistic, 6).key("threshold").value(t.threshold, 6).key("pass").value(t.pass);
  j.end_object();
}

// sd: standard deviations of (wn, zeta, gain), zeros when unknown.
// `input`: the name of the submodel's input, written only for a model of several inputs.
void write_submodel(JsonWriter& j, const Submodel& s, const ModalParameters& sd, const std::string& input) {
  j.begin_object().key("name").value(s.name);
  if (!input.empty()) j.key("input").value(input);
  // A velocity or acceleration sensor; wn, zeta and gain stay the position response's.
  if (s.output_derivatives != 0) j.key("output").value(output_kind_name(s.output_derivatives));
  if (s.is_resonance()) {
    const ModalParameters p = modal_parameters(s);
    j.key("kind").value("mode").key("wn").value(p.wn).key("zeta").value(p.zeta).key("gain").value(p.gain);
    j.key("wn_std").value(sd.wn).key("zeta_std").value(sd.zeta).key("gain_std").value(sd.gain);
    if (s.m == 1) j.key("b1").value(s.b(1));
  } else {
    j.key("kind").value("transfer_function").key("rigid_poles").value(s.rigid_poles);
    for (const auto& [name, c] : {std::pair{"a", &s.a}, std::pair{"b", &s.b}}) {
      j.key(name).begin_array();
      for (const double v : *c) j.value(v);
      j.end_array();
    }
  }
  j.end_object();
}

// The effects the model carries.
void write_effects(JsonWriter& j, const ModelEffects& e) {
  j.begin_object();
  if (e.output_offset_on) j.key("output_offset").value(e.output_offset);
  if (e.input_offset_on) j.key("input_offset").value(e.input_offset);
  if (e.drift_on) j.key("drift").value(e.drift);
  if (e.input_delay > 0) j.key("input_delay").value(e.input_delay);
  if (e.coulomb_on) j.key("coulomb").value(e.coulomb);
  if (e.cubic_on) j.key("cubic").value(e.cubic);
  j.end_object();
}

void write_params(JsonWriter& j, const EffectParams& params) {
  j.begin_object();
  for (const auto& [k, v] : params) j.key(k).value(v, 10);
  j.end_object();
}

// The refit alone of a step's model and the candidates tried from it, each with its credit over that refit.
void write_candidates(JsonWriter& j, const DiagnoseStep& s) {
  j.key("refit").begin_object();
  j.key("validation_rms").value(s.refit.validation_rms, 10).key("fit_percent").value(s.refit.fit_percent, 8);
  j.key("estimation_rms").value(s.refit.estimation_rms, 10).key("bic").value(s.refit.bic, 10);
  j.end_object();
  j.key("candidates").begin_array();
  for (const Candidate& c : s.ranking) {
    j.begin_object().key("effect").value(effect_name(c.kind));
    write_params(j.key("params"), c.params);
    j.key("validation_rms").value(c.validation_rms, 10).key("credit").value(c.credit, 10);
    j.key("estimation_rms").value(c.estimation_rms, 10).key("bic").value(c.bic, 10);
    j.key("valid").value(c.valid).key("note").value(c.note);
    j.end_object();
  }
  j.end_array();
}

void write_step(JsonWriter& j, const DiagnoseStep& s) {
  j.begin_object().key("effect").value(s.effect);
  write_params(j.key("params"), s.params);
  j.key("validation_rms").value(s.validation_rms, 10).key("fit_percent").value(s.fit_percent, 8);
  j.key("refit_validation_rms").value(s.refit_validation_rms, 10).key("credit").value(s.credit, 10);
  j.key("estimation_rms").value(s.estimation_rms, 10).key("bic").value(s.bic, 10);
  j.key("whiteness_pass").value(s.residual.whiteness.pass);
  write_test(j.key("whiteness"), s.residual.whiteness);
  write_test(j.key("independence"), s.residual.independence);
  write_test(j.key("coherence"), s.residual.coherence);
  j.key("submodels").begin_array();
  const auto& subs = s.model.linear.submodels;
  const AdditiveModel& linear = s.model.linear;
  for (std::size_t i = 0; i < subs.size(); ++i)
    write_submodel(j, subs[i], i < s.modal_std.size() ? s.modal_std[i] : ModalParameters{},
                   linear.n_inputs() > 1 ? linear.input_name(subs[i].input) : std::string());
  j.end_array();
  j.key("physical").begin_array();
  for (const ModeFinding& f : s.physical) {
    j.begin_object().key("submodel").value(f.submodel).key("verdict").value(verdict_name(f.verdict));
    j.key("into").value(f.into).key("reason").value(f.reason).end_object();
  }
  j.end_array();
  write_effects(j.key("effects"), s.model.effects);
  if (!s.ranking.empty() || s.refit.valid) write_candidates(j, s);
  j.end_object();
}

// ------------------------------------------------------------ report.md, model.yaml, tables

std::string params_text(const EffectParams& params) {
  std::string s;
  for (const auto& [k, v] : params) s += (s.empty() ? "" : ", ") + k + " = " + format_number(v, 5);
  return s.empty() ? "-" : s;
}

std::string test_line(const ResidualTest& t) {
  return std::string(t.pass ? "pass" : "FAIL") + " (" + format_number(t.statistic, 3) + " vs " +
         format_number(t.threshold, 3) + ")";
}

std::string effects_comment(const ModelEffects& e) {
  std::string s;
  if (e.output_offset_on) s += "#   output_offset: " + format_number(e.output_offset, 10) + "\n";
  if (e.input_offset_on) s += "#   input_offset: " + format_number(e.input_offset, 10) + "\n";
  if (e.drift_on) s += "#   drift: " + format_number(e.drift, 10) + "   # output units per s\n";
  if (e.input_delay > 0) s += "#   input_delay: " + std::to_string(e.input_delay) + "   # samples\n";
  if (e.coulomb_on) s += "#   coulomb: " + format_number(e.coulomb, 10) + "\n";
  if (e.cubic_on) s += "#   cubic: " + format_number(e.cubic, 10) + "\n";
  return s;
}

// Several inputs: a last column names each submodel's input.
std::string model_table(const AdditiveModel& m) {
  const bool inputs = m.n_inputs() > 1;
  std::string s =
      inputs ? "| submodel | kind | f [Hz] | wn [rad/s] | zeta | gain / coefficients | input |\n"
               "|---|---|---|---|---|---|---|\n"
             : "| submodel | kind | f [Hz] | wn [rad/s] | zeta | gain / coefficients |\n|---|---|---|---|---|---|\n";
  for (const Submodel& sm : m.submodels) {
    const std::string input = inputs ? " " + m.input_name(sm.input) + " |" : "";
    if (sm.is_resonance()) {
      const ModalParameters p = modal_parameters(sm);
      const std::string kind = sm.output_derivatives != 0 ? std::string(", ") + output_kind_name(sm.output_derivatives) : "";
      s += "| " + sm.name + (sm.m == 1 ? " | mode, b0 + b1 p" : " | mode") + kind + " | " + format_number(p.hz(), 6) + " | " +
           format_number(p.wn, 6) + " | " + format_number(p.zeta, 4) + " | " + format_number(p.gain, 5) +
           (sm.m == 1 ? ", b1 = " + format_number(sm.b(1), 5) : "") + " |" + input + "\n";
    } else {
      std::string c;
      const Eigen::VectorXd th = sm.theta();
      for (int j = 0; j < sm.n_theta(); ++j)
        c += (j ? ", " : "") + std::string(j < sm.n ? "a" : "b") + std::to_string(j < sm.n ? j + 1 : j - sm.n) + " = " +
             format_number(th(j), 6);
      s += "| " + sm.name + " | l = " + std::to_string(sm.rigid_poles) + ", n = " + std::to_string(sm.n) +
           (sm.output_derivatives != 0 ? ", z = " + std::to_string(sm.output_derivatives) : "") + " | | | | " +
           c + " |" + input + "\n";
    }
  }
  return s;
}

std::string report_md(const DiagnoseReport& in, const PlotOutcome& plots) {
  const DiagnoseResult& r = in.result;
  const DiagnoseArgs& args = in.args;
  const Config& config = in.config;
  const Eigen::Index n_est = in.estimation.size(), n_val = in.validation.size() - in.lead_in;
  std::ostringstream o;
  o << "# modalwatch diagnose\n\n";
  o << "Config `" << args.config << "` (" << (config.closed_loop ? "closed" : "open") << " loop), data `" << args.data
    << "`";
  if (!args.validate.empty()) o << ", validation `" << args.validate << "`";
  o << ". Input intersample: " << (args.input_hold == "foh" ? "band-limited (first-order hold)" : "held (ZOH)") << ", "
    << args.substeps << " integration substep(s) per sample";
  o << ". Estimation part: " << n_est << " samples; validation part: " << n_val << " samples.\n\n";
  if (in.time_in_samples)
    o << "Time: the record's `" << args.columns.t
      << "` is a sample index (no sample rate): times are in samples, frequencies in cycles/sample (the `f_hz` "
         "columns of the tables).\n\n";
  o << "Validation error: the model simulated on the validation part ("
    << (config.closed_loop ? "closed loop from r, with the measured excitation besides the controller"
                           : "open loop from the measured u")
    << "). fit % = 100 (1 - ||y - y_sim|| / ||y - mean(y)||). BIC = N ln(MSE) + k ln N on the estimation part. "
       "Credit of an effect: the validation RMS of the model without it, refitted alone from the same start with "
       "the same iterations (refit alone), minus the validation RMS with it; an effect is added on its credit, so "
       "what further refinement alone gives is not counted as the effect's.\n\n";
  o << "## Steps (before/after)\n\n";
  o << "| step | added effect | fitted parameters | est. RMS | refit alone val. RMS | val. RMS | credit | fit % | BIC "
       "| "
       "whiteness | independence | coherence |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (std::size_t i = 0; i < r.steps.size(); ++i) {
    const DiagnoseStep& s = r.steps[i];
    o << "| " << i << " | " << s.effect << " | " << params_text(s.params) << " | " << format_number(s.estimation_rms, 4)
      << " | " << (i == 0 ? "-" : format_number(s.refit_validation_rms, 4)) << " | "
      << format_number(s.validation_rms, 4) << " | " << (i == 0 ? "-" : format_number(s.credit, 4)) << " | "
      << format_number(s.fit_percent, 4) << " | " << format_number(s.bic, 6) << " | " << test_line(s.residual.whiteness)
      << " | " << test_line(s.residual.independence) << " | " << test_line(s.residual.coherence) << " |\n";
  }
  o << "\nStopped: " << r.stop_reason << ".\n\n";
  o << "Residual tests (validation part): whiteness = largest |autocorrelation| at lags 1..M against the 99 % band "
       "2.58/sqrt(N), pass when at most 5 % of the lags are outside; independence = the same for the "
       "cross-correlation with past input u(k - tau), tau = 0..M; coherence = largest residual-input squared "
       "coherence over the excited band against its 99 % level (Bonferroni over the frequencies).\n\n";
  for (std::size_t i = 0; i < r.steps.size(); ++i) {
    const DiagnoseStep& s = r.steps[i];
    if (s.ranking.empty()) continue;
    o << "### Candidates from step " << i << " (ranked by credit)\n\n";
    o << "Refit alone of step " << i << "'s model: est. RMS " << format_number(s.refit.estimation_rms, 4)
      << ", val. RMS " << format_number(s.refit.validation_rms, 4) << " (step " << i << ": "
      << format_number(s.validation_rms, 4) << "), fit " << format_number(s.refit.fit_percent, 4) << " %, BIC "
      << format_number(s.refit.bic, 6) << ".\n\n";
    o << "| rank | effect | parameters | est. RMS | val. RMS | credit | fit % | BIC | note "
         "|\n|---|---|---|---|---|---|---|---|---|\n";
    for (std::size_t j = 0; j < s.ranking.size(); ++j) {
      const Candidate& c = s.ranking[j];
      o << "| " << j + 1 << " | " << effect_name(c.kind) << " | " << params_text(c.params) << " | "
        << format_number(c.estimation_rms, 4) << " | " << format_number(c.validation_rms, 4) << " | "
        << format_number(c.credit, 4) << " | " << format_number(c.fit_percent, 4) << " | " << format_number(c.bic, 6)
        << " | " << c.note << " |\n";
    }
    o << "\n";
  }
  o << "## Models\n\nConfigured structure, fitted (step 0):\n\n" << model_table(r.steps.front().model.linear);
  o << "\nAugmented (last step):\n\n" << model_table(r.steps.back().model.linear);
  const std::string eff = effects_comment(r.steps.back().model.effects);
  if (!eff.empty())
    o << "\nEffects (fitted by diagnose only; the offsets add: the plant input is u + input_offset, the output "
         "G(p)(u + input_offset - ...) + output_offset):\n\n```\n"
      << eff << "```\n";
  o << "\n`model.yaml` holds the augmented model: its modes and rigid bodies are read by `fit`, `track` and the "
       "daemon; offset, drift, delay, Coulomb and cubic terms are written as comments, since only `diagnose` "
       "fits them.\n\n";
  o << "## Figures\n\n";
  if (plots.made) {
    o << "![Residual spectrum before and after](residual_spectrum.png)\n\n";
    o << "![Simulated against measured, validation part](validation.png)\n\n";
    o << "![Bode of both models and the measured frequency response](bode.png)\n";
  } else {
    o << "Not made";
    if (!plots.failure.empty()) o << " (" << plots.failure << ")";
    o << ": run `scripts/plot/plot_diagnose.py " << args.report << "` for residual_spectrum.png, validation.png and "
      << "bode.png from the CSV files here.\n";
  }
  return o.str();
}

double degrees(std::complex<double> h) { return std::arg(h) * 180.0 / std::numbers::pi; }

// The measured frequency response of the estimation part (H1 = S_yu / S_uu in
// open loop, S_yr / S_ur in closed loop, a held input's half-sample delay
// removed) and its coherence, beside both models' responses at the same
// frequencies; with several inputs, those from the first input (H_1 of S_yu S_uu^-1).
void write_measured_frf(const std::string& dir, const DiagnoseResult& r, const Record& estimation, bool closed_loop,
                        Hold input) {
  const FrequencyResponse h = frequency_response(estimation, closed_loop, 0, input);
  const Eigen::Index F = h.frequency_hz.size() - 1;  // without DC
  Eigen::MatrixXd t(F, 8);
  for (Eigen::Index k = 0; k < F; ++k) {
    const double f = h.frequency_hz(k + 1);
    const std::complex<double> m = h.response(k + 1);
    const auto g0 = r.steps.front().model.linear.response(2.0 * std::numbers::pi * f, 0);
    const auto g1 = r.steps.back().model.linear.response(2.0 * std::numbers::pi * f, 0);
    t.row(k) << f, std::abs(m), degrees(m), h.coherence(k + 1), std::abs(g0), degrees(g0), std::abs(g1), degrees(g1);
  }
  write_table(dir + "/frf.csv",
              {"f_hz", "mag_measured", "phase_measured_deg", "coherence", "mag_before", "phase_before_deg", "mag_after",
               "phase_after_deg"},
              t);
}

void write_tables(const std::string& dir, const DiagnoseResult& r, const Record& full_val, Eigen::Index lead_in) {
  const Record val = full_val.segment(lead_in, full_val.size() - lead_in);
  const DiagnoseStep& first = r.steps.front();
  const DiagnoseStep& last = r.steps.back();
  {
    const Spectra& a = first.residual.spectra;
    const Spectra& b = last.residual.spectra;
    const Eigen::Index F = std::min(a.frequency_hz.size(), b.frequency_hz.size());
    Eigen::MatrixXd t(F, 7);
    t << a.frequency_hz.head(F), a.residual_psd.head(F), b.residual_psd.head(F), a.residual_to_input.head(F),
        b.residual_to_input.head(F), a.coherence.head(F), b.coherence.head(F);
    write_table(
        dir + "/spectra.csv",
        {"f_hz", "psd_before", "psd_after", "e_to_u_before", "e_to_u_after", "coherence_before", "coherence_after"}, t);
  }
  {
    Eigen::MatrixXd t(val.size(), 4);
    // A step whose model diverged on validation has no simulated output: NaN.
    const auto simulated = [&](const DiagnoseStep& s) -> Eigen::VectorXd {
      if (s.validation_output.size() < val.size())
        return Eigen::VectorXd::Constant(val.size(), std::numeric_limits<double>::quiet_NaN());
      return s.validation_output.tail(val.size());
    };
    t << val.t, val.y, simulated(first), simulated(last);
    write_table(dir + "/validation.csv", {"t", "y", "y_before", "y_after"}, t);
  }
  {
    const double fs = 1.0 / val.sample_time();
    const int F = 400;
    Eigen::MatrixXd t(F, 5);
    const double f0 = fs / 2.0 * 1e-3, f1 = fs / 2.0;
    for (int i = 0; i < F; ++i) {
      const double f = f0 * std::pow(f1 / f0, double(i) / (F - 1));
      const double w = 2.0 * std::numbers::pi * f;
      const auto g0 = first.model.linear.response(w, 0), g1 = last.model.linear.response(w, 0);  // the first input's
      t.row(i) << f, std::abs(g0), degrees(g0), std::abs(g1), degrees(g1);
    }
    write_table(dir + "/bode.csv", {"f_hz", "mag_before", "phase_before_deg", "mag_after", "phase_after_deg"}, t);
  }
  {
    // A step whose model diverged on validation has no residual: NaN.
    const auto at = [](const Eigen::VectorXd& v, Eigen::Index k) {
      return k < v.size() ? v(k) : std::numeric_limits<double>::quiet_NaN();
    };
    const Eigen::Index M = std::max(first.residual.autocorrelation.size(), last.residual.autocorrelation.size());
    Eigen::MatrixXd t(M, 5);
    for (Eigen::Index k = 0; k < M; ++k)
      t.row(k) << double(k), at(first.residual.autocorrelation, k), at(last.residual.autocorrelation, k),
          at(first.residual.cross_correlation, k), at(last.residual.cross_correlation, k);
    write_table(dir + "/correlations.csv", {"lag", "acf_before", "acf_after", "ccf_before", "ccf_after"}, t);
  }
}

void print_steps(const DiagnoseResult& r, const std::string& dir) {
  std::printf("%-4s %-11s %-44s %12s %12s %12s %12s %8s %10s\n", "step", "effect", "parameters", "est. RMS",
              "refit RMS", "val. RMS", "credit", "fit %", "whiteness");
  const auto text = [](double v) { return std::isfinite(v) ? format_number(v, 5) : std::string("-"); };
  for (std::size_t i = 0; i < r.steps.size(); ++i) {
    const DiagnoseStep& s = r.steps[i];
    std::printf("%-4zu %-11s %-44s %12.5g %12s %12.5g %12s %8.3f %10s\n", i, s.effect.c_str(),
                params_text(s.params).c_str(), s.estimation_rms, text(s.refit_validation_rms).c_str(), s.validation_rms,
                text(s.credit).c_str(), s.fit_percent, s.residual.whiteness.pass ? "pass" : "fail");
  }
  std::printf("stopped: %s\nreport: %s/report.md\n", r.stop_reason.c_str(), dir.c_str());
}

}  // namespace

std::string diagnose_summary_json(const DiagnoseResult& result, bool time_in_samples) {
  JsonWriter j;
  j.begin_object().key("steps").begin_array(JsonWriter::Layout::lines);
  for (const DiagnoseStep& s : result.steps) write_step(j, s);
  j.end_array();
  j.key("stop").value(stop_name(result.stop));
  j.key("stop_reason").value(result.stop_reason);
  j.key("time_unit").value(time_in_samples ? "samples" : "s");
  return j.end_object().finish();
}

void write_diagnose_report(const DiagnoseReport& in) {
  const DiagnoseArgs& args = in.args;
  const DiagnoseResult& r = in.result;
  std::filesystem::create_directories(args.report);
  write_file_atomically(args.report + "/summary.json", diagnose_summary_json(r, in.time_in_samples));
  write_tables(args.report, r, in.validation, in.lead_in);
  write_measured_frf(args.report, r, in.estimation, in.config.closed_loop,
                     args.input_hold == "foh" ? Hold::foh : Hold::zoh);
  std::string yaml = config_to_yaml(in.config, r.steps.back().model.linear);
  const std::string eff = effects_comment(r.steps.back().model.effects);
  if (!eff.empty())
    yaml += "\n# Effects fitted by `modalwatch diagnose` that fit, track and the daemon do not carry:\n" + eff;
  write_file_atomically(args.report + "/model.yaml", yaml);
  PlotOutcome plots;
  if (!args.plot_script.empty()) {
    plots = run_plot_script(args.plot_script, args.report);
    if (!plots.made) std::fprintf(stderr, "modalwatch diagnose: plots failed (%s)\n", plots.failure.c_str());
  }
  write_file_atomically(args.report + "/report.md", report_md(in, plots));
  print_steps(r, args.report);
}

}  // namespace modalwatch::cli
