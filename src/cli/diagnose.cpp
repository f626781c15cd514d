// `modalwatch diagnose`: the residual analysis and model augmentation of
// include/modalwatch/diagnose.hpp on a record; its report is diagnose_report.hpp's.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "commands.hpp"
#include "diagnose_report.hpp"
#include "guarded.hpp"
#include "modalwatch/io/records.hpp"
#include "table.hpp"

#include "modalwatch/diagnose.hpp"
#include "modalwatch/error.hpp"
#include "modalwatch/io/config.hpp"

namespace modalwatch::cli {
namespace {

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
    if (!found) {
      std::string allowed;
      for (EffectKind k : all_effects()) allowed += std::string(allowed.empty() ? "" : ", ") + effect_name(k);
      throw InputError("--effects", "unknown effect '" + item + "' (allowed: " + allowed + ")");
    }
  }
  return out;
}

// The option that sets the rule which stopped the augmentation.
const char* stop_option(DiagnoseStop stop) {
  switch (stop) {
    case DiagnoseStop::max_steps:
      return " (--max-steps)";
    case DiagnoseStop::min_improvement:
      return " (--min-improvement)";
    case DiagnoseStop::mode_cap:
      return " (--max-added-modes)";
    default:
      return "";
  }
}

}  // namespace

int diagnose(const DiagnoseArgs& args) {
  return guarded("diagnose", [&] {
    const Config config = load_config(args.config);
    if (!args.validate.empty() && args.split) throw InputError("--split", "give --validate or --split, not both");
    const std::vector<std::string> inputs = input_columns(args.columns, config.model, config.closed_loop);
    const RecordColumns columns = record_columns(args.columns, inputs);
    const Record full = read_record_with_columns(RecordSource(args.data, columns, args.channel, config.closed_loop));
    Record est, val;
    Eigen::Index lead_in = 0;
    if (!args.validate.empty()) {
      est = samples(full, args.estimate_samples, "--estimate-samples", args.data);
      val = samples(read_record_with_columns(RecordSource(args.validate, columns, args.channel, config.closed_loop)),
                    args.validate_samples, "--validate-samples", args.validate);
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
      if (config.closed_loop)
        throw InputError("--input-hold", "foh is for open-loop records (u is simulated in closed loop)");
    }
    DiagnoseOptions options;
    options.max_steps = args.max_steps;
    options.max_modes_added = args.max_modes_added;
    options.validation_lead_in = lead_in;
    options.min_improvement = args.min_improvement;
    options.max_delay = args.max_delay;
    options.library = parse_effects(args.effects);
    // A long run is not silent: a line on stderr per fit.
    const auto start = std::chrono::steady_clock::now();
    options.progress = [&](const DiagnoseProgress& p) {
      const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (p.step == 0)
        std::fprintf(stderr, "modalwatch diagnose: step 0: configured model: validation RMS %.4g (%.1f s)\n",
                     p.validation_rms, elapsed);
      else if (p.effect == "refit")
        std::fprintf(stderr, "modalwatch diagnose: step %d/%d: refit alone: validation RMS %.4g (%.1f s)\n", p.step,
                     args.max_steps, p.validation_rms, elapsed);
      else if (p.valid)
        std::fprintf(stderr, "modalwatch diagnose: step %d/%d: tried %s: validation RMS %.4g (%.1f s)\n", p.step,
                     args.max_steps, p.effect.c_str(), p.validation_rms, elapsed);
      else
        std::fprintf(stderr, "modalwatch diagnose: step %d/%d: tried %s: not fitted (%s) (%.1f s)\n", p.step,
                     args.max_steps, p.effect.c_str(), p.note.c_str(), elapsed);
    };
    LoopSpec loop;
    loop.closed = config.closed_loop;
    loop.controller = config.controller;
    loop.interpolate_input = args.input_hold == "foh";
    loop.substeps = args.substeps;

    // Modes from the data: --modes, or model.modes without submodels.
    const std::optional<int> modes = args.modes ? args.modes : config.model_modes;
    const bool in_samples = time_in_samples(full, args.columns, config.sample_time);
    const int output = output_kind(config, args.output, modes.has_value());
    const AdditiveModel initial =
        modes ? modes_from_data(est, *modes, loop.srivc_options(), args.data, in_samples,
                                config.model.inputs.empty() ? inputs : config.model.inputs, output)
              : config.model;
    options.output_hold = output_hold(config, initial, est.sample_time());
    DiagnoseResult r = diagnose(est, val, initial, loop, options);
    r.stop_reason += stop_option(r.stop);

    write_diagnose_report({args, config, r, val, lead_in, est, in_samples});
    for (const auto& step : r.steps) print_physical_findings(step.physical);
    return 0;
  });
}

}  // namespace modalwatch::cli
