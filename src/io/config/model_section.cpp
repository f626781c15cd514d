// The model: section (submodels, initial covariances, the loop), the
// controller: section, and the submodel entries that plant: shares.
#include "sections.hpp"

#include "modalwatch/polynomial.hpp"
#include "modalwatch/record.hpp"

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

namespace modalwatch::config_detail {

namespace {

Submodel parse_transfer_function(const Map& m, const std::string& name, int rigid_poles, int output_derivatives) {
  const Value a_value = m.require("a", "kind transfer_function");
  const Value b_value = m.require("b", "kind transfer_function");
  const std::vector<double> a = a_value.numbers();
  const std::vector<double> b = b_value.nonempty_numbers();
  if (!a.empty() && a.back() == 0.0) a_value.fail("the last coefficient a_n must be != 0");
  // A model names the plant's mechanics: an unstable A is an estimate to be
  // projected (fit, diagnose), never a model to track.
  if (is_unstable(Eigen::Map<const Eigen::VectorXd>(a.data(), static_cast<Eigen::Index>(a.size()))))
    a_value.fail("A(p) = 1 + a_1 p + ... + a_n p^n has a root in the right half plane (unstable)");
  const int n = static_cast<int>(a.size());
  const int mm = static_cast<int>(b.size()) - 1;
  if (mm > n + rigid_poles)
    b_value.fail("m = " + std::to_string(mm) + " (length of b - 1) exceeds n + l = " + std::to_string(n) + " + " +
                 std::to_string(rigid_poles) + " (n = length of a, l = rigid_poles): improper");
  if (mm + output_derivatives > n + rigid_poles)
    b_value.fail("m + z = " + std::to_string(mm) + " + " + std::to_string(output_derivatives) + " exceeds n + l = " +
                 std::to_string(n) + " + " + std::to_string(rigid_poles) + ": p^z B / (p^l A) is improper for model.output " +
                 output_kind_name(output_derivatives));
  Submodel s;
  s.name = name;
  s.output_derivatives = output_derivatives;
  s.n = n;
  s.m = mm;
  s.rigid_poles = rigid_poles;
  s.a = Eigen::Map<const Eigen::VectorXd>(a.data(), n);
  s.b = Eigen::Map<const Eigen::VectorXd>(b.data(), mm + 1);
  return s;
}

}  // namespace

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
namespace {

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
  if (kind == "feedthrough") keys.insert(keys.end(), {"gain"});
  if (kind == "transfer_function") keys.insert(keys.end(), {"a", "b", "rigid_poles"});
  keys.insert(keys.end(), extra.begin(), extra.end());
  return keys;
}

}  // namespace

SubmodelEntry parse_submodel(const Map& m, const Keys& extra, int output_derivatives) {
  const std::string kind = m.get("kind") ? m.get("kind")->choice({"mode", "rigid_body", "feedthrough", "transfer_function"}) : "mode";
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
    e.submodel = make_mode(name, e.modal, output_derivatives);
  } else if (kind == "rigid_body") {
    if (rigid_poles < output_derivatives)
      (poles ? *poles : m.self())
          .fail("a rigid body b0 / p^" + std::to_string(rigid_poles) + " measured as " +
                output_kind_name(output_derivatives) + " is improper (rigid_poles >= " +
                std::to_string(output_derivatives) + ")");
    e.submodel =
        make_rigid_body(name, m.require("gain", "kind rigid_body").nonzero(), rigid_poles, output_derivatives);
  } else if (kind == "feedthrough") {
    // A constant measured response: with a derivative output, the rigid body
    // b0 / p^z (an accelerometer sees a rigid body's acceleration b0 u).
    e.submodel = make_rigid_body(name, m.require("gain", "kind feedthrough").nonzero(), output_derivatives,
                                 output_derivatives);
  } else {
    e.submodel = parse_transfer_function(m, name, rigid_poles, output_derivatives);
  }
  return e;
}

void check_unique_names(const std::vector<Value>& items, const std::vector<SubmodelEntry>& entries) {
  std::map<std::string, int> seen;
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const auto [it, fresh] = seen.emplace(entries[i].submodel.name, entries[i].line);
    if (!fresh)
      Map(items[i]).require("name").fail("duplicate name (first used at line " + std::to_string(it->second) + ")");
  }
}

// ---------------------------------------------------------------- model

// `initial_covariance` of a submodel: the diagonal of P_i(t0), one entry per
// element of theta_i = [a_1 .. a_n, b_0 .. b_m].
namespace {

Eigen::VectorXd parse_initial_covariance(const Value& v, const Submodel& s) {
  const std::vector<Value> items = v.items();
  const int nt = s.n_theta();
  if (static_cast<int>(items.size()) != nt)
    v.fail("must have n + m + 1 = " + std::to_string(s.n) + " + " + std::to_string(s.m) +
           " + 1 = " + std::to_string(nt) + " entries, one per parameter of theta = [a_1 .. a_n, b_0 .. b_m]");
  Eigen::VectorXd out(nt);
  for (int j = 0; j < nt; ++j) out(j) = items[static_cast<std::size_t>(j)].positive();
  return out;
}

}  // namespace

// `model.inputs`: the names of the measured inputs (record columns), unique;
// a closed loop has the controller's one input.
namespace {

std::vector<std::string> parse_inputs(const Value& v, bool closed_loop) {
  const std::vector<Value> items = v.items();
  if (items.empty()) v.fail("must list at least one input column");
  std::vector<std::string> names;
  for (const Value& item : items) {
    const std::string name = item.text();
    if (std::find(names.begin(), names.end(), name) != names.end()) item.fail("duplicate input name");
    names.push_back(name);
  }
  if (closed_loop && names.size() > 1)
    v.fail("a closed loop has one input (the controller's u); several inputs need loop: open");
  if (names.size() > static_cast<std::size_t>(kMaxInputs))
    v.fail("at most " + std::to_string(kMaxInputs) + " inputs (what a sample of track and the daemon carries)");
  return names;
}

}  // namespace

int parse_submodel_input(const Map& m, const std::vector<std::string>& inputs) {
  const auto v = m.get("input");
  if (!v) return 0;
  if (inputs.empty()) v->fail("names an input, but model.inputs does not list the input columns");
  const std::string name = v->text();
  const auto it = std::find(inputs.begin(), inputs.end(), name);
  if (it == inputs.end()) {
    std::string listed;
    for (const auto& i : inputs) listed += (listed.empty() ? "" : ", ") + i;
    v->fail("must be one of model.inputs (" + listed + ")");
  }
  return static_cast<int>(it - inputs.begin());
}

void parse_model(const Map& model, Config& config) {
  model.allow({"loop", "output", "output_hold", "inputs", "submodels", "modes"}, "model");
  if (const auto loop = model.get("loop")) config.closed_loop = loop->choice({"open", "closed"}) == "closed";
  if (const auto output = model.get("output"))
    config.output_derivatives = *output_derivatives_of(output->choice({"position", "velocity", "acceleration"}));
  if (const auto hold = model.get("output_hold"))
    config.output_hold = hold->choice({"zoh", "foh"}) == "foh" ? Hold::foh : Hold::zoh;
  if (const auto inputs = model.get("inputs")) config.model.inputs = parse_inputs(*inputs, config.closed_loop);
  if (const auto modes = model.get("modes")) {
    if (model.get("submodels"))
      modes->fail("give submodels (initial modes) or modes (a count to start from the data), not both");
    config.model_modes = static_cast<int>(modes->integer(1, 64));
    return;
  }
  const Value list = model.require("submodels", "or modes: N to start N modes from the data");
  const std::vector<Value> items = list.items();
  if (items.empty()) list.fail("must list at least one submodel");
  std::vector<SubmodelEntry> entries;
  std::vector<Value> poles_of;  // the keys, for an error on their line
  for (const auto& item : items) {
    const Map m(item);
    entries.push_back(parse_submodel(
        m, {"input", "poles_of", "forgetting", "random_walk", "stabilisation", "min_memory", "initial_covariance"},
        config.output_derivatives));
    entries.back().submodel.input = parse_submodel_input(m, config.model.inputs);
    if (const auto p = m.get("poles_of")) {
      poles_of.push_back(*p);
      entries.back().submodel.poles_of = p->text();
    }
    SubmodelSettings settings;
    if (const auto f = m.get("forgetting")) {
      settings.forgetting = f->number();
      if (!(settings.forgetting > 0.0 && settings.forgetting <= 1.0)) f->fail("must be in (0, 1]");
    }
    if (const auto q = m.get("random_walk")) settings.random_walk = q->at_least(0.0);
    if (const auto q = m.get("stabilisation")) settings.stabilisation = q->at_least(0.0);
    if (const auto q = m.get("min_memory")) settings.min_memory = q->at_least(0.0);
    const auto cov = m.get("initial_covariance");
    config.estimator.initial_covariance.push_back(cov ? parse_initial_covariance(*cov, entries.back().submodel)
                                                      : Eigen::VectorXd());
    config.model.submodels.push_back(entries.back().submodel);
    config.submodel_settings.push_back(settings);
  }
  check_unique_names(items, entries);
  // Each poles_of names a submodel with its own poles, of the same orders, on another input.
  for (const Value& p : poles_of) {
    AdditiveModel only = config.model;
    for (auto& s : only.submodels)
      if (s.poles_of != p.text()) s.poles_of.clear();
    try {
      pole_groups(only);
    } catch (const std::invalid_argument& e) {
      p.fail(e.what());
    }
  }
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

}  // namespace modalwatch::config_detail
