#pragma once
// The YAML configuration: one file describes the model to identify, the loop
// (controller), and optionally the simulated plant and experiment. Every key is
// documented in config/README.md; an unknown key, a wrong type or an invalid
// value is an InputError naming the key and its line.
#include <array>
#include <optional>
#include <string>
#include <vector>

#include "modalwatch/estimator.hpp"
#include "modalwatch/fault_detector.hpp"
#include "modalwatch/model.hpp"
#include "modalwatch/prefilter.hpp"
#include "modalwatch/simulator.hpp"
#include "modalwatch/transfer_function.hpp"

namespace modalwatch {

struct SubmodelSettings {
  double forgetting = 1.0;              // lambda in (0, 1], eq. (13)
  std::optional<double> random_walk;    // this submodel's Q (else estimator.random_walk)
  std::optional<double> stabilisation;  // this submodel's stabilised forgetting (else estimator.stabilisation)
  std::optional<double> min_memory;     // this submodel's shortest memory (else estimator.min_memory)
  bool operator==(const SubmodelSettings&) const = default;
};

// The `lcm:` section: where the daemon listens and publishes, and where `replay`
// publishes. Defaults stay on the host (ttl=0).
struct LcmSettings {
  std::string url = "udpm://239.255.76.67:7667?ttl=0";
  std::string samples_channel = "MODALWATCH_SAMPLES";            // sample_t in
  std::string batches_channel = "MODALWATCH_BATCHES";            // sample_batch_t in
  std::string estimates_channel = "MODALWATCH_ESTIMATES";        // estimates_t out
  std::string fault_status_channel = "MODALWATCH_FAULT_STATUS";  // fault_status_t out
  std::string heartbeat_channel = "MODALWATCH_HEARTBEAT";        // heartbeat_t out
  bool operator==(const LcmSettings&) const = default;
};

// The `daemon:` section: rates, input policy, ring sizes, checkpoint, logging.
struct DaemonSettings {
  double loop_rate_hz = 1000.0;     // estimation loop tick (absolute-time sleep, CLOCK_MONOTONIC)
  double publish_period = 0.1;      // s of sample time between estimates / fault status messages
  double heartbeat_period = 1.0;    // s (wall clock) between heartbeats
  double stale_time = 1.0;          // s (wall clock) without a sample: HEALTH_STALE_INPUT
  int sample_ring = 65536;          // samples between the LCM thread and the estimation loop
  int snapshot_ring = 256;          // snapshots between the estimation loop and the publisher
  double warmup_backlog = 30.0;     // s of input held while the warm-up fit runs (off the loop)
  int realtime_priority = 0;        // SCHED_FIFO priority of the latency-path threads, + mlockall; 0: off
  std::string checkpoint_path;      // empty: no checkpoint (relative paths: to the config file)
  double checkpoint_period = 60.0;  // s (wall clock) between periodic checkpoints
  std::string log_level = "info";   // spdlog level name
  std::string metrics_listen;       // daemon.metrics.listen, "host:port"; empty: no metrics endpoint
  bool operator==(const DaemonSettings&) const = default;
};

// The `faults:` section: the fault detector (baselines, thresholds per quantity,
// the false-alarm rate and learning). The defaults are FaultDetectorSettings'.
struct FaultSettings {
  double learn_window = FaultDetectorSettings{}.learn_window;                  // s of sample time
  double false_alarm_interval = FaultDetectorSettings{}.false_alarm_interval;  // h per mode
  double cusum_shift = FaultDetectorSettings{}.cusum_shift;
  double settle_std_fraction = FaultDetectorSettings{}.settle_std_fraction;
  double settle_change_fraction = FaultDetectorSettings{}.settle_change_fraction;
  std::array<FaultThresholds, kQuantities> thresholds{};
  // Per submodel (config order): a configured baseline, or none (learned).
  std::vector<std::optional<ModalParameters>> baselines;
  // Per submodel: the standard deviations of its configured baseline (`std:`), or none (exact).
  std::vector<std::optional<ModalParameters>> baseline_std;
  bool operator==(const FaultSettings&) const = default;
};

struct Config {
  std::string source;                               // file name, for messages
  std::string axis;                                 // `axis:`, the axis this file describes (default: the file's stem)
  double sample_time = 0.0;                         // s (from sample_rate_hz)
  AdditiveModel model;                              // initial guesses / nominal model
  // `model.modes`, given instead of submodels: the number of modes that `fit`
  // and `diagnose` start from the data (model then has no submodels).
  std::optional<int> model_modes;
  // `model.output`: what the sensor measures, as z, the derivatives of the
  // position (0 position, 1 velocity, 2 acceleration). Every submodel of
  // `model` and of `plant` carries it.
  int output_derivatives = 0;
  std::vector<SubmodelSettings> submodel_settings;  // one per submodel
  bool closed_loop = false;
  DiscreteTransferFunction controller;
  // `model.output_hold` as given; unset, the batch fits take default_output_hold
  // (srivc.hpp) of their start and the recursive estimator of the configured modes.
  std::optional<Hold> output_hold;
  std::optional<PlantSpec> plant;            // `plant:` section (simulate)
  std::optional<ExperimentSpec> experiment;  // `simulation:` section (simulate)
  // `estimator:` section (track, daemon), completed from the rest of the file:
  // sample_time, closed_loop, controller, output_hold, forgetting and the
  // per-submodel initial_covariance come from the sections above.
  EstimatorSettings estimator;
  LcmSettings lcm;        // `lcm:` section (daemon, replay)
  DaemonSettings daemon;  // `daemon:` section (modalwatchd)
  // `faults:` section (modalwatchd). `daemon.gap_time`, when given, is written
  // into estimator.gap_factor (= gap_time / sample_time): one gap rule for
  // track and the daemon.
  FaultSettings faults;

  // Every setting equal (`source`, the file name, included).
  bool operator==(const Config&) const = default;
};

// Signal files that the config names (`type: csv` under simulation.input or
// simulation.reference) are read as records.hpp's read_signal_file reads them:
// a CSV table with a time column 't', or an LCM log's samples (key `channel`).
Config load_config(const std::string& path);
Config parse_config(const std::string& yaml_text, const std::string& source_name);

// The fault detector's settings for this configuration, for the daemon and
// `track --faults` alike: the `faults:` section, each submodel's memory_time
// = sample_time / (1 - forgetting) (learn_window when it does not forget) and
// update_period = daemon.publish_period.
FaultDetectorSettings fault_detector_settings(const Config& config);

// The configuration as YAML, with `model` in place of the configured one (for
// `fit --out`: a fitted model that seeds the other commands). Throws
// std::invalid_argument for a submodel with an unstable A(p) (is_unstable), which the reader
// would reject: project it first (check_physical in modalwatch/physical.hpp).
std::string config_to_yaml(const Config& config, const AdditiveModel& model);

}  // namespace modalwatch
