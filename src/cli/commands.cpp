#include "commands.hpp"
#include "guarded.hpp"

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

void print_modal_table(const FitResult& fit) {
  std::printf("\n%-10s %11s %10s %12s %10s %9s %9s %12s %10s\n", "submodel", "f [Hz]", "+-", "wn [rad/s]", "+-",
              "zeta", "+-", "gain", "+-");
  for (std::size_t i = 0; i < fit.model.submodels.size(); ++i) {
    const Submodel& s = fit.model.submodels[i];
    const ModalParameters p = modal_parameters(s);
    const ModalParameters sd = modal_std(s, fit.theta_covariance(static_cast<int>(i)));
    if (s.is_mode()) {
      std::printf("%-10s %11.5f %10.2e %12.5f %10.2e %9.5f %9.2e %12.5g %10.2e\n", s.name.c_str(), p.hz(),
                  sd.wn / (2 * std::numbers::pi), p.wn, sd.wn, p.zeta, sd.zeta, p.gain, sd.gain);
      continue;
    }
    // Rigid bodies and general transfer functions: their coefficients, and the
    // resonances of A when it has any.
    std::printf("%-10s n=%d m=%d l=%d", s.name.c_str(), s.n, s.m, s.rigid_poles);
    const Eigen::VectorXd th = s.theta();
    const Eigen::MatrixXd c = fit.theta_covariance(static_cast<int>(i));
    for (int j = 0; j < s.n_theta(); ++j) {
      const bool is_a = j < s.n;
      std::printf("  %s%d=%.6g(+-%.2g)", is_a ? "a" : "b", is_a ? j + 1 : j - s.n, th(j), std::sqrt(std::max(0.0, c(j, j))));
    }
    std::printf("\n");
    for (const auto& r : resonances(s))
      std::printf("%-10s %11.5f %10s %12.5f %10s %9.5f\n", "", r.hz(), "", r.wn, "", r.zeta);
  }
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
    const Config config = load_config(args.config);
    const Record full = read_record(args.data);
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
    print_modal_table(result);
    std::printf("\nfit on the data: %.2f %%   output-error std: %.4g\n", result.fit_percent,
                std::sqrt(result.noise_variance));
    if (!args.out.empty()) write_text_atomically(args.out, config_to_yaml(config, result.model));
    return 0;
  });
}

}  // namespace modalwatch::cli
