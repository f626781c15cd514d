// modalwatch: one command line, several subcommands, all driving the same core
// library as the daemon and the tests.
#include <cstdio>

#include <CLI/CLI.hpp>

#include "commands.hpp"

int main(int argc, char** argv) {
  using namespace modalwatch::cli;
  CLI::App app{"modalwatch: identification of continuous-time modal models (additive RSRIVC)"};
  app.require_subcommand(1);

  SimulateArgs sim;
  auto* simulate_cmd = app.add_subcommand("simulate", "Simulate the plant of a config: writes t,r,u,y and the truth");
  simulate_cmd->add_option("--config,-c", sim.config, "YAML with plant: and simulation: sections")->required();
  simulate_cmd->add_option("--out,-o", sim.out, "record CSV to write (t,r,u,y)")->required();
  simulate_cmd->add_option("--truth", sim.truth, "CSV of the true modal parameters over time");
  simulate_cmd->add_option("--duration", sim.duration, "override simulation.duration [s]");
  simulate_cmd->add_option("--seed", sim.seed, "override simulation.seed");

  FitArgs fit_args;
  auto* fit_cmd = app.add_subcommand("fit", "Offline additive SRIVC on a record: prints the modal table");
  fit_cmd->add_option("--config,-c", fit_args.config, "YAML with the model: section (initial guesses)")->required();
  fit_cmd->add_option("--data,-d", fit_args.data, "record CSV with columns t,u,y[,r]")->required();
  fit_cmd->add_option("--out,-o", fit_args.out, "write the fitted model as a config YAML");
  fit_cmd->add_option("--from", fit_args.from, "use samples from this time on [s]");
  fit_cmd->add_option("--to", fit_args.to, "use samples up to this time [s]");
  fit_cmd->add_option("--max-iterations", fit_args.max_iterations, "block-coordinate cycles")->check(CLI::PositiveNumber);

  TrackArgs track_args;
  bool no_progress = false;
  auto* track_cmd = app.add_subcommand("track", "Recursive additive RSRIVC over a record: writes the estimates per sample");
  track_cmd->add_option("--config,-c", track_args.config, "YAML with the model: (and estimator:) sections")->required();
  track_cmd->add_option("--data,-d", track_args.data, "record CSV with columns t,u,y[,r]")->required();
  track_cmd->add_option("--out,-o", track_args.out, "estimates CSV to write (one row per sample)")->required();
  track_cmd->add_flag("--no-progress", no_progress, "no progress bar on stderr");

  WatchArgs watch_args;
  auto* watch_cmd = app.add_subcommand("watch", "Print the daemon's estimates and fault status as they arrive (LCM)");
  watch_cmd->add_option("--config,-c", watch_args.config, "YAML whose lcm: section names the URL and channels")->required();
  watch_cmd->add_option("--count", watch_args.count, "stop after this many estimates messages");
  watch_cmd->add_option("--timeout", watch_args.timeout, "stop after this many seconds");
  watch_cmd->add_option("--every", watch_args.every, "print every n-th message of each kind")->check(CLI::PositiveNumber);

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return 2;  // bad command line is bad input
  }
  if (simulate_cmd->parsed()) return simulate(sim);
  if (fit_cmd->parsed()) return fit(fit_args);
  if (watch_cmd->parsed()) return watch(watch_args);
  if (track_cmd->parsed()) {
    track_args.progress = !no_progress;
    return track(track_args);
  }
  return 2;
}
