// The YAML configuration (config/README.md is the specification). Every key is
// read through Value/Map, which know the file, the line and the dotted key
// path, so that any rejection names all three: a config error must be fixable
// from the message alone.
#include "modalwatch/io/config.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string_view>
#include <system_error>

#include "modalwatch/io/csv.hpp"
#include "modalwatch/error.hpp"

namespace modalwatch {
namespace {

constexpr double kTwoPi = 6.283185307179586476925286766559;

using Keys = std::vector<std::string_view>;

std::string join(const Keys& keys) {
  std::string out;
  for (const auto k : keys) (out += out.empty() ? "" : ", ") += k;
  return out;
}

std::string format_number(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.17g", v);
  return buffer;
}

// A node as the user wrote it, for "(got ...)": quoted strings keep their quotes.
std::string render(const YAML::Node& node) {
  if (!node.IsDefined() || node.IsNull()) return "null";
  if (node.IsScalar()) return node.Tag() == "!" ? "\"" + node.Scalar() + "\"" : node.Scalar();
  YAML::Emitter out;
  out.SetSeqFormat(YAML::Flow);
  out.SetMapFormat(YAML::Flow);
  out << node;
  std::string text = out.c_str();
  return text.size() > 60 ? text.substr(0, 57) + "..." : text;
}

// Plain (unquoted) scalars only: `wn: "2"` is a string, not a number. The whole
// scalar must be consumed, so `2 rad/s` is rejected rather than read as 2.
template <typename T>
bool parse_plain(const YAML::Node& node, T& value) {
  if (!node.IsScalar() || node.Tag() == "!") return false;
  std::string_view s = node.Scalar();
  if (s.size() > 1 && s.front() == '+' && s[1] != '-') s.remove_prefix(1);  // from_chars rejects '+'
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
  return !s.empty() && ec == std::errc() && ptr == s.data() + s.size();
}

// One node of the document with its place: the file, the 1-based line and
// the dotted key path (`model.submodels[2].zeta`).
class Value {
 public:
  Value(const std::string& source, YAML::Node node, std::string path, int line)
      : source_(&source), node_(std::move(node)), path_(std::move(path)), line_(line) {}

  const YAML::Node& node() const { return node_; }
  const std::string& path() const { return path_; }
  const std::string& source() const { return *source_; }
  int line() const { return line_; }

  std::string location() const {
    std::string loc = *source_ + ":" + std::to_string(line_);
    return path_.empty() ? loc : loc + ": key '" + path_ + "'";
  }
  [[noreturn]] void fail(const std::string& what) const {
    throw InputError(location(), what + " (got " + render(node_) + ")");
  }
  [[noreturn]] void fail_plain(const std::string& what) const { throw InputError(location(), what); }

  Value child(const std::string& key, YAML::Node node, int line) const {
    return Value(*source_, std::move(node), path_.empty() ? key : path_ + "." + key, line);
  }

  double number() const {
    double v = 0.0;
    if (!parse_plain(node_, v)) fail("expected a number");
    if (!std::isfinite(v)) fail("must be a finite number");
    return v;
  }
  double positive() const {
    const double v = number();
    if (!(v > 0.0)) fail("must be > 0");
    return v;
  }
  double nonzero() const {
    const double v = number();
    if (v == 0.0) fail("must be != 0");
    return v;
  }
  double at_least(double lo) const {
    const double v = number();
    if (!(v >= lo)) fail("must be >= " + format_number(lo));
    return v;
  }
  double above(double lo) const {
    const double v = number();
    if (!(v > lo)) fail("must be > " + format_number(lo));
    return v;
  }
  // Plain `true` or `false` only: YAML 1.1's yes/no/on/off are too easy to mistype.
  bool boolean() const {
    if (node_.IsScalar() && node_.Tag() != "!") {
      if (node_.Scalar() == "true") return true;
      if (node_.Scalar() == "false") return false;
    }
    fail("expected true or false");
  }
  long long integer(long long lo, long long hi) const {
    long long v = 0;
    if (!parse_plain(node_, v)) fail("expected an integer");
    if (v < lo || v > hi) {
      const bool open_ended = hi >= std::numeric_limits<int>::max();  // no useful upper bound to show
      fail(open_ended ? "must be >= " + std::to_string(lo)
                      : "must be in " + std::to_string(lo) + ".." + std::to_string(hi));
    }
    return v;
  }
  std::string text() const {
    if (!node_.IsScalar() || node_.Scalar().empty()) fail("expected a non-empty string");
    return node_.Scalar();
  }
  std::string choice(const Keys& options) const {
    const std::string s = text();
    if (std::find(options.begin(), options.end(), s) == options.end())
      fail("must be one of " + join(options));
    return s;
  }

  std::vector<Value> items() const {
    if (!node_.IsSequence()) fail("expected a list");
    std::vector<Value> out;
    for (std::size_t i = 0; i < node_.size(); ++i) {
      const YAML::Node item = node_[i];
      const int line = item.Mark().line >= 0 ? item.Mark().line + 1 : line_;
      out.emplace_back(*source_, item, path_ + "[" + std::to_string(i) + "]", line);
    }
    return out;
  }
  std::vector<double> numbers() const {
    std::vector<double> out;
    for (const auto& item : items()) out.push_back(item.number());
    return out;
  }
  std::vector<double> nonempty_numbers() const {
    std::vector<double> out = numbers();
    if (out.empty()) fail("must not be empty");
    return out;
  }

 private:
  const std::string* source_;
  YAML::Node node_;
  std::string path_;
  int line_;
};

// A YAML map whose keys are checked: duplicates and unknown keys are errors.
class Map {
 public:
  explicit Map(Value self) : self_(std::move(self)) {
    if (!self_.node().IsMap()) self_.fail("expected a map of keys");
    for (auto it = self_.node().begin(); it != self_.node().end(); ++it) add(it->first, it->second);
  }

  const Value& self() const { return self_; }

  // Rejects any key not in `allowed`; `what` says whose keys these are.
  void allow(const Keys& allowed, const std::string& what) const {
    for (const auto& [key, value] : entries_)
      if (std::find(allowed.begin(), allowed.end(), key) == allowed.end())
        value.fail_plain("unknown key" + (what.empty() ? "" : " for " + what) + " (allowed: " +
                         join(allowed) + ")");
  }

  bool has(std::string_view key) const { return find(key) != nullptr; }
  std::optional<Value> get(std::string_view key) const {
    const Value* v = find(key);
    return v ? std::optional<Value>(*v) : std::nullopt;
  }
  // A missing key is reported at the line of this map.
  Value require(std::string_view key, const std::string& why = "") const {
    if (const Value* v = find(key)) return *v;
    missing(key, why);
  }
  [[noreturn]] void missing(std::string_view key, const std::string& why) const {
    const Value place = self_.child(std::string(key), YAML::Node(), self_.line());
    place.fail_plain("missing required key" + (why.empty() ? "" : " (" + why + ")"));
  }

 private:
  void add(const YAML::Node& key, const YAML::Node& value) {
    const int key_line = key.Mark().line + 1;
    if (!key.IsScalar()) self_.child("?", key, key_line).fail("keys must be plain names");
    const std::string name = key.Scalar();
    const Value entry = self_.child(name, value, key_line);
    if (const Value* first = find(name))
      entry.fail_plain("duplicate key (first at line " + std::to_string(first->line()) + ")");
    entries_.emplace_back(name, entry);
  }
  const Value* find(std::string_view key) const {
    for (const auto& [k, v] : entries_)
      if (k == key) return &v;
    return nullptr;
  }

  Value self_;
  std::vector<std::pair<std::string, Value>> entries_;
};

double optional_number(const Map& m, std::string_view key, double fallback) {
  const auto v = m.get(key);
  return v ? v->number() : fallback;
}

// `a` or `b` but not both; `scale` converts b's unit to a's.
std::optional<double> one_of(const Map& m, std::string_view a, std::string_view b, double scale,
                             bool positive) {
  const auto va = m.get(a);
  const auto vb = m.get(b);
  if (va && vb) vb->fail_plain("give " + std::string(a) + " or " + std::string(b) + ", not both");
  if (va) return positive ? va->positive() : va->number();
  if (vb) return (positive ? vb->positive() : vb->number()) * scale;
  return std::nullopt;
}

// ---------------------------------------------------------------- submodels

struct SubmodelEntry {
  Submodel submodel;
  bool mode = false;
  ModalParameters modal;
  int line = 0;  // of the name, for duplicate-name messages
};

Submodel parse_transfer_function(const Map& m, const std::string& name, int rigid_poles) {
  const Value a_value = m.require("a", "kind transfer_function");
  const Value b_value = m.require("b", "kind transfer_function");
  const std::vector<double> a = a_value.numbers();
  const std::vector<double> b = b_value.nonempty_numbers();
  if (!a.empty() && a.back() == 0.0) a_value.fail("the last coefficient a_n must be != 0");
  const int n = static_cast<int>(a.size());
  const int mm = static_cast<int>(b.size()) - 1;
  if (mm > n + rigid_poles)
    b_value.fail("m = " + std::to_string(mm) + " (length of b - 1) exceeds n + l = " +
                 std::to_string(n) + " + " + std::to_string(rigid_poles) +
                 " (n = length of a, l = rigid_poles): improper");
  Submodel s;
  s.name = name;
  s.n = n;
  s.m = mm;
  s.rigid_poles = rigid_poles;
  s.a = Eigen::Map<const Eigen::VectorXd>(a.data(), n);
  s.b = Eigen::Map<const Eigen::VectorXd>(b.data(), mm + 1);
  return s;
}

ModalParameters parse_modal(const Map& m) {
  ModalParameters modal;
  const auto wn = one_of(m, "wn", "frequency_hz", kTwoPi, true);
  if (!wn) m.missing("wn", "kind mode needs wn or frequency_hz");
  modal.wn = *wn;
  modal.zeta = m.require("zeta", "kind mode").positive();
  modal.gain = m.require("gain", "kind mode").nonzero();
  return modal;
}

// Names become CSV column prefixes (`<name>_wn`), so they are kept to a safe alphabet.
std::string parse_name(const Value& v) {
  const std::string name = v.text();
  const auto safe = [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-'; };
  if (!std::all_of(name.begin(), name.end(), safe)) v.fail("names may contain only letters, digits, '_' and '-'");
  return name;
}

Keys submodel_keys(const std::string& kind, const Keys& extra) {
  Keys keys{"name", "kind"};
  if (kind == "mode") keys.insert(keys.end(), {"wn", "frequency_hz", "zeta", "gain", "rigid_poles"});
  if (kind == "rigid_body") keys.insert(keys.end(), {"gain", "rigid_poles"});
  if (kind == "transfer_function") keys.insert(keys.end(), {"a", "b", "rigid_poles"});
  keys.insert(keys.end(), extra.begin(), extra.end());
  return keys;
}

// A submodel of `model.submodels` or `plant.modes`; `extra` are the keys the
// caller reads itself (forgetting, trajectory).
SubmodelEntry parse_submodel(const Map& m, const Keys& extra) {
  const std::string kind = m.get("kind") ? m.get("kind")->choice({"mode", "rigid_body", "transfer_function"})
                                         : "mode";
  if (kind != "mode")
    if (const auto t = m.get("trajectory"))
      t->fail_plain("a trajectory is only allowed for kind mode (this submodel is kind " + kind + ")");
  Keys keys = submodel_keys(kind, extra);
  if (kind != "mode") keys.erase(std::remove(keys.begin(), keys.end(), "trajectory"), keys.end());
  m.allow(keys, "kind " + kind);
  SubmodelEntry e;
  const Value name_value = m.require("name");
  const std::string name = parse_name(name_value);
  e.line = name_value.line();
  const auto poles = m.get("rigid_poles");
  const int rigid_poles = poles ? static_cast<int>(poles->integer(0, 2)) : (kind == "rigid_body" ? 2 : 0);
  if (kind == "mode") {
    if (rigid_poles != 0) poles->fail("a mode has no poles at the origin; use kind transfer_function");
    e.mode = true;
    e.modal = parse_modal(m);
    e.submodel = make_mode(name, e.modal);
  } else if (kind == "rigid_body") {
    e.submodel = make_rigid_body(name, m.require("gain", "kind rigid_body").nonzero(), rigid_poles);
  } else {
    e.submodel = parse_transfer_function(m, name, rigid_poles);
  }
  return e;
}

void check_unique_names(const std::vector<Value>& items, const std::vector<SubmodelEntry>& entries) {
  std::map<std::string, int> seen;
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const auto [it, fresh] = seen.emplace(entries[i].submodel.name, entries[i].line);
    if (!fresh)
      Map(items[i]).require("name").fail("duplicate name (first used at line " +
                                         std::to_string(it->second) + ")");
  }
}

// ---------------------------------------------------------------- model

// `initial_covariance` of a submodel: the diagonal of P_i(t0), one entry per
// element of theta_i = [a_1 .. a_n, b_0 .. b_m].
Eigen::VectorXd parse_initial_covariance(const Value& v, const Submodel& s) {
  const std::vector<Value> items = v.items();
  const int nt = s.n_theta();
  if (static_cast<int>(items.size()) != nt)
    v.fail("must have n + m + 1 = " + std::to_string(s.n) + " + " + std::to_string(s.m) + " + 1 = " +
           std::to_string(nt) + " entries, one per parameter of theta = [a_1 .. a_n, b_0 .. b_m]");
  Eigen::VectorXd out(nt);
  for (int j = 0; j < nt; ++j) out(j) = items[static_cast<std::size_t>(j)].positive();
  return out;
}

void parse_model(const Map& model, Config& config) {
  model.allow({"loop", "output_hold", "submodels"}, "model");
  if (const auto loop = model.get("loop")) config.closed_loop = loop->choice({"open", "closed"}) == "closed";
  if (const auto hold = model.get("output_hold"))
    config.output_hold = hold->choice({"zoh", "foh"}) == "foh" ? Hold::foh : Hold::zoh;
  const Value list = model.require("submodels");
  const std::vector<Value> items = list.items();
  if (items.empty()) list.fail("must list at least one submodel");
  std::vector<SubmodelEntry> entries;
  for (const auto& item : items) {
    const Map m(item);
    entries.push_back(parse_submodel(m, {"forgetting", "random_walk", "initial_covariance"}));
    SubmodelSettings settings;
    if (const auto f = m.get("forgetting")) {
      settings.forgetting = f->number();
      if (!(settings.forgetting > 0.0 && settings.forgetting <= 1.0)) f->fail("must be in (0, 1]");
    }
    if (const auto q = m.get("random_walk")) settings.random_walk = q->at_least(0.0);
    const auto cov = m.get("initial_covariance");
    config.estimator.initial_covariance.push_back(
        cov ? parse_initial_covariance(*cov, entries.back().submodel) : Eigen::VectorXd());
    config.model.submodels.push_back(entries.back().submodel);
    config.submodel_settings.push_back(settings);
  }
  check_unique_names(items, entries);
}

DiscreteTransferFunction parse_controller(const Map& c) {
  c.allow({"numerator", "denominator"}, "controller");
  const Value num_value = c.require("numerator");
  const Value den_value = c.require("denominator");
  std::vector<double> num = num_value.nonempty_numbers();
  std::vector<double> den = den_value.nonempty_numbers();
  if (den.front() == 0.0) den_value.fail("the leading coefficient must be != 0");
  if (num.size() > den.size())
    num_value.fail("improper controller: numerator degree " + std::to_string(num.size() - 1) +
                   " exceeds denominator degree " + std::to_string(den.size() - 1));
  try {
    return DiscreteTransferFunction(std::move(num), std::move(den));
  } catch (const std::invalid_argument& e) {
    c.self().fail_plain(e.what());
  }
}

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

PlantSpec parse_plant(const Map& plant) {
  plant.allow({"modes", "noise_variance", "snr_db", "output_offset", "input_offset", "input_delay", "coulomb", "cubic"},
              "plant");
  PlantSpec spec;
  const Value list = plant.require("modes");
  const std::vector<Value> items = list.items();
  if (items.empty()) list.fail("must list at least one mode");
  std::vector<SubmodelEntry> entries;
  for (const auto& item : items) {
    const Map m(item);
    entries.push_back(parse_submodel(m, {"trajectory"}));
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

// ---------------------------------------------------------------- signals

// What a signal needs besides its own keys.
struct SignalContext {
  double sample_time = 0.0;
  Eigen::Index samples = 0;
  std::uint64_t seed = 1;
  std::filesystem::path directory;  // of the config file, for relative csv paths
  const SignalFileReader* read_file = nullptr;  // null: CSV only
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
      phases->fail("must have as many entries as amplitudes (" + std::to_string(s.amplitudes.size()) +
                   ")");
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
Eigen::VectorXd interpolate(const Value& where, const Eigen::VectorXd& t, const Eigen::VectorXd& x,
                            double T, Eigen::Index n) {
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
    if (ctx.read_file && *ctx.read_file) {
      table = (*ctx.read_file)(s.csv_path, s.csv_channel);
    } else {
      if (channel) channel->fail("applies to LCM logs, which this program does not read (the modalwatch CLI does)");
      table = read_table(s.csv_path);
    }
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
      path.fail_plain(s.csv_path + ": row " + std::to_string(k + 2) +
                      ", column 't': time does not increase");
  return interpolate(path, t, table.data.col(xc), ctx.sample_time, ctx.samples);
}

// Fills experiment.excitation (and excitation_samples for csv).
void parse_signal(const Value& v, const SignalContext& ctx, ExperimentSpec& experiment) {
  const Map m(v);
  const std::string type = m.require("type").choice({"sum_of_sines", "multisine", "prbs", "square", "csv"});
  SignalSpec& s = experiment.excitation;
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
    experiment.excitation_samples = parse_csv_signal(m, s, ctx);
  }
}

// ---------------------------------------------------------------- simulation

ExperimentSpec parse_simulation(const Map& sim, const Config& config, const std::filesystem::path& dir,
                                const SignalFileReader& read_file) {
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
    extra->fail_plain("not used when model.loop is " + loop + " (the excitation is simulation." + used +
                      ")");
  const SignalContext ctx{e.sample_time, static_cast<Eigen::Index>(samples), e.seed, dir, &read_file};
  parse_signal(sim.require(used, "model.loop is " + loop), ctx, e);
  return e;
}

// ---------------------------------------------------------------- estimator

// The `estimator:` keys; every one is optional and defaults to EstimatorSettings'.
void parse_estimator(const Map& est, double sample_time, EstimatorSettings& e) {
  est.allow({"block_iterations", "refinements", "update_divisor", "warmup", "fit_on_warmup",
             "warmup_iterations", "initial_covariance_relative", "random_walk", "covariance_bound",
             "divergence_ratio", "gap_factor", "outlier_sigma", "residual_window", "low_excitation_ratio",
             "low_excitation_window"},
            "estimator");
  constexpr long long kIntMax = std::numeric_limits<int>::max();
  const auto count = [&](std::string_view key, long long lo, int& out) {
    if (const auto v = est.get(key)) out = static_cast<int>(v->integer(lo, kIntMax));
  };
  count("block_iterations", 1, e.block_iterations);
  count("refinements", 0, e.refinements);
  count("update_divisor", 1, e.update_divisor);
  count("warmup_iterations", 1, e.warmup_iterations);
  if (const auto w = est.get("warmup")) {
    const double seconds = w->at_least(0.0);
    const double samples = std::round(seconds / sample_time);
    if (seconds > 0.0 && samples < 1.0) w->fail("shorter than one sample period (use 0 for no warm-up)");
    if (samples > static_cast<double>(kIntMax)) w->fail("too long: more than " + std::to_string(kIntMax) + " samples");
    e.warmup_samples = static_cast<int>(samples);
  }
  if (const auto v = est.get("fit_on_warmup")) e.fit_on_warmup = v->boolean();
  if (const auto v = est.get("initial_covariance_relative")) e.initial_covariance_relative = v->positive();
  if (const auto v = est.get("random_walk")) e.random_walk = v->at_least(0.0);
  if (const auto v = est.get("covariance_bound")) e.covariance_bound = v->above(1.0);
  if (const auto v = est.get("divergence_ratio")) e.divergence_ratio = v->above(1.0);
  if (const auto v = est.get("gap_factor")) e.gap_factor = v->above(1.0);
  if (const auto v = est.get("outlier_sigma")) e.outlier_sigma = v->positive();
  if (const auto v = est.get("residual_window")) e.residual_window = v->at_least(0.0);
  if (const auto v = est.get("low_excitation_ratio")) {
    e.low_excitation_ratio = v->number();
    if (!(e.low_excitation_ratio >= 0.0 && e.low_excitation_ratio < 1.0)) v->fail("must be in [0, 1)");
  }
  if (const auto v = est.get("low_excitation_window")) e.low_excitation_window = v->at_least(0.0);
}

void parse_lcm(const Map& m, LcmSettings& lcm) {
  m.allow({"url", "channels"}, "lcm");
  if (const auto v = m.get("url")) {
    lcm.url = v->text();
    if (lcm.url.find("://") == std::string::npos)
      v->fail("expected an LCM URL such as udpm://239.255.76.67:7667?ttl=0 or memq://");
  }
  if (const auto c = m.get("channels")) {
    const Map ch(*c);
    ch.allow({"samples", "batches", "estimates", "fault_status", "heartbeat"}, "lcm.channels");
    const std::pair<const char*, std::string*> names[] = {
        {"samples", &lcm.samples_channel},     {"batches", &lcm.batches_channel},
        {"estimates", &lcm.estimates_channel}, {"fault_status", &lcm.fault_status_channel},
        {"heartbeat", &lcm.heartbeat_channel}};
    for (const auto& [key, out] : names)
      if (const auto v = ch.get(key)) *out = v->text();
    // One channel for two purposes would feed the daemon its own output.
    for (std::size_t i = 0; i < std::size(names); ++i)
      for (std::size_t j = i + 1; j < std::size(names); ++j)
        if (*names[i].second == *names[j].second)
          (ch.get(names[j].first) ? *ch.get(names[j].first) : ch.self())
              .fail("channel '" + *names[j].second + "' is also lcm.channels." + names[i].first);
  }
}


// ---------------------------------------------------------------- daemon

void parse_daemon(const Map& d, Config& config, const std::filesystem::path& dir, bool gap_factor_given) {
  d.allow({"loop_rate_hz", "publish_period", "heartbeat_period", "gap_time", "stale_time", "sample_ring",
           "snapshot_ring", "warmup_backlog", "realtime_priority", "checkpoint", "log_level"},
          "daemon");
  DaemonSettings& s = config.daemon;
  if (const auto v = d.get("loop_rate_hz")) {
    s.loop_rate_hz = v->positive();
    if (s.loop_rate_hz > 100000.0) v->fail("must be <= 100000 (a tick shorter than 10 us is a busy loop)");
  }
  if (const auto v = d.get("publish_period")) {
    s.publish_period = v->positive();
    if (s.publish_period < config.sample_time) v->fail("must be at least one sample period");
  }
  if (const auto v = d.get("heartbeat_period")) s.heartbeat_period = v->positive();
  if (const auto v = d.get("gap_time")) {
    if (gap_factor_given) v->fail_plain("give daemon.gap_time or estimator.gap_factor, not both");
    const double gap = v->positive();
    if (!(gap > config.sample_time)) v->fail("must exceed the sample period " + format_number(config.sample_time) + " s");
    config.estimator.gap_factor = gap / config.sample_time;
  }
  if (const auto v = d.get("stale_time")) s.stale_time = v->positive();
  constexpr long long kRingMax = 1LL << 24;
  if (const auto v = d.get("sample_ring")) s.sample_ring = static_cast<int>(v->integer(16, kRingMax));
  if (const auto v = d.get("snapshot_ring")) s.snapshot_ring = static_cast<int>(v->integer(2, 65536));
  if (const auto v = d.get("warmup_backlog")) {
    s.warmup_backlog = v->positive();
    if (s.warmup_backlog / config.sample_time > static_cast<double>(kRingMax))
      v->fail("must hold at most " + std::to_string(kRingMax) + " samples (" +
              format_number(std::floor(static_cast<double>(kRingMax) * config.sample_time)) + " s at this sample rate)");
  }
  if (const auto v = d.get("realtime_priority")) s.realtime_priority = static_cast<int>(v->integer(0, 99));
  if (const auto c = d.get("checkpoint")) {
    const Map m(*c);
    m.allow({"path", "period"}, "daemon.checkpoint");
    const Value path = m.require("path");
    const std::filesystem::path file(path.text());
    s.checkpoint_path = (file.is_absolute() ? file : dir / file).lexically_normal().string();
    if (const auto p = m.get("period")) s.checkpoint_period = p->positive();
  }
  if (const auto v = d.get("log_level"))
    s.log_level = v->choice({"trace", "debug", "info", "warn", "error", "critical", "off"});
}

// ---------------------------------------------------------------- faults

void parse_thresholds(const Map& m, FaultThresholds& th) {
  m.allow({"sigma", "relative", "hold", "clear_fraction", "clear_time"}, "thresholds");
  if (const auto v = m.get("sigma")) th.sigma_threshold = v->positive();
  if (const auto v = m.get("relative")) th.relative_threshold = v->positive();
  if (const auto v = m.get("hold")) th.hold_time = v->at_least(0.0);
  if (const auto v = m.get("clear_fraction")) {
    th.clear_fraction = v->number();
    if (!(th.clear_fraction > 0.0 && th.clear_fraction < 1.0)) v->fail("must be in (0, 1)");
  }
  if (const auto v = m.get("clear_time")) th.clear_time = v->at_least(0.0);
}

void parse_faults(const Map& f, Config& config) {
  f.allow({"learn_window", "wn", "zeta", "gain", "baselines"}, "faults");
  FaultSettings& s = config.faults;
  if (const auto v = f.get("learn_window")) s.learn_window = v->positive();
  const char* names[kQuantities] = {"wn", "zeta", "gain"};
  for (int q = 0; q < kQuantities; ++q)
    if (const auto v = f.get(names[q])) parse_thresholds(Map(*v), s.thresholds[static_cast<std::size_t>(q)]);
  if (const auto b = f.get("baselines")) {
    const Map m(*b);
    Keys modes;
    for (const auto& sub : config.model.submodels)
      if (sub.is_mode()) modes.push_back(sub.name);
    m.allow(modes, "faults.baselines (the model's modes)");
    for (std::size_t i = 0; i < config.model.submodels.size(); ++i)
      if (const auto v = m.get(config.model.submodels[i].name)) {
        const Map mode(*v);
        mode.allow({"wn", "frequency_hz", "zeta", "gain"}, "a baseline");
        s.baselines[i] = parse_modal(mode);
      }
  }
}

// ---------------------------------------------------------------- document

void parse_document(const Map& top, Config& config, const std::filesystem::path& dir,
                    const SignalFileReader& read_file) {
  top.allow({"sample_rate_hz", "model", "controller", "plant", "simulation", "estimator", "lcm", "daemon",
             "faults"},
            "");
  config.sample_time = 1.0 / top.require("sample_rate_hz").positive();
  parse_model(Map(top.require("model")), config);
  if (const auto c = top.get("controller")) config.controller = parse_controller(Map(*c));
  if (config.closed_loop && !top.has("controller"))
    top.missing("controller", "model.loop is closed");
  if (const auto p = top.get("plant")) config.plant = parse_plant(Map(*p));
  if (const auto s = top.get("simulation")) config.experiment = parse_simulation(Map(*s), config, dir, read_file);
  if (const auto e = top.get("estimator")) parse_estimator(Map(*e), config.sample_time, config.estimator);
  if (const auto l = top.get("lcm")) parse_lcm(Map(*l), config.lcm);
  const bool gap_factor_given = top.get("estimator") && Map(*top.get("estimator")).has("gap_factor");
  if (const auto d = top.get("daemon")) parse_daemon(Map(*d), config, dir, gap_factor_given);
  config.faults.baselines.assign(config.model.submodels.size(), std::nullopt);
  if (const auto f = top.get("faults")) parse_faults(Map(*f), config);
}

// The estimator settings that the other sections determine (the `estimator:`
// section and the submodels' initial_covariance are already in place).
void complete_estimator(Config& config) {
  EstimatorSettings& e = config.estimator;
  e.sample_time = config.sample_time;
  e.closed_loop = config.closed_loop;
  e.controller = config.controller;
  e.output_hold = config.output_hold;
  e.forgetting.clear();
  for (const auto& s : config.submodel_settings) e.forgetting.push_back(s.forgetting);
  e.random_walks.clear();
  for (const auto& s : config.submodel_settings) e.random_walks.push_back(s.random_walk.value_or(e.random_walk));
}

YAML::Node load_yaml(const std::string& text, const std::string& source) {
  try {
    return YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw InputError(source + ":" + std::to_string(e.mark.line + 1), "YAML syntax error: " + e.msg);
  }
}

}  // namespace

Config parse_config(const std::string& yaml_text, const std::string& source_name,
                    const SignalFileReader& read_signal_file) {
  const YAML::Node root = load_yaml(yaml_text, source_name);
  if (!root.IsDefined() || root.IsNull())
    throw InputError(source_name + ":1", "empty configuration (expected keys sample_rate_hz and model)");
  const int line = root.Mark().line >= 0 ? root.Mark().line + 1 : 1;
  Config config;
  config.source = source_name;
  const Map top(Value(source_name, root, "", line));
  parse_document(top, config, std::filesystem::path(source_name).parent_path(), read_signal_file);
  complete_estimator(config);
  return config;
}

Config load_config(const std::string& path, const SignalFileReader& read_signal_file) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, std::string("cannot open: ") + std::strerror(errno));
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw InputError(path, "cannot read");
  return parse_config(text.str(), path, read_signal_file);
}

// ---------------------------------------------------------------- writing

namespace {

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

std::string points(const Trajectory& traj) {
  std::string out = "[";
  for (const auto& [t, v] : traj.points)
    (out += out.size() > 1 ? ", " : "") += "[" + format_number(t) + ", " + format_number(v) + "]";
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
  return std::isfinite(p.wn) && p.wn > 0 && std::isfinite(p.zeta) && p.zeta > 0 && std::isfinite(p.gain) &&
         p.gain != 0;
}

// The keys of a submodel after `- name:`; list items are written at `indent`.
void write_submodel(YamlWriter& w, int indent, const Submodel& s) {
  w.key(indent, "- name", quoted(s.name));
  const int in = indent + 1;
  const ModalParameters modal = s.is_mode() ? modal_parameters(s) : ModalParameters{};
  if (s.is_mode() && valid_modal(modal)) {
    w.key(in, "kind", "mode");
    w.number(in, "wn", modal.wn);
    w.number(in, "zeta", modal.zeta);
    w.number(in, "gain", modal.gain);
  } else if (s.n == 0 && s.m == 0 && s.b.size() == 1 && s.b(0) != 0.0) {
    w.key(in, "kind", "rigid_body");
    w.number(in, "gain", s.b(0));
    w.key(in, "rigid_poles", std::to_string(s.rigid_poles));
  } else {
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
  w.key(1, "output_hold", config.output_hold == Hold::foh ? "foh" : "zoh");
  w.line(1, "submodels:");
  const auto& covariances = config.estimator.initial_covariance;
  for (std::size_t i = 0; i < model.submodels.size(); ++i) {
    const Submodel& s = model.submodels[i];
    const std::size_t c = configured_index(config, s.name, i);
    write_submodel(w, 2, s);
    w.number(3, "forgetting", c < config.submodel_settings.size() ? config.submodel_settings[c].forgetting : 1.0);
    if (c < config.submodel_settings.size() && config.submodel_settings[c].random_walk)
      w.number(3, "random_walk", *config.submodel_settings[c].random_walk);
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

void write_plant(YamlWriter& w, const PlantSpec& plant) {
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
      continue;
    }
    w.key(2, "- name", quoted(mode.submodel.name));
    w.key(3, "kind", "mode");
    w.number(3, "wn", mode.modal.wn);
    w.number(3, "zeta", mode.modal.zeta);
    w.number(3, "gain", mode.modal.gain);
    if (mode.wn.points.empty() && mode.zeta.points.empty() && mode.gain.points.empty()) continue;
    w.line(3, "trajectory:");
    if (!mode.wn.points.empty()) w.key(4, "wn", points(mode.wn));
    if (!mode.zeta.points.empty()) w.key(4, "zeta", points(mode.zeta));
    if (!mode.gain.points.empty()) w.key(4, "gain", points(mode.gain));
  }
}

void write_signal(YamlWriter& w, int in, const SignalSpec& s) {
  switch (s.kind) {
    case SignalSpec::Kind::sum_of_sines:
      w.key(in, "type", "sum_of_sines");
      w.key(in, "amplitudes", flow_list(s.amplitudes));
      w.key(in, "frequencies_rad_s", flow_list(s.frequencies_rad_s));
      if (!s.phases.empty()) w.key(in, "phases", flow_list(s.phases));
      break;
    case SignalSpec::Kind::multisine:
      w.key(in, "type", "multisine");
      w.number(in, "f_min_hz", s.f_min_hz);
      w.number(in, "f_max_hz", s.f_max_hz);
      w.number(in, "period_s", s.period_s);
      w.number(in, "rms", s.rms);
      break;
    case SignalSpec::Kind::prbs:
      w.key(in, "type", "prbs");
      w.key(in, "register_bits", std::to_string(s.register_bits));
      w.key(in, "clock_period", std::to_string(s.clock_period));
      w.number(in, "amplitude", s.amplitude);
      break;
    case SignalSpec::Kind::square:
      w.key(in, "type", "square");
      w.number(in, "frequency_hz", s.frequency_hz);
      w.number(in, "amplitude", s.amplitude);
      w.number(in, "offset", s.offset);
      break;
    case SignalSpec::Kind::csv:
      w.key(in, "type", "csv");
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
  w.number(1, "divergence_ratio", e.divergence_ratio);
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
}

void write_faults(YamlWriter& w, const FaultSettings& f, const AdditiveModel& model) {
  w.line(0, "faults:");
  w.number(1, "learn_window", f.learn_window);
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
  }
}

void write_simulation(YamlWriter& w, const ExperimentSpec& e) {
  w.line(0, "simulation:");
  w.number(1, "duration", e.duration);
  w.key(1, "seed", std::to_string(e.seed));
  w.line(1, e.closed_loop ? "reference:" : "input:");
  write_signal(w, 2, e.excitation);
}

}  // namespace

std::string config_to_yaml(const Config& config, const AdditiveModel& model) {
  YamlWriter w;
  w.line(0, "# modalwatch configuration" +
                (config.source.empty() ? std::string() : ", written from " + config.source) +
                " (keys: config/README.md)");
  w.number(0, "sample_rate_hz", 1.0 / config.sample_time);
  write_model(w, config, model);
  if (!config.controller.empty()) write_controller(w, config.controller);
  if (config.plant) write_plant(w, *config.plant);
  if (config.experiment) write_simulation(w, *config.experiment);
  write_estimator(w, config.estimator, config.sample_time);
  write_lcm(w, config.lcm);
  write_daemon(w, config.daemon);
  write_faults(w, config.faults, config.model);
  return w.str();
}

}  // namespace modalwatch
