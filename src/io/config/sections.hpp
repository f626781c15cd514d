#pragma once
// The section parsers of the configuration, one per top-level key, for
// config.cpp's document parser.
#include <filesystem>

#include "modalwatch/io/config.hpp"
#include "yaml_value.hpp"

namespace modalwatch::config_detail {

// A submodel as model.submodels and plant.modes give it.
struct SubmodelEntry {
  Submodel submodel;
  bool mode = false;
  ModalParameters modal;
  int line = 0;  // of the name, for duplicate-name messages
};
// A submodel entry; `extra` are the keys the caller reads itself (forgetting,
// trajectory). The submodel measures the z-th derivative of its position (model.output).
SubmodelEntry parse_submodel(const Map& m, const Keys& extra, int output_derivatives);
// A submodel's `input`: the index of one of `inputs` (model.inputs) by name,
// the first when the key is absent.
int parse_submodel_input(const Map& m, const std::vector<std::string>& inputs);
// Modal parameters (wn or frequency_hz, zeta, gain).
ModalParameters parse_modal(const Map& m);
// Names are unique within a list; `items` locate the entries in messages.
void check_unique_names(const std::vector<Value>& items, const std::vector<SubmodelEntry>& entries);

// model: (the submodels, their settings and the loop) into config.
void parse_model(const Map& model, Config& config);
DiscreteTransferFunction parse_controller(const Map& c);
// The plant is measured by the model's sensor: its modes take model.output's z.
PlantSpec parse_plant(const Map& plant, int output_derivatives, const std::vector<std::string>& inputs);
// simulation: signal files are read relative to `dir` (CSV or LCM log, records.hpp).
ExperimentSpec parse_simulation(const Map& sim, const Config& config, const std::filesystem::path& dir);
void parse_estimator(const Map& est, double sample_time, EstimatorSettings& e);
void parse_lcm(const Map& m, LcmSettings& lcm);
void parse_daemon(const Map& d, Config& config, const std::filesystem::path& dir, bool gap_factor_given);
void parse_faults(const Map& f, Config& config);

}  // namespace modalwatch::config_detail
