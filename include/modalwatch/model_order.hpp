#pragma once
// The number of modes from the data. Fits of 1, 2, ... modes, each started
// from that many of the most prominent resonances of the frequency response
// estimate (initial_modes.hpp) and made physical (physical.hpp), are compared
// by the Bayesian information criterion
//
//   BIC = N ln(sigma^2) + k ln N     (sigma^2 the output error's variance, k free parameters)
//
// and drawn as the stabilisation diagram of modal analysis: per order the modes
// found, each marked stable when the order below has a mode within
// frequency_tolerance in frequency and damping_tolerance in damping (relative).
// A physical mode stays put as orders grow; a mode the noise or a neighbour
// made moves from order to order.
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "modalwatch/initial_modes.hpp"
#include "modalwatch/model.hpp"
#include "modalwatch/physical.hpp"
#include "modalwatch/record.hpp"
#include "modalwatch/srivc.hpp"

namespace modalwatch {

struct OrderOptions {
  int max_modes = 8;
  double frequency_tolerance = 0.01;  // the usual limits of a stabilisation diagram
  double damping_tolerance = 0.05;
  PeakOptions peaks;
  PhysicalOptions physical;
  // Several inputs in the record: their names (initial_modes), one submodel per input and mode.
  std::vector<std::string> inputs;
  // What the sensor measures: the z-th derivative of the position (Submodel::output_derivatives).
  int output_derivatives = 0;
};

struct StabilisedMode {
  ModalParameters modal;
  bool stable_frequency = false;  // the order below has a mode within frequency_tolerance
  bool stable = false;            // that mode is also within damping_tolerance in zeta
};

struct OrderFit {
  int modes = 0;  // asked for: the start's resonance peaks
  FitResult fit;
  std::vector<ModeFinding> findings;  // what the physical check corrected
  double bic = std::numeric_limits<double>::infinity();
  std::vector<StabilisedMode> diagram;  // the fitted model's modes, ascending in wn
};

struct OrderSelection {
  // 1, 2, ... modes, up to max_modes; fewer when the data show fewer resonance
  // peaks or a fit fails (a record too short for the parameters).
  std::vector<OrderFit> orders;
  // Index into orders of the lowest BIC (a fit that did not converge counts
  // with its cycle of least output error when options.best_cycle is set); -1
  // when no fit has a finite BIC.
  int chosen = -1;
};

// A fit's Bayesian information criterion over N samples, N ln(sigma^2) +
// k ln N with sigma^2 its output error's variance and k its free parameters
// (a shared A(p) counts once); infinite for a failed fit and for one that
// makes the loop with the controller diverge (its output error then says
// nothing about the plant).
double bic_of(const FitResult& fit, double N);

// The fits use `options` (loop, controller, hold, settle_samples); the peaks
// are taken from the record after options.settle_samples. Throws
// std::invalid_argument when max_modes < 1.
OrderSelection select_order(const Record& data, const SrivcOptions& options, const OrderOptions& order = {});

// A record whose frequency response shows no resonance peak: each structure of
// non_resonant_starts (h the record's estimate) fitted with `options` and made
// physical, and the start whose fit has the least BIC. The estimate alone
// does not tell the structures apart where it is poor: a step's energy lies
// below the first bins of a Welch estimate, whose Hann windows over the step
// make them. `fitted_bic` holds each structure's BIC, closest first as
// non_resonant_starts orders them (infinite for a fit that failed); the
// returned start's structure is empty when there is none.
NonResonantStart choose_non_resonant_start(const Record& data, const FrequencyResponse& h, const SrivcOptions& options,
                                           int output_derivatives = 0,
                                           std::vector<std::pair<std::string, double>>* fitted_bic = nullptr);

}  // namespace modalwatch
