// The plant: and simulation: sections (the simulated plant and its excitation
// signals, read from a CSV file or an LCM log for type csv).
#include "sections.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "modalwatch/io/records.hpp"

namespace modalwatch::config_detail {

namespace {
// ---------------------------------------------------------------- plant

Trajectory parse_points(const Value& list, bool positive, double scale) {
  Trajectory traj;
  for (const auto& point : list.items()) {
    const std::vector<Value> tv = point.items();
    if (tv.size() != 2) point.fail("expected a point [t, value]");
    const double t = tv[0].number();
    const double v = positive ? tv[1].positive() : tv[1].number();
    if (!traj.points.empty() && !(t > traj.points.back().first))
      point.fail("t must increase strictly from point to point");
    traj.points.emplace_back(t, v * scale);
  }
  return traj;
}

void parse_trajectory(const Map& m, PlantMode& mode) {
  m.allow({"wn", "frequency_hz", "zeta", "gain"}, "a trajectory");
  const auto wn = m.get("wn");
  const auto hz = m.get("frequency_hz");
  if (wn && hz) hz->fail_plain("give wn or frequency_hz, not both");
  if (wn) mode.wn = parse_points(*wn, true, 1.0);
  if (hz) mode.wn = parse_points(*hz, true, kTwoPi);
  if (const auto z = m.get("zeta")) mode.zeta = parse_points(*z, true, 1.0);
  if (const auto g = m.get("gain")) mode.gain = parse_points(*g, false, 1.0);
}

}  // namespace

PlantSpec parse_plant(const Map& plant, int output_derivatives, const std::vector<std::string>& inputs) {
  plant.allow({"modes", "noise_variance", "snr_db", "output_offset", "input_offset", "input_delay", "coulomb", "cubic"},
              "plant");
  PlantSpec spec;
  const Value list = plant.require("modes");
  const std::vector<Value> items = list.items();
  if (items.empty()) list.fail("must list at least one mode");
  std::vector<SubmodelEntry> entries;
  for (const auto& item : items) {
    const Map m(item);
    entries.push_back(parse_submodel(m, {"trajectory", "input"}, output_derivatives));
    entries.back().submodel.input = parse_submodel_input(m, inputs);
    PlantMode mode;
    mode.submodel = entries.back().submodel;
    mode.resonant = entries.back().mode;
    mode.modal = entries.back().modal;
    if (const auto t = m.get("trajectory")) parse_trajectory(Map(*t), mode);
    spec.modes.push_back(mode);
  }
  check_unique_names(items, entries);
  const auto variance = plant.get("noise_variance");
  const auto snr = plant.get("snr_db");
  if (variance && snr) snr->fail_plain("give noise_variance or snr_db, not both");
  if (variance) {
    spec.noise_variance = variance->number();
    if (spec.noise_variance < 0.0) variance->fail("must be >= 0");
  }
  if (snr) spec.snr_db = snr->number();
  // Undeclared effects for `diagnose` (PlantEffects).
  spec.effects.output_offset = optional_number(plant, "output_offset", 0.0);
  spec.effects.input_offset = optional_number(plant, "input_offset", 0.0);
  if (const auto d = plant.get("input_delay")) spec.effects.input_delay = static_cast<int>(d->integer(0, 1000));
  if (const auto c = plant.get("coulomb")) spec.effects.coulomb = c->at_least(0.0);
  spec.effects.cubic = optional_number(plant, "cubic", 0.0);
  return spec;
}

namespace {

// ---------------------------------------------------------------- signals

// What a signal needs besides its own keys.
struct SignalContext {
  double sample_time = 0.0;
  Eigen::Index samples = 0;
  std::uint64_t seed = 1;
  std::filesystem::path directory;  // of the config file, for relative csv paths
};

void parse_sum_of_sines(const Map& m, SignalSpec& s) {
  m.allow({"type", "amplitudes", "frequencies_rad_s", "frequencies_hz", "phases"}, "type sum_of_sines");
  const Value amplitudes = m.require("amplitudes");
  s.amplitudes = amplitudes.nonempty_numbers();
  const auto rad = m.get("frequencies_rad_s");
  const auto hz = m.get("frequencies_hz");
  if (rad && hz) hz->fail_plain("give frequencies_rad_s or frequencies_hz, not both");
  if (!rad && !hz) m.missing("frequencies_rad_s", "or frequencies_hz");
  const Value& freq = rad ? *rad : *hz;
  for (const auto& f : freq.items()) {
    const double v = f.number();
    if (v < 0.0) f.fail("must be >= 0");
    s.frequencies_rad_s.push_back(rad ? v : v * kTwoPi);
  }
  if (s.frequencies_rad_s.size() != s.amplitudes.size())
    freq.fail("must have as many entries as amplitudes (" + std::to_string(s.amplitudes.size()) + ")");
  if (const auto phases = m.get("phases")) {
    s.phases = phases->numbers();
    if (s.phases.size() != s.amplitudes.size())
      phases->fail("must have as many entries as amplitudes (" + std::to_string(s.amplitudes.size()) + ")");
  }
}

void parse_multisine(const Map& m, SignalSpec& s, const SignalContext& ctx) {
  m.allow({"type", "f_min_hz", "f_max_hz", "period_s", "rms"}, "type multisine");
  const Value f_min = m.require("f_min_hz");
  const Value f_max = m.require("f_max_hz");
  s.f_min_hz = f_min.number();
  if (s.f_min_hz < 0.0) f_min.fail("must be >= 0");
  s.f_max_hz = f_max.number();
  if (!(s.f_max_hz > s.f_min_hz)) f_max.fail("must be > f_min_hz");
  if (s.f_max_hz > 0.5 / ctx.sample_time)
    f_max.fail("must not exceed the Nyquist frequency " + format_number(0.5 / ctx.sample_time) + " Hz");
  const Value period = m.require("period_s");
  s.period_s = period.positive();
  s.rms = m.require("rms").positive();
  // The grid lines k / period_s, k >= 1, inside [f_min, f_max].
  const double first = std::max(1.0, std::ceil(s.f_min_hz * s.period_s));
  const double last = std::floor(s.f_max_hz * s.period_s);
  if (first > last) period.fail("no frequency k / period_s (k >= 1) falls in [f_min_hz, f_max_hz]");
  // Every line is a sine per sample; the count also has to fit the generator's integers.
  constexpr double kMaxLines = 1e6;
  if (last - first + 1.0 > kMaxLines)
    period.fail(format_number(last - first + 1.0) + " frequency lines k / period_s in [f_min_hz, f_max_hz], at most " +
                format_number(kMaxLines) + ": shorten period_s or the band");
}

void parse_prbs(const Map& m, SignalSpec& s) {
  m.allow({"type", "register_bits", "clock_period", "amplitude"}, "type prbs");
  s.register_bits = static_cast<int>(m.require("register_bits").integer(2, 31));
  s.clock_period = static_cast<int>(m.require("clock_period").integer(1, std::numeric_limits<int>::max()));
  s.amplitude = m.require("amplitude").positive();
}

void parse_square(const Map& m, SignalSpec& s) {
  m.allow({"type", "frequency_hz", "amplitude", "offset"}, "type square");
  s.frequency_hz = m.require("frequency_hz").positive();
  s.amplitude = m.require("amplitude").positive();
  s.offset = optional_number(m, "offset", 0.0);
}

std::string available(const Table& table) {
  Keys names(table.columns.begin(), table.columns.end());
  return "available: " + join(names);
}

// Linear interpolation of (t, x) onto k * T, k = 0..n-1; the file must cover the grid.
Eigen::VectorXd interpolate(const Value& where, const Eigen::VectorXd& t, const Eigen::VectorXd& x, double T,
                            Eigen::Index n) {
  const double end = static_cast<double>(n - 1) * T;
  const double slack = 1e-9 * T;
  if (t(0) > slack || t(t.size() - 1) < end - slack)
    where.fail("the file covers t in [" + format_number(t(0)) + ", " + format_number(t(t.size() - 1)) +
               "] s but the simulation needs [0, " + format_number(end) + "] s");
  if (t.size() == 1) return Eigen::VectorXd::Constant(n, x(0));
  Eigen::VectorXd out(n);
  Eigen::Index j = 0;  // the segment [t_j, t_{j+1}] holding t_k; the grid only moves forward
  for (Eigen::Index k = 0; k < n; ++k) {
    const double tk = std::clamp(static_cast<double>(k) * T, t(0), t(t.size() - 1));
    while (j + 2 < t.size() && t(j + 1) < tk) ++j;
    const double w = (tk - t(j)) / (t(j + 1) - t(j));
    out(k) = x(j) + std::clamp(w, 0.0, 1.0) * (x(j + 1) - x(j));
  }
  return out;
}

Eigen::VectorXd parse_csv_signal(const Map& m, SignalSpec& s, const SignalContext& ctx) {
  m.allow({"type", "path", "column", "channel"}, "type csv");
  const Value path = m.require("path");
  const Value column = m.require("column");
  const std::filesystem::path file = ctx.directory / path.text();
  s.csv_path = std::filesystem::absolute(file).lexically_normal().string();
  s.csv_column = column.text();
  const auto channel = m.get("channel");
  if (channel) s.csv_channel = channel->text();
  Table table;
  try {
    table = read_signal_file(s.csv_path, s.csv_channel);
  } catch (const InputError& e) {
    path.fail_plain(e.what());
  }
  const int tc = table.column("t");
  const int xc = table.column(s.csv_column);
  if (tc < 0) path.fail("the file has no time column 't' (" + available(table) + ")");
  if (xc < 0) column.fail("no such column in " + s.csv_path + " (" + available(table) + ")");
  const Eigen::VectorXd t = table.data.col(tc);
  for (Eigen::Index k = 1; k < t.size(); ++k)
    if (!(t(k) > t(k - 1)))
      path.fail_plain(s.csv_path + ": row " + std::to_string(k + 2) + ", column 't': time does not increase");
  return interpolate(path, t, table.data.col(xc), ctx.sample_time, ctx.samples);
}

// A signal, and its samples on the time grid for csv (else empty).
struct ParsedSignal {
  SignalSpec spec;
  Eigen::VectorXd samples;
};

ParsedSignal parse_signal(const Value& v, const SignalContext& ctx) {
  const Map m(v);
  const std::string type = m.require("type").choice({"sum_of_sines", "multisine", "prbs", "square", "csv"});
  ParsedSignal parsed;
  SignalSpec& s = parsed.spec;
  s.seed = ctx.seed;
  if (type == "sum_of_sines") {
    s.kind = SignalSpec::Kind::sum_of_sines;
    parse_sum_of_sines(m, s);
  } else if (type == "multisine") {
    s.kind = SignalSpec::Kind::multisine;
    parse_multisine(m, s, ctx);
  } else if (type == "prbs") {
    s.kind = SignalSpec::Kind::prbs;
    parse_prbs(m, s);
  } else if (type == "square") {
    s.kind = SignalSpec::Kind::square;
    parse_square(m, s);
  } else {
    s.kind = SignalSpec::Kind::csv;
    parsed.samples = parse_csv_signal(m, s, ctx);
  }
  return parsed;
}

// ---------------------------------------------------------------- simulation

}  // namespace

ExperimentSpec parse_simulation(const Map& sim, const Config& config, const std::filesystem::path& dir) {
  sim.allow({"duration", "seed", "input", "reference"}, "simulation");
  ExperimentSpec e;
  e.sample_time = config.sample_time;
  const Value duration = sim.require("duration");
  e.duration = duration.positive();
  const double samples = std::round(e.duration / e.sample_time);
  if (samples < 1.0) duration.fail("shorter than one sample period");
  // The record is held in memory, and the count must fit the index type (found
  // by fuzz_config: a duration of 7e59 s made the conversion undefined).
  constexpr double kMaxSamples = std::numeric_limits<int>::max();
  if (samples > kMaxSamples)
    duration.fail("too long: " + format_number(samples) + " samples at sample_rate_hz, at most " +
                  format_number(kMaxSamples));
  if (const auto seed = sim.get("seed"))
    e.seed = static_cast<std::uint64_t>(seed->integer(0, std::numeric_limits<long long>::max()));
  e.closed_loop = config.closed_loop;
  e.controller = config.controller;
  const std::string used = e.closed_loop ? "reference" : "input";
  const std::string unused = e.closed_loop ? "input" : "reference";
  const std::string loop = e.closed_loop ? "closed" : "open";
  if (const auto extra = sim.get(unused))
    extra->fail_plain("not used when model.loop is " + loop + " (the excitation is simulation." + used + ")");
  const SignalContext ctx{e.sample_time, static_cast<Eigen::Index>(samples), e.seed, dir};
  const Value signal = sim.require(used, "model.loop is " + loop);
  const std::size_t inputs = config.model.inputs.size();
  if (inputs < 2) {
    ParsedSignal parsed = parse_signal(signal, ctx);
    e.excitation = std::move(parsed.spec);
    e.excitation_samples = std::move(parsed.samples);
    return e;
  }
  // One signal per input in model.inputs' order. Two random signals of one
  // kind differ: input j's seed is the record's seed + j, and its PRBS is the
  // sequence shifted by j / inputs of its period.
  const std::string count = std::to_string(inputs);
  if (!signal.node().IsSequence())
    signal.fail_plain("model.inputs names " + count + " inputs: give a list of " + count +
                      " signals, one per input in that order");
  const std::vector<Value> items = signal.items();
  if (items.size() != inputs)
    signal.fail_plain("lists " + std::to_string(items.size()) + " signals; model.inputs names " + count + " inputs");
  for (std::size_t j = 0; j < inputs; ++j) {
    SignalContext input_ctx = ctx;
    input_ctx.seed = ctx.seed + j;
    ParsedSignal parsed = parse_signal(items[j], input_ctx);
    if (parsed.spec.kind == SignalSpec::Kind::prbs)
      parsed.spec.prbs_shift = static_cast<long long>(j) * ((1LL << parsed.spec.register_bits) - 1) /
                               static_cast<long long>(inputs);
    if (j == 0) {
      e.excitation = std::move(parsed.spec);
      e.excitation_samples = std::move(parsed.samples);
    } else {
      e.further_excitations.push_back(std::move(parsed.spec));
      e.further_input_samples.push_back(std::move(parsed.samples));
    }
  }
  return e;
}

}  // namespace modalwatch::config_detail
