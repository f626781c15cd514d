// config_to_yaml: every section that load_config reads, written back so that
// parse_config(config_to_yaml(c)) == c.
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "modalwatch/io/config.hpp"
#include "modalwatch/polynomial.hpp"
#include "yaml_value.hpp"

namespace modalwatch {
namespace {

using config_detail::format_number;
using config_detail::kTwoPi;

std::string quoted(const std::string& s) {
  std::string out = "\"";
  for (const char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    if (static_cast<unsigned char>(c) < 0x20) {
      char esc[8];
      std::snprintf(esc, sizeof esc, "\\x%02x", static_cast<unsigned char>(c));
      out += esc;
      continue;
    }
    out += c;
  }
  return out + "\"";
}

template <typename Range>
std::string flow_list(const Range& values) {
  std::string out = "[";
  for (const double v : values) (out += out.size() > 1 ? ", " : "") += format_number(v);
  return out + "]";
}

std::string flow_names(const std::vector<std::string>& names) {
  std::string out = "[";
  for (const auto& n : names) (out += out.size() > 1 ? ", " : "") += quoted(n);
  return out + "]";
}

std::string points(const Trajectory& traj) {
  std::string out = "[";
  // Appended piece by piece: GCC 12's -O3 warns (-Wrestrict) on "[" + std::string.
  for (const auto& [t, v] : traj.points) {
    out += out.size() > 1 ? ", [" : "[";
    out += format_number(t);
    out += ", ";
    out += format_number(v);
    out += "]";
  }
  return out + "]";
}

// Writes `key: value` lines at an indentation.
class YamlWriter {
 public:
  void line(int indent, const std::string& text) { out_ << std::string(2 * indent, ' ') << text << '\n'; }
  void key(int indent, const std::string& k, const std::string& v) { line(indent, k + ": " + v); }
  void number(int indent, const std::string& k, double v) { key(indent, k, format_number(v)); }
  std::string str() const { return out_.str(); }

 private:
  std::ostringstream out_;
};

bool valid_modal(const ModalParameters& p) {
  return std::isfinite(p.wn) && p.wn > 0 && std::isfinite(p.zeta) && p.zeta > 0 && std::isfinite(p.gain) && p.gain != 0;
}

// The keys of a submodel after `- name:`; list items are written at `indent`.
// x moved by `steps` units in the last place.
double nudge(double x, int steps) {
  for (; steps > 0; --steps) x = std::nextafter(x, std::numeric_limits<double>::infinity());
  for (; steps < 0; ++steps) x = std::nextafter(x, -std::numeric_limits<double>::infinity());
  return x;
}

// Modal parameters from which make_mode gives back the mode's coefficients
// exactly, so that the file reads back as the same model: modal_parameters
// rounds, and a few units in the last place either way undo it. Of those that
// do, the shortest to write; when none does, modal_parameters' (the model read
// back differs in the last digits); nothing for a submodel that is no mode.
std::optional<ModalParameters> mode_parameters(const Submodel& s) {
  const ModalParameters guess = modal_parameters(s);
  if (!valid_modal(guess)) return std::nullopt;
  std::optional<ModalParameters> best;
  std::size_t best_length = 0;
  for (int i = -4; i <= 4; ++i) {
    const double wn = nudge(guess.wn, i);
    if (1.0 / (wn * wn) != s.a(1)) continue;
    for (int j = -4; j <= 4; ++j) {
      const double zeta = nudge(guess.zeta, j);
      if (2.0 * zeta / wn != s.a(0)) continue;
      const ModalParameters modal{wn, zeta, guess.gain};
      if (!valid_modal(modal)) continue;
      const std::size_t length = format_number(wn).size() + format_number(zeta).size();
      if (!best || length < best_length) {
        best = modal;
        best_length = length;
      }
    }
  }
  return best ? best : std::optional<ModalParameters>(guess);
}

void write_submodel(YamlWriter& w, int indent, const Submodel& s) {
  w.key(indent, "- name", quoted(s.name));
  const int in = indent + 1;
  const std::optional<ModalParameters> modal = s.is_mode() ? mode_parameters(s) : std::nullopt;
  if (modal) {
    w.key(in, "kind", "mode");
    w.number(in, "wn", modal->wn);
    w.number(in, "zeta", modal->zeta);
    w.number(in, "gain", modal->gain);
  } else if (s.is_feedthrough() && s.b.size() == 1 && s.b(0) != 0.0) {
    w.key(in, "kind", "feedthrough");
    w.number(in, "gain", s.b(0));
  } else if (s.n == 0 && s.m == 0 && s.b.size() == 1 && s.b(0) != 0.0) {
    w.key(in, "kind", "rigid_body");
    w.number(in, "gain", s.b(0));
    w.key(in, "rigid_poles", std::to_string(s.rigid_poles));
  } else {
    // The reader rejects it too: an unstable estimate is projected (physical.hpp) before it is written.
    if (is_unstable(s.a))
      throw std::invalid_argument("submodel " + s.name +
                                  ": A(p) has a root in the right half plane; an unstable model is not written");
    w.key(in, "kind", "transfer_function");
    w.key(in, "a", flow_list(s.a));
    w.key(in, "b", flow_list(s.b));
    w.key(in, "rigid_poles", std::to_string(s.rigid_poles));
  }
}

// The configured submodel that the index-th submodel of a written model stands
// for: the one of the same name, else the one at the same place.
std::size_t configured_index(const Config& config, const std::string& name, std::size_t index) {
  const auto& subs = config.model.submodels;
  for (std::size_t i = 0; i < subs.size(); ++i)
    if (subs[i].name == name) return i;
  return index;
}

void write_model(YamlWriter& w, const Config& config, const AdditiveModel& model) {
  w.line(0, "model:");
  w.key(1, "loop", config.closed_loop ? "closed" : "open");
  // Only as given: unset resolves per command (fit and track differ).
  if (config.output_hold) w.key(1, "output_hold", hold_name(*config.output_hold));
  // What the sensor measures; position, the default, is not written.
  const int output = model.submodels.empty() ? config.output_derivatives : model.output_derivatives();
  if (output != 0) w.key(1, "output", output_kind_name(output));
  if (!model.inputs.empty()) w.key(1, "inputs", flow_names(model.inputs));
  if (model.submodels.empty() && config.model_modes) {
    w.key(1, "modes", std::to_string(*config.model_modes));
    return;
  }
  w.line(1, "submodels:");
  const auto& covariances = config.estimator.initial_covariance;
  for (std::size_t i = 0; i < model.submodels.size(); ++i) {
    const Submodel& s = model.submodels[i];
    const std::size_t c = configured_index(config, s.name, i);
    write_submodel(w, 2, s);
    if (!model.inputs.empty()) w.key(3, "input", quoted(model.input_name(s.input)));
    if (!s.poles_of.empty()) w.key(3, "poles_of", quoted(s.poles_of));
    w.number(3, "forgetting", c < config.submodel_settings.size() ? config.submodel_settings[c].forgetting : 1.0);
    if (c < config.submodel_settings.size() && config.submodel_settings[c].random_walk)
      w.number(3, "random_walk", *config.submodel_settings[c].random_walk);
    if (c < config.submodel_settings.size() && config.submodel_settings[c].stabilisation)
      w.number(3, "stabilisation", *config.submodel_settings[c].stabilisation);
    if (c < config.submodel_settings.size() && config.submodel_settings[c].min_memory)
      w.number(3, "min_memory", *config.submodel_settings[c].min_memory);
    // Only when it still fits theta_i (a written model of another order would not load).
    if (c < covariances.size() && covariances[c].size() > 0 && covariances[c].size() == s.n_theta())
      w.key(3, "initial_covariance", flow_list(covariances[c]));
  }
}

void write_controller(YamlWriter& w, const DiscreteTransferFunction& c) {
  w.line(0, "controller:");
  w.key(1, "numerator", flow_list(c.numerator()));
  w.key(1, "denominator", flow_list(c.denominator()));
}

void write_plant(YamlWriter& w, const PlantSpec& plant, const AdditiveModel& model) {
  w.line(0, "plant:");
  if (plant.snr_db)
    w.number(1, "snr_db", *plant.snr_db);
  else
    w.number(1, "noise_variance", plant.noise_variance);
  const PlantEffects& e = plant.effects;
  if (e.output_offset != 0.0) w.number(1, "output_offset", e.output_offset);
  if (e.input_offset != 0.0) w.number(1, "input_offset", e.input_offset);
  if (e.input_delay != 0) w.number(1, "input_delay", e.input_delay);
  if (e.coulomb != 0.0) w.number(1, "coulomb", e.coulomb);
  if (e.cubic != 0.0) w.number(1, "cubic", e.cubic);
  w.line(1, "modes:");
  for (const auto& mode : plant.modes) {
    if (!mode.resonant) {
      write_submodel(w, 2, mode.submodel);
      if (!model.inputs.empty()) w.key(3, "input", quoted(model.input_name(mode.submodel.input)));
      continue;
    }
    w.key(2, "- name", quoted(mode.submodel.name));
    w.key(3, "kind", "mode");
    w.number(3, "wn", mode.modal.wn);
    w.number(3, "zeta", mode.modal.zeta);
    w.number(3, "gain", mode.modal.gain);
    if (!model.inputs.empty()) w.key(3, "input", quoted(model.input_name(mode.submodel.input)));
    if (mode.wn.points.empty() && mode.zeta.points.empty() && mode.gain.points.empty()) continue;
    w.line(3, "trajectory:");
    if (!mode.wn.points.empty()) w.key(4, "wn", points(mode.wn));
    if (!mode.zeta.points.empty()) w.key(4, "zeta", points(mode.zeta));
    if (!mode.gain.points.empty()) w.key(4, "gain", points(mode.gain));
  }
}

// A signal's keys at `in`, or as a list item (`- type:` at `in`, the rest below it).
void write_signal(YamlWriter& w, int in, const SignalSpec& s, bool list_item = false) {
  const std::string type = list_item ? "- type" : "type";
  const int at = in;
  if (list_item) ++in;
  switch (s.kind) {
    case SignalSpec::Kind::sum_of_sines:
      w.key(at, type, "sum_of_sines");
      w.key(in, "amplitudes", flow_list(s.amplitudes));
      w.key(in, "frequencies_rad_s", flow_list(s.frequencies_rad_s));
      if (!s.phases.empty()) w.key(in, "phases", flow_list(s.phases));
      break;
    case SignalSpec::Kind::multisine:
      w.key(at, type, "multisine");
      w.number(in, "f_min_hz", s.f_min_hz);
      w.number(in, "f_max_hz", s.f_max_hz);
      w.number(in, "period_s", s.period_s);
      w.number(in, "rms", s.rms);
      break;
    case SignalSpec::Kind::prbs:
      w.key(at, type, "prbs");
      w.key(in, "register_bits", std::to_string(s.register_bits));
      w.key(in, "clock_period", std::to_string(s.clock_period));
      w.number(in, "amplitude", s.amplitude);
      break;
    case SignalSpec::Kind::square:
      w.key(at, type, "square");
      w.number(in, "frequency_hz", s.frequency_hz);
      w.number(in, "amplitude", s.amplitude);
      w.number(in, "offset", s.offset);
      break;
    case SignalSpec::Kind::csv:
      w.key(at, type, "csv");
      w.key(in, "path", quoted(s.csv_path));  // absolute: valid wherever the YAML is written
      w.key(in, "column", quoted(s.csv_column));
      if (!s.csv_channel.empty()) w.key(in, "channel", quoted(s.csv_channel));
      break;
  }
}

// Every key, defaults included, so that the file shows what a run uses.
void write_estimator(YamlWriter& w, const EstimatorSettings& e, double sample_time) {
  w.line(0, "estimator:");
  w.key(1, "block_iterations", std::to_string(e.block_iterations));
  w.key(1, "refinements", std::to_string(e.refinements));
  w.key(1, "update_divisor", std::to_string(e.update_divisor));
  w.number(1, "warmup", static_cast<double>(e.warmup_samples) * sample_time);
  w.key(1, "fit_on_warmup", e.fit_on_warmup ? "true" : "false");
  w.key(1, "warmup_iterations", std::to_string(e.warmup_iterations));
  w.number(1, "initial_covariance_relative", e.initial_covariance_relative);
  w.number(1, "random_walk", e.random_walk);
  w.number(1, "covariance_bound", e.covariance_bound);
  w.number(1, "stabilisation", e.stabilisation);
  w.number(1, "min_memory", e.min_memory);
  w.number(1, "settled_memory", e.settled_memory);
  w.number(1, "damping_deadband", e.damping_deadband);
  w.number(1, "divergence_ratio", e.divergence_ratio);
  w.number(1, "change_ratio", e.change_ratio);
  w.number(1, "change_threshold", e.change_threshold);
  w.number(1, "change_hold", e.change_hold);
  w.number(1, "gap_factor", e.gap_factor);
  w.number(1, "outlier_sigma", e.outlier_sigma);
  w.number(1, "residual_window", e.residual_window);
  w.number(1, "low_excitation_ratio", e.low_excitation_ratio);
  w.number(1, "low_excitation_window", e.low_excitation_window);
}

void write_lcm(YamlWriter& w, const LcmSettings& l) {
  w.line(0, "lcm:");
  w.key(1, "url", quoted(l.url));
  w.line(1, "channels:");
  w.key(2, "samples", quoted(l.samples_channel));
  w.key(2, "batches", quoted(l.batches_channel));
  w.key(2, "estimates", quoted(l.estimates_channel));
  w.key(2, "fault_status", quoted(l.fault_status_channel));
  w.key(2, "heartbeat", quoted(l.heartbeat_channel));
}

void write_daemon(YamlWriter& w, const DaemonSettings& d) {
  w.line(0, "daemon:");
  w.number(1, "loop_rate_hz", d.loop_rate_hz);
  w.number(1, "publish_period", d.publish_period);
  w.number(1, "heartbeat_period", d.heartbeat_period);
  w.number(1, "stale_time", d.stale_time);
  w.key(1, "sample_ring", std::to_string(d.sample_ring));
  w.key(1, "snapshot_ring", std::to_string(d.snapshot_ring));
  w.number(1, "warmup_backlog", d.warmup_backlog);
  if (d.realtime_priority > 0) w.key(1, "realtime_priority", std::to_string(d.realtime_priority));
  if (!d.checkpoint_path.empty()) {
    w.line(1, "checkpoint:");
    w.key(2, "path", quoted(d.checkpoint_path));  // absolute: valid wherever the YAML is written
    w.number(2, "period", d.checkpoint_period);
  }
  w.key(1, "log_level", d.log_level);
  if (!d.metrics_listen.empty()) {
    w.line(1, "metrics:");
    w.key(2, "listen", quoted(d.metrics_listen));
  }
}

void write_faults(YamlWriter& w, const FaultSettings& f, const AdditiveModel& model) {
  w.line(0, "faults:");
  w.number(1, "learn_window", f.learn_window);
  w.number(1, "false_alarm_interval", f.false_alarm_interval);
  w.number(1, "cusum_shift", f.cusum_shift);
  w.number(1, "settle_std_fraction", f.settle_std_fraction);
  w.number(1, "settle_change_fraction", f.settle_change_fraction);
  const char* names[kQuantities] = {"wn", "zeta", "gain"};
  for (int q = 0; q < kQuantities; ++q) {
    const FaultThresholds& th = f.thresholds[static_cast<std::size_t>(q)];
    w.line(1, std::string(names[q]) + ":");
    w.number(2, "sigma", th.sigma_threshold);
    w.number(2, "relative", th.relative_threshold);
    w.number(2, "hold", th.hold_time);
    w.number(2, "clear_fraction", th.clear_fraction);
    w.number(2, "clear_time", th.clear_time);
  }
  bool any = false;
  for (std::size_t i = 0; i < f.baselines.size() && i < model.submodels.size(); ++i) {
    if (!f.baselines[i]) continue;
    if (!any) w.line(1, "baselines:");
    any = true;
    w.line(2, quoted(model.submodels[i].name) + ":");
    w.number(3, "wn", f.baselines[i]->wn);
    w.number(3, "zeta", f.baselines[i]->zeta);
    w.number(3, "gain", f.baselines[i]->gain);
    if (i < f.baseline_std.size() && f.baseline_std[i]) {
      w.line(3, "std:");
      w.number(4, "wn", f.baseline_std[i]->wn);
      w.number(4, "zeta", f.baseline_std[i]->zeta);
      w.number(4, "gain", f.baseline_std[i]->gain);
    }
  }
}

void write_simulation(YamlWriter& w, const ExperimentSpec& e) {
  w.line(0, "simulation:");
  w.number(1, "duration", e.duration);
  w.key(1, "seed", std::to_string(e.seed));
  w.line(1, e.closed_loop ? "reference:" : "input:");
  if (e.further_inputs() == 0) {
    write_signal(w, 2, e.excitation);
    return;
  }
  // One signal per input, in model.inputs' order. Samples given without a
  // signal (a program's, not a file's) cannot be written.
  write_signal(w, 2, e.excitation, true);
  for (const SignalSpec& further : e.further_excitations) write_signal(w, 2, further, true);
}

}  // namespace

std::string config_to_yaml(const Config& config, const AdditiveModel& model) {
  YamlWriter w;
  w.line(0, "# modalwatch configuration" + (config.source.empty() ? std::string() : ", written from " + config.source) +
                " (keys: config/README.md)");
  if (!config.axis.empty()) w.key(0, "axis", quoted(config.axis));
  w.number(0, "sample_rate_hz", 1.0 / config.sample_time);
  write_model(w, config, model);
  if (!config.controller.empty()) write_controller(w, config.controller);
  if (config.plant) write_plant(w, *config.plant, config.model);
  if (config.experiment) write_simulation(w, *config.experiment);
  write_estimator(w, config.estimator, config.sample_time);
  write_lcm(w, config.lcm);
  write_daemon(w, config.daemon);
  write_faults(w, config.faults, config.model);
  return w.str();
}

}  // namespace modalwatch
