#pragma once
// The modalwatch subcommands. Each returns the process exit code: 0 on success,
// 2 on bad input (the message names the file and the key or row), 1 otherwise.
#include <cstdint>
#include <optional>
#include <string>

#include "record_columns.hpp"

namespace modalwatch::cli {

struct SimulateArgs {
  std::string config;
  std::string out;                 // t,r,u,y CSV
  std::string truth;               // parameter truth CSV (optional)
  std::optional<double> duration;  // overrides simulation.duration
  std::optional<unsigned> seed;    // overrides simulation.seed
};

struct FitArgs {
  std::string config;
  std::string data;                // CSV or LCM log
  std::string channel;             // LCM log: the channel to read
  std::string out;                 // fitted model YAML (optional)
  bool baselines = false;          // --out also carries the fitted modes as the fault detector's baselines
  std::optional<double> from, to;  // time window of the record to use, s
  int max_iterations = 200;
  std::optional<int> modes;        // start this many modes from the data (else model.modes or the submodels)
  std::optional<int> max_modes;    // choose the number of modes from the data, up to this
  std::optional<std::string> output;  // what the sensor measures, for modes from the data (else model.output)
  std::string stabilisation;       // with max_modes: the stabilisation diagram's tables here
  std::string plot_script;         // scripts/plot/plot_stabilisation.py, run on them when given
  std::string input_hold = "zoh";  // zoh (held input) or foh (band-limited input, open loop)
  ColumnArgs columns;
};

struct TrackArgs {
  std::string config;
  std::string data;      // CSV or LCM log
  std::string channel;   // LCM log: the channel to read
  std::string out;       // est.csv
  std::string faults;    // flags CSV (the daemon's fault detector over the record); empty: none
  bool progress = true;  // progress bar on stderr
  ColumnArgs columns;    // the model's inputs (model.inputs) by default
};

// Publishes a record on LCM (config lcm:) as sample_t (batch 1) or
// sample_batch_t (batch N), or with several inputs (model.inputs) as sample2_t
// or sample_batch2_t, paced at speed x real time (0: as fast as possible).
struct ReplayArgs {
  std::string config;
  std::string data;                         // CSV or LCM log
  std::string channel;                      // LCM log: the channel to read
  double speed = 1.0;                       // 0: as fast as possible
  int batch = 1;                            // samples per packet
  std::string url;                          // overrides lcm.url
  std::optional<std::int64_t> start_utime;  // utime of the first sample, us (default: now)
  ColumnArgs columns;                       // the model's inputs (model.inputs) by default
};

struct DiagnoseArgs {
  std::string config;
  std::string data;                            // CSV or LCM log
  std::string channel;                         // LCM logs: the channel to read
  std::string validate;                        // validation record (optional)
  std::optional<double> split;                 // estimation fraction of --data (default 0.7)
  std::string estimate_samples;                // "A:B" rows of --data
  std::string validate_samples;                // "A:B" rows of the validation record
  std::string report;                          // output directory
  std::string effects;                         // comma-separated library (default: all)
  std::string plot_script;                     // scripts/plot/plot_diagnose.py, run when given
  ColumnArgs columns;
  std::string input_hold = "zoh";              // zoh, or foh: held value (u_k + u_k+1)/2 (open loop)
  int substeps = 1;                            // integration substeps per sample
  int max_steps = 5;
  int max_modes_added = 4;  // the mode candidate is not tried past it
  double min_improvement = 0.10;
  int max_delay = 10;
  std::optional<int> modes;  // start this many modes from the data (else model.modes or the submodels)
  std::optional<std::string> output;  // what the sensor measures, for modes from the data (else model.output)
};

int simulate(const SimulateArgs& args);
int replay(const ReplayArgs& args);
int diagnose(const DiagnoseArgs& args);
struct WatchArgs {
  std::string config;    // lcm: section (URL, channels)
  long long count = 0;   // stop after this many estimates messages (0: never)
  double timeout = 0.0;  // s; stop after this long (0: never)
  long long every = 1;   // print every n-th message of each kind
};

int watch(const WatchArgs& args);
int track(const TrackArgs& args);
int fit(const FitArgs& args);

}  // namespace modalwatch::cli
