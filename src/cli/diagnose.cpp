// `modalwatch diagnose`: the residual analysis and model augmentation of
// include/modalwatch/diagnose.hpp on a record, and its report: DIR/report.md,
// DIR/summary.json, DIR/model.yaml (the augmented model) and the CSV tables
// that scripts/plot/plot_diagnose.py turns into the PNGs the report links.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>

#include "commands.hpp"
#include "modalwatch/io/records.hpp"
#include "guarded.hpp"

#include "modalwatch/io/config.hpp"
#include "modalwatch/io/csv.hpp"
#include "modalwatch/diagnose.hpp"
#include "modalwatch/error.hpp"
#include "modalwatch/io/atomic_file.hpp"

namespace modalwatch::cli {
namespace {

std::string num(double v, int precision = 6) {
  if (!std::isfinite(v)) return "null";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*g", precision, v);
  return buf;
}

// "A:B" -> samples [A, B) of the record.
Record samples(const Record& r, const std::string& range, const std::string& flag, const std::string& file) {
  if (range.empty()) return r;
  const auto colon = range.find(':');
  long long a = 0, b = 0;
  try {
    if (colon == std::string::npos) throw std::invalid_argument("no colon");
    std::size_t used = 0;
    a = std::stoll(range.substr(0, colon), &used);
    if (used != colon) throw std::invalid_argument("trailing text");
    const std::string rest = range.substr(colon + 1);
    b = std::stoll(rest, &used);
    if (used != rest.size()) throw std::invalid_argument("trailing text");
  } catch (const std::exception&) {
    throw InputError(flag, "expected FIRST:END sample indices (0-based, END excluded), got '" + range + "'");
  }
  if (a < 0 || b <= a || b > r.size())
    throw InputError(flag, "samples " + range + " outside the " + std::to_string(r.size()) + " rows of " + file);
  return r.segment(a, b - a);
}

std::vector<EffectKind> parse_effects(const std::string& list) {
  if (list.empty()) return all_effects();
  std::vector<EffectKind> out;
  std::stringstream ss(list);
  std::string item;
  while (std::getline(ss, item, ',')) {
    bool found = false;
    for (EffectKind k : all_effects())
      if (item == effect_name(k)) {
        out.push_back(k);
        found = true;
      }
    if (!found)
      throw InputError("--effects", "unknown effect '" + item +
                                        "' (allowed: mode, rigid_body, offset, drift, delay, coulomb, cubic)");
  }
  return out;
}

std::string params_text(const EffectParams& params) {
  std::string s;
  for (const auto& [k, v] : params) s += (s.empty() ? "" : ", ") + k + " = " + num(v, 5);
  return s.empty() ? "-" : s;
}

std::string params_json(const EffectParams& params) {
  std::string s = "{";
  for (std::size_t i = 0; i < params.size(); ++i)
    s += (i ? ", " : "") + std::string("\"") + params[i].first + "\": " + num(params[i].second, 10);
  return s + "}";
}

std::string test_json(const ResidualTest& t) {
  return "{\"statistic\": " + num(t.statistic) + ", \"threshold\": " + num(t.threshold) +
         ", \"pass\": " + (t.pass ? "true" : "false") + "}";
}

std::string summary_json(const DiagnoseResult& r) {
  std::string s = "{\"steps\": [\n";
  for (std::size_t i = 0; i < r.steps.size(); ++i) {
    const DiagnoseStep& st = r.steps[i];
    s += "  {\"effect\": \"" + st.effect + "\", \"params\": " + params_json(st.params) +
         ", \"validation_rms\": " + num(st.validation_rms, 10) + ", \"fit_percent\": " + num(st.fit_percent, 8) +
         ", \"estimation_rms\": " + num(st.estimation_rms, 10) + ", \"bic\": " + num(st.bic, 10) +
         ", \"whiteness_pass\": " + (st.residual.whiteness.pass ? "true" : "false") +
         ", \"whiteness\": " + test_json(st.residual.whiteness) +
         ", \"independence\": " + test_json(st.residual.independence) +
         ", \"coherence\": " + test_json(st.residual.coherence) + "}" + (i + 1 < r.steps.size() ? ",\n" : "\n");
  }
  s += "], \"stop_reason\": \"" + r.stop_reason + "\"}\n";
  return s;
}

std::string test_line(const ResidualTest& t) {
  return std::string(t.pass ? "pass" : "FAIL") + " (" + num(t.statistic, 3) + " vs " + num(t.threshold, 3) + ")";
}

std::string effects_comment(const ModelEffects& e) {
  std::string s;
  if (e.output_offset_on) s += "#   output_offset: " + num(e.output_offset, 10) + "\n";
  if (e.input_offset_on) s += "#   input_offset: " + num(e.input_offset, 10) + "\n";
  if (e.drift_on) s += "#   drift: " + num(e.drift, 10) + "   # output units per s\n";
  if (e.delay > 0) s += "#   input_delay: " + std::to_string(e.delay) + "   # samples\n";
  if (e.coulomb_on) s += "#   coulomb: " + num(e.coulomb, 10) + "\n";
  if (e.cubic_on) s += "#   cubic: " + num(e.cubic, 10) + "\n";
  return s;
}

std::string model_table(const AdditiveModel& m) {
  std::string s = "| submodel | kind | f [Hz] | wn [rad/s] | zeta | gain / coefficients |\n|---|---|---|---|---|---|\n";
  for (const Submodel& sm : m.submodels) {
    if (sm.is_mode()) {
      const ModalParameters p = modal_parameters(sm);
      s += "| " + sm.name + " | mode | " + num(p.hz(), 6) + " | " + num(p.wn, 6) + " | " + num(p.zeta, 4) + " | " +
           num(p.gain, 5) + " |\n";
    } else {
      std::string c;
      const Eigen::VectorXd th = sm.theta();
      for (int j = 0; j < sm.n_theta(); ++j)
        c += (j ? ", " : "") + std::string(j < sm.n ? "a" : "b") + std::to_string(j < sm.n ? j + 1 : j - sm.n) +
             " = " + num(th(j), 6);
      s += "| " + sm.name + " | l = " + std::to_string(sm.rigid_poles) + ", n = " + std::to_string(sm.n) +
           " | | | | " + c + " |\n";
    }
  }
  return s;
}

std::string report_md(const DiagnoseResult& r, const DiagnoseArgs& args, const Config& config, Eigen::Index n_est,
                      Eigen::Index n_val, bool plots) {
  std::ostringstream o;
  o << "# modalwatch diagnose\n\n";
  o << "Config `" << args.config << "` (" << (config.closed_loop ? "closed" : "open") << " loop), data `"
    << args.data << "`";
  if (!args.validate.empty()) o << ", validation `" << args.validate << "`";
  o << ". Input intersample: " << (args.input_hold == "foh" ? "band-limited (first-order hold)" : "held (ZOH)")
    << ", " << args.substeps << " integration substep(s) per sample";
  o << ". Estimation part: " << n_est << " samples; validation part: " << n_val << " samples.\n\n";
  o << "Validation error: the model simulated on the validation part ("
    << (config.closed_loop ? "closed loop from r, with the measured excitation besides the controller"
                           : "open loop from the measured u")
    << "). fit % = 100 (1 - ||y - y_sim|| / ||y - mean(y)||). BIC = N ln(MSE) + k ln N on the estimation part.\n\n";
  o << "## Steps (before/after)\n\n";
  o << "| step | added effect | fitted parameters | est. RMS | val. RMS | fit % | BIC | whiteness | independence | "
       "coherence |\n|---|---|---|---|---|---|---|---|---|---|\n";
  for (std::size_t i = 0; i < r.steps.size(); ++i) {
    const DiagnoseStep& s = r.steps[i];
    o << "| " << i << " | " << s.effect << " | " << params_text(s.params) << " | " << num(s.estimation_rms, 4)
      << " | " << num(s.validation_rms, 4) << " | " << num(s.fit_percent, 4) << " | " << num(s.bic, 6) << " | "
      << test_line(s.residual.whiteness) << " | " << test_line(s.residual.independence) << " | "
      << test_line(s.residual.coherence) << " |\n";
  }
  o << "\nStopped: " << r.stop_reason << ".\n\n";
  o << "Residual tests (validation part): whiteness = largest |autocorrelation| at lags 1..M against the 99 % band "
       "2.58/sqrt(N), pass when at most 5 % of the lags are outside; independence = the same for the "
       "cross-correlation with past input u(k - tau), tau = 0..M; coherence = largest residual-input squared "
       "coherence over the excited band against its 99 % level (Bonferroni over the frequencies).\n\n";
  for (std::size_t i = 0; i < r.steps.size(); ++i) {
    const DiagnoseStep& s = r.steps[i];
    if (s.ranking.empty()) continue;
    o << "### Candidates from step " << i << " (ranked by validation RMS)\n\n";
    o << "| rank | effect | parameters | est. RMS | val. RMS | fit % | BIC | note |\n|---|---|---|---|---|---|---|---|\n";
    for (std::size_t j = 0; j < s.ranking.size(); ++j) {
      const Candidate& c = s.ranking[j];
      o << "| " << j + 1 << " | " << effect_name(c.kind) << " | " << params_text(c.params) << " | "
        << num(c.estimation_rms, 4) << " | " << num(c.validation_rms, 4) << " | " << num(c.fit_percent, 4) << " | "
        << num(c.bic, 6) << " | " << c.note << " |\n";
    }
    o << "\n";
  }
  o << "## Models\n\nConfigured structure, fitted (step 0):\n\n" << model_table(r.steps.front().model.linear);
  o << "\nAugmented (last step):\n\n" << model_table(r.steps.back().model.linear);
  const std::string eff = effects_comment(r.steps.back().model.effects);
  if (!eff.empty()) o << "\nEffects (fitted by diagnose only):\n\n```\n" << eff << "```\n";
  o << "\n`model.yaml` holds the augmented model: its modes and rigid bodies are read by `fit`, `track` and the "
       "daemon; offset, drift, delay, Coulomb and cubic terms are written as comments, since only `diagnose` "
       "fits them.\n\n";
  o << "## Figures\n\n";
  if (plots) {
    o << "![Residual spectrum before and after](residual_spectrum.png)\n\n";
    o << "![Simulated against measured, validation part](validation.png)\n\n";
    o << "![Bode of both models](bode.png)\n";
  } else {
    o << "Not made (run `scripts/plot/plot_diagnose.py " << args.report << "`): residual_spectrum.png, validation.png, "
      << "bode.png from the CSV files here.\n";
  }
  return o.str();
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
    write_table(dir + "/spectra.csv",
                {"f_hz", "psd_before", "psd_after", "e_to_u_before", "e_to_u_after", "coherence_before",
                 "coherence_after"},
                t);
  }
  {
    Eigen::MatrixXd t(val.size(), 4);
    t << val.t, val.y, first.validation_output.tail(val.size()), last.validation_output.tail(val.size());
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
      const auto g0 = first.model.linear.response(w), g1 = last.model.linear.response(w);
      t.row(i) << f, std::abs(g0), std::arg(g0) * 180.0 / std::numbers::pi, std::abs(g1),
          std::arg(g1) * 180.0 / std::numbers::pi;
    }
    write_table(dir + "/bode.csv", {"f_hz", "mag_before", "phase_before_deg", "mag_after", "phase_after_deg"}, t);
  }
  {
    const Eigen::Index M = first.residual.autocorrelation.size();
    Eigen::MatrixXd t(M, 5);
    for (Eigen::Index k = 0; k < M; ++k)
      t.row(k) << double(k), first.residual.autocorrelation(k), last.residual.autocorrelation(k),
          first.residual.cross_correlation(k), last.residual.cross_correlation(k);
    write_table(dir + "/correlations.csv", {"lag", "acf_before", "acf_after", "ccf_before", "ccf_after"}, t);
  }
}

}  // namespace

int diagnose(const DiagnoseArgs& args) {
  return guarded("diagnose", [&] {
    const Config config = load_config(args.config);
    if (!args.validate.empty() && args.split) throw InputError("--split", "give --validate or --split, not both");
    RecordColumns columns;
    columns.t = args.t_column;
    columns.y = args.y_column;
    const Record full = read_record(RecordSource(args.data, columns, args.channel, config.closed_loop));
    Record est, val;
    Eigen::Index lead_in = 0;
    if (!args.validate.empty()) {
      est = samples(full, args.estimate_samples, "--estimate-samples", args.data);
      val = samples(read_record(RecordSource(args.validate, columns, args.channel, config.closed_loop)), args.validate_samples,
                    "--validate-samples", args.validate);
    } else if (!args.estimate_samples.empty() || !args.validate_samples.empty()) {
      if (args.estimate_samples.empty() || args.validate_samples.empty())
        throw InputError("--estimate-samples", "give both --estimate-samples and --validate-samples");
      est = samples(full, args.estimate_samples, "--estimate-samples", args.data);
      val = samples(full, args.validate_samples, "--validate-samples", args.data);
    } else {
      const double f = args.split.value_or(0.7);
      if (!(f > 0.0 && f < 1.0)) throw InputError("--split", "must be in (0, 1)");
      const auto n = static_cast<Eigen::Index>(std::floor(f * static_cast<double>(full.size())));
      est = full.segment(0, n);
      // The validation run starts at the record's start so the model's state
      // is right at the split; only the samples after it are scored.
      val = full;
      lead_in = n;
    }
    check_record(est, args.data, config.sample_time, config.closed_loop, config.source);
    check_record(val, args.validate.empty() ? args.data : args.validate, config.sample_time, config.closed_loop,
                 config.source);
    if (args.input_hold == "foh") {
      if (config.closed_loop) throw InputError("--input-hold", "foh is for open-loop records (u is simulated in closed loop)");
    }
    DiagnoseOptions options;
    options.max_steps = args.max_steps;
    options.validation_lead_in = lead_in;
    options.min_improvement = args.min_improvement;
    options.max_delay = args.max_delay;
    options.output_hold = config.output_hold;
    options.library = parse_effects(args.effects);
    LoopSpec loop;
    loop.closed = config.closed_loop;
    loop.controller = config.controller;
    loop.interpolate_input = args.input_hold == "foh";
    loop.substeps = args.substeps;

    const DiagnoseResult r = diagnose(est, val, config.model, loop, options);

    std::filesystem::create_directories(args.report);
    write_file_atomically(args.report + "/summary.json", summary_json(r));
    write_tables(args.report, r, val, lead_in);
    std::string yaml = config_to_yaml(config, r.steps.back().model.linear);
    const std::string eff = effects_comment(r.steps.back().model.effects);
    if (!eff.empty())
      yaml += "\n# Effects fitted by `modalwatch diagnose` that fit, track and the daemon do not carry:\n" + eff;
    write_file_atomically(args.report + "/model.yaml", yaml);
    bool plots = false;
    if (!args.plot_script.empty()) {
      const std::string cmd = "/usr/bin/python3 '" + args.plot_script + "' '" + args.report + "'";
      plots = std::system(cmd.c_str()) == 0;
      if (!plots) std::fprintf(stderr, "modalwatch diagnose: plots failed (%s)\n", cmd.c_str());
    }
    write_file_atomically(args.report + "/report.md", report_md(r, args, config, est.size(), val.size() - options.validation_lead_in, plots));

    std::printf("%-4s %-11s %-44s %12s %12s %8s %10s\n", "step", "effect", "parameters", "est. RMS", "val. RMS",
                "fit %", "whiteness");
    for (std::size_t i = 0; i < r.steps.size(); ++i) {
      const DiagnoseStep& s = r.steps[i];
      std::printf("%-4zu %-11s %-44s %12.5g %12.5g %8.3f %10s\n", i, s.effect.c_str(), params_text(s.params).c_str(),
                  s.estimation_rms, s.validation_rms, s.fit_percent, s.residual.whiteness.pass ? "pass" : "fail");
    }
    std::printf("stopped: %s\nreport: %s/report.md\n", r.stop_reason.c_str(), args.report.c_str());
    return 0;
  });
}

}  // namespace modalwatch::cli
