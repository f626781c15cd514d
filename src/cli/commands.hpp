#pragma once
// The modalwatch subcommands. Each returns the process exit code: 0 on success,
// 2 on bad input (the message names the file and the key or row), 1 otherwise.
#include <optional>
#include <string>

namespace modalwatch::cli {

struct SimulateArgs {
  std::string config;
  std::string out;                  // t,r,u,y CSV
  std::string truth;                // parameter truth CSV (optional)
  std::optional<double> duration;   // overrides simulation.duration
  std::optional<unsigned> seed;     // overrides simulation.seed
};

struct FitArgs {
  std::string config;
  std::string data;
  std::string out;  // fitted model YAML (optional)
  std::optional<double> from, to;  // time window of the record to use, s
  int max_iterations = 200;
};

struct TrackArgs {
  std::string config;
  std::string data;
  std::string out;       // est.csv
  bool progress = true;  // progress bar on stderr
};

struct WatchArgs {
  std::string config;     // lcm: section (URL, channels)
  long long count = 0;    // stop after this many estimates messages (0: never)
  double timeout = 0.0;   // s; stop after this long (0: never)
  long long every = 1;    // print every n-th message of each kind
};

int simulate(const SimulateArgs& args);
int watch(const WatchArgs& args);
int track(const TrackArgs& args);
int fit(const FitArgs& args);

}  // namespace modalwatch::cli
