// modalwatch: one command line, several subcommands, all driving the same core
// library as the daemon and the tests.
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include <CLI/CLI.hpp>

#include "commands.hpp"
#include "modalwatch_version.hpp"

namespace {

// The record columns (CSV records; an LCM log has fixed fields).
void add_column_options(CLI::App* command, modalwatch::cli::ColumnArgs& columns) {
  command->add_option("--t-column", columns.t, "time column of the record (e.g. n: sample index)")
      ->capture_default_str();
  command->add_option("--u-column", columns.u,
                      "input column of the record (e.g. u1); repeat it for several inputs (--u-column u1 --u-column "
                      "u2), in the order of model.inputs [default: model.inputs, else u]");
  command->add_option("--y-column", columns.y, "output column of the record (e.g. y2)")->capture_default_str();
}

}  // namespace

int main(int argc, char** argv) {
  using namespace modalwatch::cli;
  CLI::App app{"modalwatch: identification of continuous-time modal models (additive RSRIVC)"};
  app.set_version_flag("--version", "modalwatch " MODALWATCH_VERSION);
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
  fit_cmd->add_option("--data,-d", fit_args.data, "record: CSV with columns t,u,y[,r], or an LCM log")->required();
  fit_cmd->add_option("--channel", fit_args.channel, "LCM log: channel with the samples (default: the only one)");
  fit_cmd->add_option("--out,-o", fit_args.out, "write the fitted model as a config YAML");
  fit_cmd
      ->add_flag("--baselines", fit_args.baselines,
                 "with --out: the fitted modes (with their standard deviations) become the fault detector's "
                 "baselines (faults.baselines), a commissioning fit instead of a learned baseline")
      ->needs("--out");
  fit_cmd->add_option("--from", fit_args.from, "use samples from this time on [s]");
  fit_cmd->add_option("--to", fit_args.to, "use samples up to this time [s]");
  fit_cmd->add_option("--max-iterations", fit_args.max_iterations, "block-coordinate cycles")
      ->check(CLI::PositiveNumber);
  auto* fit_modes =
      fit_cmd->add_option("--modes", fit_args.modes, "start this many modes from the data (overrides model:)")
          ->check(CLI::Range(1, 64));
  fit_cmd
      ->add_option("--max-modes", fit_args.max_modes,
                   "choose the number of modes from the data: fits of 1..N modes compared by BIC, with a "
                   "stabilisation diagram")
      ->check(CLI::Range(1, 64))
      ->excludes(fit_modes);
  fit_cmd
      ->add_option("--output", fit_args.output,
                   "what the sensor measures, for modes from the data (--modes, --max-modes, model.modes): "
                   "position, velocity or acceleration (overrides model.output)")
      ->check(CLI::IsMember({"position", "velocity", "acceleration"}));
  fit_cmd
      ->add_option("--stabilisation", fit_args.stabilisation,
                   "with --max-modes: write stabilisation.csv and frf.csv into this directory")
      ->needs("--max-modes");
  fit_cmd
      ->add_option("--plot-script", fit_args.plot_script,
                   "with --stabilisation: run this scripts/plot/plot_stabilisation.py on it")
      ->needs("--stabilisation");
  add_column_options(fit_cmd, fit_args.columns);
  fit_cmd
      ->add_option("--input-hold", fit_args.input_hold,
                   "zoh (input held between samples, as from a DAC) or foh (a measured band-limited input, "
                   "open loop)")
      ->check(CLI::IsMember({"zoh", "foh"}));

  TrackArgs track_args;
  bool no_progress = false;
  auto* track_cmd =
      app.add_subcommand("track", "Recursive additive RSRIVC over a record: writes the estimates per sample");
  track_cmd->add_option("--config,-c", track_args.config, "YAML with the model: (and estimator:) sections")->required();
  track_cmd->add_option("--data,-d", track_args.data, "record: CSV with columns t,u,y[,r], or an LCM log")->required();
  track_cmd->add_option("--channel", track_args.channel, "LCM log: channel with the samples (default: the only one)");
  track_cmd->add_option("--out,-o", track_args.out, "estimates CSV to write (one row per sample)")->required();
  track_cmd->add_option("--faults", track_args.faults,
                        "flags CSV to write: the daemon's fault detector (faults:) over the record, one row per flag "
                        "change (t,mode,quantity,event,value,baseline,relative,sigma)");
  track_cmd->add_flag("--no-progress", no_progress, "no progress bar on stderr");
  add_column_options(track_cmd, track_args.columns);

  ReplayArgs replay_args;
  std::string speed = "1";
  auto* replay_cmd = app.add_subcommand("replay", "Publish a record on LCM (lcm: section) at real time or faster");
  replay_cmd->add_option("--config,-c", replay_args.config, "YAML with the lcm: section (and model.loop)")->required();
  replay_cmd->add_option("--data,-d", replay_args.data, "record: CSV with columns t,u,y[,r], or an LCM log")
      ->required();
  replay_cmd->add_option("--channel", replay_args.channel, "LCM log input: channel with the samples");
  replay_cmd->add_option("--speed", speed, "times real time; 0 or 'max': as fast as possible")->capture_default_str();
  replay_cmd
      ->add_option("--batch", replay_args.batch,
                   "samples per packet: 1 = sample_t, N > 1 = sample_batch_t (several inputs: sample2_t, "
                   "sample_batch2_t)")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  replay_cmd->add_option("--url", replay_args.url, "LCM URL (overrides lcm.url)");
  replay_cmd->add_option("--start-utime", replay_args.start_utime, "utime of the first sample [us] (default: now)");
  add_column_options(replay_cmd, replay_args.columns);
  DiagnoseArgs diag;
  auto* diagnose_cmd = app.add_subcommand("diagnose", "Residual analysis and model augmentation: writes a report");
  diagnose_cmd->add_option("--config,-c", diag.config, "YAML with the model: section")->required();
  diagnose_cmd->add_option("--data,-d", diag.data, "record: CSV with columns t,u,y[,r], or an LCM log")->required();
  diagnose_cmd->add_option("--validate", diag.validate, "validation record (CSV or LCM log)");
  diagnose_cmd->add_option("--channel", diag.channel, "LCM log input: channel with the samples");
  diagnose_cmd->add_option("--split", diag.split, "estimation fraction of --data, the rest validates (0.7)");
  diagnose_cmd->add_option("--estimate-samples", diag.estimate_samples, "FIRST:END rows of --data to estimate on");
  diagnose_cmd->add_option("--validate-samples", diag.validate_samples, "FIRST:END rows to validate on");
  diagnose_cmd->add_option("--report,-r", diag.report, "directory for report.md, summary.json, model.yaml")->required();
  diagnose_cmd->add_option("--effects", diag.effects, "comma-separated candidate effects (default: all)");
  diagnose_cmd->add_option("--plot-script", diag.plot_script, "run this scripts/plot/plot_diagnose.py on the report");
  add_column_options(diagnose_cmd, diag.columns);
  diagnose_cmd->add_option("--input-hold", diag.input_hold, "zoh (held input) or foh (band-limited input, open loop)")
      ->check(CLI::IsMember({"zoh", "foh"}));
  diagnose_cmd->add_option("--substeps", diag.substeps, "integration substeps per sample (nonlinear effects)")
      ->check(CLI::Range(1, 64));
  diagnose_cmd->add_option("--max-steps", diag.max_steps, "effects added at most")->check(CLI::NonNegativeNumber);
  diagnose_cmd->add_option("--max-added-modes", diag.max_modes_added, "modes added at most")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  diagnose_cmd
      ->add_option("--min-improvement", diag.min_improvement,
                   "credit to add an effect: its drop of the validation RMS beyond the refit without it, relative")
      ->check(CLI::Range(0.0, 1.0));
  diagnose_cmd->add_option("--max-delay", diag.max_delay, "largest input delay tried [samples]")
      ->check(CLI::PositiveNumber);
  diagnose_cmd->add_option("--modes", diag.modes, "start this many modes from the data (overrides model:)")
      ->check(CLI::Range(1, 64));
  diagnose_cmd
      ->add_option("--output", diag.output,
                   "what the sensor measures, for modes from the data (--modes, model.modes): position, velocity "
                   "or acceleration (overrides model.output)")
      ->check(CLI::IsMember({"position", "velocity", "acceleration"}));
  WatchArgs watch_args;
  auto* watch_cmd = app.add_subcommand("watch", "Print the daemon's estimates and fault status as they arrive (LCM)");
  watch_cmd->add_option("--config,-c", watch_args.config, "YAML whose lcm: section names the URL and channels")
      ->required();
  watch_cmd->add_option("--count", watch_args.count, "stop after this many estimates messages");
  watch_cmd->add_option("--timeout", watch_args.timeout, "stop after this many seconds");
  watch_cmd->add_option("--every", watch_args.every, "print every n-th message of each kind")
      ->check(CLI::PositiveNumber);

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return 2;  // bad command line is bad input
  }
  if (simulate_cmd->parsed()) return simulate(sim);
  if (fit_cmd->parsed()) return fit(fit_args);
  if (replay_cmd->parsed()) {
    if (speed == "max") {
      replay_args.speed = 0.0;
    } else {
      try {
        std::size_t used = 0;
        replay_args.speed = std::stod(speed, &used);
        if (used != speed.size() || !(replay_args.speed >= 0.0) || !std::isfinite(replay_args.speed))
          throw std::invalid_argument(speed);
      } catch (const std::exception&) {
        std::fprintf(stderr, "modalwatch replay: --speed: '%s' is not a number >= 0 or 'max'\n", speed.c_str());
        return 2;
      }
    }
    return replay(replay_args);
  }
  if (diagnose_cmd->parsed()) return diagnose(diag);
  if (watch_cmd->parsed()) return watch(watch_args);
  if (track_cmd->parsed()) {
    track_args.progress = !no_progress;
    return track(track_args);
  }
  return 2;
}
