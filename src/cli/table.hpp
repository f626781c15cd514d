#pragma once
// The modal table that `fit` and `track` print: per submodel its frequency (Hz,
// rad/s), damping and gain with standard deviations, or for rigid bodies and
// general transfer functions their coefficients and resonances; and the
// warnings of `fit` and `diagnose` about submodels that are no physical mode;
// their starting modes from the data and the output hold of their fits.
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "modalwatch/io/config.hpp"
#include "modalwatch/model.hpp"
#include "modalwatch/physical.hpp"

namespace modalwatch::cli {

// covariances[i]: covariance of theta_i in physical units (zeros when unknown).
// in_samples: the record counts samples, not seconds (frequencies per sample).
void print_modal_table(const AdditiveModel& model, const std::vector<Eigen::MatrixXd>& covariances,
                       bool in_samples = false);

// One WARNING line per finding (verdicts other than physical), naming the submodel.
void print_physical_findings(const std::vector<ModeFinding>& findings);

// The starting modes that `fit --modes` and `diagnose --modes` take from the
// data (initial_modes.hpp), with a warning when the data show fewer than asked.
// Throws InputError (naming `data`) when they show none. With several inputs
// in the record each mode is one submodel per input, the model's inputs named
// `inputs`.
// `output_derivatives`: what the sensor measures (output_kind below); `fit`:
// the loop, controller and holds of the fit that follows (its settle_samples
// ignored: `data` is the part the fit estimates from), which also fits each
// non-resonant structure when the data show no resonance peak.
AdditiveModel modes_from_data(const Record& data, int count, const SrivcOptions& fit, const std::string& data_name,
                              bool in_samples, const std::vector<std::string>& inputs = {}, int output_derivatives = 0);

// `fit` with one mode from the data on one input: the estimate's peak need
// not be a resonance (a closed loop's own peak over a rigid body with
// friction). When the peak's mode, fitted (`peak`), makes the loop diverge,
// `start` becomes the non-resonant structure of least BIC, fitted with `fit`
// on `data` (after fit.settle_samples); when the mode needed a stability
// projection, that structure only if its BIC is less than the mode's. Prints
// a warning with the BICs and returns true when `start` changed. `diagnose`
// keeps the peak: its output-error refinement takes the mode where the data
// say (an overdamped pair for a rigid body with viscous friction).
bool non_resonant_instead(const Record& data, const FitResult& peak, const SrivcOptions& fit, bool in_samples,
                          int output_derivatives, AdditiveModel& start);

// What the sensor measures as z (Submodel::output_derivatives): `--output`
// when given, else model.output. `--output` is for modes started from the data
// (`from_data`); configured submodels keep model.output, and an `--output`
// that contradicts them is an InputError.
int output_kind(const Config& config, const std::optional<std::string>& option, bool from_data);

// The output hold that `fit` and `diagnose` assume: model.output_hold when
// given, else default_output_hold of the start (srivc.hpp), with a line saying
// so when that is foh.
Hold output_hold(const Config& config, const AdditiveModel& start, double sample_time);

}  // namespace modalwatch::cli
