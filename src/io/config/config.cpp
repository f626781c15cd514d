// The YAML configuration (config/README.md is the specification): the document
// and its sections (sections.hpp), each key read through yaml_value.hpp so that
// a rejection names the file, the line and the key.
#include "modalwatch/io/config.hpp"

#include <yaml-cpp/yaml.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "modalwatch/error.hpp"
#include "modalwatch/srivc.hpp"
#include "sections.hpp"

namespace modalwatch {
namespace {

using namespace config_detail;

// ---------------------------------------------------------------- document

void parse_document(const Map& top, Config& config, const std::filesystem::path& dir) {
  top.allow(
      {"axis", "sample_rate_hz", "model", "controller", "plant", "simulation", "estimator", "lcm", "daemon", "faults"},
      "");
  if (const auto a = top.get("axis")) config.axis = a->text();
  config.sample_time = 1.0 / top.require("sample_rate_hz").positive();
  parse_model(Map(top.require("model")), config);
  if (const auto c = top.get("controller")) config.controller = parse_controller(Map(*c));
  if (config.closed_loop && !top.has("controller")) top.missing("controller", "model.loop is closed");
  if (const auto p = top.get("plant")) config.plant = parse_plant(Map(*p), config.output_derivatives, config.model.inputs);
  if (const auto s = top.get("simulation")) config.experiment = parse_simulation(Map(*s), config, dir);
  if (const auto e = top.get("estimator")) parse_estimator(Map(*e), config.sample_time, config.estimator);
  if (const auto l = top.get("lcm")) parse_lcm(Map(*l), config.lcm);
  const bool gap_factor_given = top.get("estimator") && Map(*top.get("estimator")).has("gap_factor");
  if (const auto d = top.get("daemon")) parse_daemon(Map(*d), config, dir, gap_factor_given);
  config.faults.baselines.assign(config.model.submodels.size(), std::nullopt);
  config.faults.baseline_std.assign(config.model.submodels.size(), std::nullopt);
  if (const auto f = top.get("faults")) parse_faults(Map(*f), config);
}

// The estimator settings that the other sections determine (the `estimator:`
// section and the submodels' initial_covariance are already in place).
void complete_estimator(Config& config) {
  EstimatorSettings& e = config.estimator;
  e.sample_time = config.sample_time;
  e.closed_loop = config.closed_loop;
  e.controller = config.controller;
  // Unset: the batch fits' rule (default_output_hold, srivc.hpp) on the configured modes.
  e.output_hold = config.output_hold.value_or(default_output_hold(config.model, config.sample_time));
  e.forgetting.clear();
  for (const auto& s : config.submodel_settings) e.forgetting.push_back(s.forgetting);
  e.random_walks.clear();
  for (const auto& s : config.submodel_settings) e.random_walks.push_back(s.random_walk.value_or(e.random_walk));
  e.stabilisations.clear();
  for (const auto& s : config.submodel_settings) e.stabilisations.push_back(s.stabilisation.value_or(e.stabilisation));
  e.min_memories.clear();
  for (const auto& s : config.submodel_settings) e.min_memories.push_back(s.min_memory.value_or(e.min_memory));
}

YAML::Node load_yaml(const std::string& text, const std::string& source) {
  try {
    return YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw InputError(source + ":" + std::to_string(e.mark.line + 1), "YAML syntax error: " + e.msg);
  }
}

}  // namespace

Config parse_config(const std::string& yaml_text, const std::string& source_name) {
  const YAML::Node root = load_yaml(yaml_text, source_name);
  if (!root.IsDefined() || root.IsNull())
    throw InputError(source_name + ":1", "empty configuration (expected keys sample_rate_hz and model)");
  const int line = root.Mark().line >= 0 ? root.Mark().line + 1 : 1;
  Config config;
  config.source = source_name;
  config.axis = std::filesystem::path(source_name).stem().string();
  const Map top(Value(source_name, root, "", line));
  parse_document(top, config, std::filesystem::path(source_name).parent_path());
  complete_estimator(config);
  return config;
}

Config load_config(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, std::string("cannot open: ") + std::strerror(errno));
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw InputError(path, "cannot read");
  return parse_config(text.str(), path);
}

}  // namespace modalwatch
