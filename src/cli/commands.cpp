#include "commands.hpp"
#include "guarded.hpp"
#include "modalwatch/io/records.hpp"
#include "stabilisation.hpp"
#include "table.hpp"

#include <cmath>
#include <cstdio>
#include <exception>
#include <fstream>
#include <numbers>
#include <stdexcept>

#include "modalwatch/error.hpp"
#include "modalwatch/initial_modes.hpp"
#include "modalwatch/io/atomic_file.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/io/csv.hpp"
#include "modalwatch/physical.hpp"
#include "modalwatch/simulator.hpp"
#include "modalwatch/srivc.hpp"

namespace modalwatch::cli {
namespace {

// --from/--to. The samples before --from stay in the record: they bring the
// model's simulation and the prefilters up to the running plant (a model output
// started from rest at --from would not match y for a few time constants).
struct Window {
  Record data;              // the record's start up to --to
  Eigen::Index settle = 0;  // samples before --from: filters only, not in the estimate
};
Window window(const Record& r, const FitArgs& args) {
  Eigen::Index begin = 0, end = r.size();
  if (args.from)
    while (begin < end && r.t(begin) < *args.from) ++begin;
  if (args.to)
    while (end > begin && r.t(end - 1) > *args.to) --end;
  return {r.segment(0, end), begin};
}

}  // namespace

int simulate(const SimulateArgs& args) {
  return guarded("simulate", [&] {
    const Config config = load_config(args.config);
    if (!config.plant || !config.experiment)
      throw InputError(args.config, "simulate needs the 'plant' and 'simulation' sections");
    ExperimentSpec experiment = *config.experiment;
    if (args.duration) {
      if (!(*args.duration > 0.0)) throw InputError("--duration", "must be > 0");
      experiment.duration = *args.duration;
    }
    if (args.seed) experiment.seed = *args.seed;
    const SimulationResult sim = simulate(*config.plant, experiment);
    write_record(args.out, sim.record, config.model.inputs);
    if (!args.truth.empty()) {
      std::vector<std::string> columns{"t"};
      columns.insert(columns.end(), sim.truth_columns.begin(), sim.truth_columns.end());
      Eigen::MatrixXd table(sim.truth.rows(), sim.truth.cols() + 1);
      table << sim.record.t, sim.truth;
      write_table(args.truth, columns, table);
    }
    std::fprintf(stderr, "modalwatch simulate: %lld samples at %g Hz (%s loop), noise variance %.4g -> %s\n",
                 static_cast<long long>(sim.record.size()), 1.0 / experiment.sample_time,
                 experiment.closed_loop ? "closed" : "open", sim.noise_variance, args.out.c_str());
    return 0;
  });
}

namespace {

// The instruments' condition, and a warning naming the parameters of the
// weakest direction when the record leaves some combination undetermined (the
// +- above then understate it).
void print_identifiability(const FitResult& result) {
  if (result.unstable_loop) {
    std::printf(
        "WARNING: the fitted model, in the loop with the controller, diverges on the record (positive feedback?):\n"
        "its instruments overflow, so the +- above and the information condition are not defined\n");
    return;
  }
  std::printf("information condition: %.3g\n", result.information_condition);
  if (!(result.information_condition > FitResult::kPoorlyDetermined)) return;
  std::printf(
      "WARNING: the record does not determine every parameter (condition above %.0e): the input\n"
      "excites too few frequencies for this model (n sinusoids give 2n equations), or the model has\n"
      "more modes than the data show. The +- above understate the combination it leaves open,\n"
      "theta = [a_1..a_n, b_0..b_m] (components above 0.1):\n",
      FitResult::kPoorlyDetermined);
  const Eigen::VectorXd& v = result.weakest_direction;
  for (int i = 0, o = 0; i < static_cast<int>(result.model.submodels.size()); ++i) {
    const Submodel& s = result.model.submodels[i];
    for (int j = 0; j < s.n_theta(); ++j, ++o) {
      if (std::abs(v(o)) < 0.1) continue;
      const bool a = j < s.n;
      std::printf("  %-12s %s_%d %+.2f\n", s.name.c_str(), a ? "a" : "b", a ? j + 1 : j - s.n, v(o));
    }
  }
}

// A commissioning fit as the fault detector's baselines: every resonance's
// (wn, zeta, DC gain), a mode's or a complex-residue one's, with its standard
// deviations from the fit's covariance, which the detector takes as the
// baseline's covariance C0. Other submodels keep what the config gave them (a
// rigid body has no baseline).
void set_baselines(Config& config, const AdditiveModel& fitted, const std::vector<Eigen::MatrixXd>& covariances) {
  const std::size_t K = fitted.submodels.size();
  config.faults.baselines.resize(K);
  config.faults.baseline_std.resize(K);
  for (std::size_t i = 0; i < K; ++i) {
    const Submodel& s = fitted.submodels[i];
    if (!s.is_resonance()) continue;
    config.faults.baselines[i] = modal_parameters(s);
    config.faults.baseline_std[i] = modal_std(s, covariances[i]);
  }
}

}  // namespace

int fit(const FitArgs& args) {
  return guarded("fit", [&] {
    const Config config = load_config(args.config);
    const std::vector<std::string> inputs = input_columns(args.columns, config.model, config.closed_loop);
    const Record full = read_record_with_columns(
        RecordSource(args.data, record_columns(args.columns, inputs), args.channel, config.closed_loop));
    const auto [data, settle] = window(full, args);
    const Eigen::Index used = data.size() - settle;
    // Modes from the data: --modes, or model.modes without submodels.
    const std::optional<int> modes = args.modes ? args.modes : config.model_modes;
    const int output = output_kind(config, args.output, args.max_modes || modes);
    const int nb = args.max_modes ? 3 : modes ? 3 * *modes : config.model.n_beta();
    if (used < 2 * nb + 2)
      throw InputError(args.data, std::to_string(used) + " samples (rows) for " + std::to_string(nb) +
                                      " parameters: need at least " + std::to_string(2 * nb + 2));
    check_record(data, args.data, config.sample_time, config.closed_loop, config.source);
    const double T = data.sample_time();
    SrivcOptions options;
    options.closed_loop = config.closed_loop;
    options.best_cycle = true;
    if (args.input_hold == "foh") {
      if (config.closed_loop)
        throw InputError("--input-hold",
                         "foh is for open-loop records (u is the controller's held output in closed loop)");
      options.input_hold = Hold::foh;
    }
    options.controller = config.controller;
    options.max_iterations = args.max_iterations;
    options.settle_samples = settle;
    const bool in_samples = time_in_samples(full, args.columns, config.sample_time);
    std::vector<ModeFinding> findings;
    FitResult result;
    if (args.max_modes) {
      OrderOptions order;
      order.max_modes = *args.max_modes;
      order.output_derivatives = output;
      if (data.inputs() > 1) order.inputs = config.model.inputs.empty() ? inputs : config.model.inputs;
      // One hold for every order: the one of the largest start.
      options.output_hold = output_hold(
          config, initial_modes(data.segment(settle, used), order.max_modes, config.closed_loop, order.peaks, output),
          T);
      OrderSelection selection = select_order(data, options, order);
      print_order_selection(selection, in_samples);
      if (!args.stabilisation.empty())
        write_stabilisation(args.stabilisation, selection, data.segment(settle, used), config.closed_loop, in_samples,
                            args.plot_script);
      if (selection.chosen < 0)
        throw InputError(args.data, "no fit of 1 to " + std::to_string(*args.max_modes) +
                                        " modes from the resonance peaks of the data");
      OrderFit& chosen = selection.orders[static_cast<std::size_t>(selection.chosen)];
      result = std::move(chosen.fit);
      findings = std::move(chosen.findings);
      std::printf("\n");
    } else {
      AdditiveModel start = modes ? modes_from_data(data.segment(settle, used), *modes, options, args.data, in_samples,
                                                    config.model.inputs.empty() ? inputs : config.model.inputs, output)
                                  : config.model;
      options.output_hold = output_hold(config, start, T);
      result = fit_physical(data, start, options, findings);
      if (modes == 1 && non_resonant_instead(data, result, options, in_samples, output, start)) {
        findings.clear();
        options.output_hold = output_hold(config, start, T);
        result = fit_physical(data, start, options, findings);
      }
    }

    char rate[48] = "";
    if (!in_samples) std::snprintf(rate, sizeof rate, " at %g Hz", 1.0 / T);
    // Free parameters: a resonance's A shared by several inputs counts once.
    std::printf("modalwatch fit: %lld samples%s, %s loop, %zu submodels, %lld parameters\n",
                static_cast<long long>(used), rate, config.closed_loop ? "closed" : "open",
                result.model.submodels.size(), static_cast<long long>(free_beta(result.model).size()));
    if (settle > 0)
      std::printf("(the %lld samples before --from run the filters and the model only)\n",
                  static_cast<long long>(settle));
    std::printf("%s after %d block-coordinate cycles (last change %.2e), %d stability projections\n",
                result.converged ? "converged" : "NOT converged", result.iterations,
                result.change_history.empty() ? 0.0 : result.change_history.back(), result.projections);
    if (result.best_iteration > 0)
      std::printf("returned cycle %d, the one of least output error (the cycles after it raised it)\n",
                  result.best_iteration);
    std::vector<Eigen::MatrixXd> covariances;
    for (int i = 0; i < static_cast<int>(result.model.submodels.size()); ++i)
      covariances.push_back(result.theta_covariance(i));
    print_modal_table(result.model, covariances, in_samples);
    std::printf("\nfit on the data: %.2f %%   output-error std: %.4g\n", result.fit_percent,
                std::sqrt(result.noise_variance));
    print_identifiability(result);
    print_physical_findings(findings);
    if (!args.out.empty()) {
      Config written = config;
      if (args.baselines) {
        set_baselines(written, result.model, covariances);
        int n_baselines = 0;
        for (const auto& b : written.faults.baselines) n_baselines += b.has_value();
        std::printf("baselines: %d modes, with their standard deviations, as faults.baselines in %s\n", n_baselines,
                    args.out.c_str());
      }
      write_file_atomically(args.out, config_to_yaml(written, result.model));
    }
    return 0;
  });
}

}  // namespace modalwatch::cli
