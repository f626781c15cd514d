#include "commands.hpp"
#include "guarded.hpp"
#include "records.hpp"
#include "table.hpp"

#include <cmath>
#include <cstdio>
#include <exception>
#include <fstream>
#include <numbers>
#include <stdexcept>

#include "modalwatch/config.hpp"
#include "modalwatch/csv.hpp"
#include "modalwatch/error.hpp"
#include "modalwatch/simulator.hpp"
#include "modalwatch/srivc.hpp"

namespace modalwatch::cli {
namespace {


void write_text_atomically(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out << text;
    if (!out.flush()) {
      std::remove(tmp.c_str());
      throw InputError(path, "cannot write");
    }
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw InputError(path, "cannot write");
  }
}

Record window(const Record& r, const FitArgs& args) {
  Eigen::Index begin = 0, end = r.size();
  if (args.from) while (begin < end && r.t(begin) < *args.from) ++begin;
  if (args.to) while (end > begin && r.t(end - 1) > *args.to) --end;
  return r.segment(begin, end - begin);
}


}  // namespace

int simulate(const SimulateArgs& args) {
  return guarded("simulate", [&] {
    const Config config = load_cli_config(args.config);
    if (!config.plant || !config.experiment)
      throw InputError(args.config, "simulate needs the 'plant' and 'simulation' sections");
    ExperimentSpec experiment = *config.experiment;
    if (args.duration) {
      if (!(*args.duration > 0.0)) throw InputError("--duration", "must be > 0");
      experiment.duration = *args.duration;
    }
    if (args.seed) experiment.seed = *args.seed;
    const SimulationResult sim = simulate(*config.plant, experiment);
    write_record(args.out, sim.record);
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

int fit(const FitArgs& args) {
  return guarded("fit", [&] {
    const Config config = load_cli_config(args.config);
    const Record full = load_record({args.data, args.channel, config.closed_loop, {}});
    const Record data = window(full, args);
    const int nb = config.model.n_beta();
    if (data.size() < 2 * nb + 2)
      throw InputError(args.data, std::to_string(data.size()) + " samples (rows) for " + std::to_string(nb) +
                                      " parameters: need at least " + std::to_string(2 * nb + 2));
    const double T = data.sample_time();
    if (std::abs(T - config.sample_time) > 0.01 * config.sample_time)
      throw InputError(args.data, "column 't': sample time " + std::to_string(T) + " s does not match sample_rate_hz " +
                                      std::to_string(1.0 / config.sample_time) + " of " + config.source);
    if (config.closed_loop && !data.has_reference())
      throw InputError(args.data, "closed loop (model.loop) needs a column 'r'");
    SrivcOptions options;
    options.closed_loop = config.closed_loop;
    options.controller = config.controller;
    options.output_hold = config.output_hold;
    options.max_iterations = args.max_iterations;
    const FitResult result = fit_srivc(data, config.model, options);

    std::printf("modalwatch fit: %lld samples at %g Hz, %s loop, %zu submodels, %d parameters\n",
                static_cast<long long>(data.size()), 1.0 / T, config.closed_loop ? "closed" : "open",
                config.model.submodels.size(), nb);
    std::printf("%s after %d block-coordinate cycles (last change %.2e), %d stability projections\n",
                result.converged ? "converged" : "NOT converged", result.iterations,
                result.change_history.empty() ? 0.0 : result.change_history.back(), result.projections);
    std::vector<Eigen::MatrixXd> covariances;
    for (int i = 0; i < static_cast<int>(result.model.submodels.size()); ++i)
      covariances.push_back(result.theta_covariance(i));
    print_modal_table(result.model, covariances);
    std::printf("\nfit on the data: %.2f %%   output-error std: %.4g\n", result.fit_percent,
                std::sqrt(result.noise_variance));
    if (!args.out.empty()) write_text_atomically(args.out, config_to_yaml(config, result.model));
    return 0;
  });
}

}  // namespace modalwatch::cli
