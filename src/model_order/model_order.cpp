#include "modalwatch/model_order.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace modalwatch {
namespace {

// The resonances of a fitted model, ascending in wn: once each, however many
// inputs' submodels share its A(p).
std::vector<ModalParameters> modes_of(const AdditiveModel& m) {
  std::vector<ModalParameters> out;
  for (const Submodel& s : m.submodels)
    if (s.is_resonance() && s.poles_of.empty()) out.push_back(modal_parameters(s));
  std::sort(out.begin(), out.end(), [](const ModalParameters& a, const ModalParameters& b) { return a.wn < b.wn; });
  return out;
}

std::vector<StabilisedMode> stabilise(const std::vector<ModalParameters>& modes,
                                      const std::vector<StabilisedMode>& below, const OrderOptions& o) {
  std::vector<StabilisedMode> out;
  for (const ModalParameters& p : modes) {
    StabilisedMode s{p};
    for (const StabilisedMode& q : below) {
      if (std::abs(q.modal.wn - p.wn) > o.frequency_tolerance * p.wn) continue;
      s.stable_frequency = true;
      s.stable = s.stable || std::abs(q.modal.zeta - p.zeta) <= o.damping_tolerance * p.zeta;
    }
    out.push_back(s);
  }
  return out;
}

}  // namespace

double bic_of(const FitResult& fit, double N) {
  if (fit.unstable_loop ||
      !(std::isfinite(fit.noise_variance) && fit.noise_variance > 0.0 && fit.model.beta().allFinite()))
    return std::numeric_limits<double>::infinity();
  return N * std::log(fit.noise_variance) + static_cast<double>(free_beta(fit.model).size()) * std::log(N);
}

OrderSelection select_order(const Record& data, const SrivcOptions& options, const OrderOptions& order) {
  if (order.max_modes < 1) throw std::invalid_argument("select_order: max_modes must be at least 1");
  const Eigen::Index settle = std::min<Eigen::Index>(options.settle_samples, data.size());
  const Record used = data.segment(settle, data.size() - settle);
  // One estimate serves every order.
  const FrequencyResponse h = resolving_response(used, options.closed_loop, options.input_hold);
  OrderSelection out;
  for (int k = 1; k <= order.max_modes; ++k) {
    const AdditiveModel start = initial_modes(h, k, order.peaks, order.inputs, order.output_derivatives);
    // The data show no further resonance (one submodel per input and resonance).
    if (static_cast<int>(start.submodels.size()) < k * h.inputs()) break;
    OrderFit f;
    f.modes = k;
    try {
      f.fit = fit_physical(data, start, options, f.findings, order.physical);
    } catch (const std::invalid_argument&) {
      break;  // too few samples for this many parameters
    }
    f.bic = bic_of(f.fit, static_cast<double>(used.size()));
    f.diagram = stabilise(modes_of(f.fit.model),
                          out.orders.empty() ? std::vector<StabilisedMode>{} : out.orders.back().diagram, order);
    out.orders.push_back(std::move(f));
  }
  // The lowest BIC. A fit that did not converge counts too: it returns its
  // cycle of least output error, and on a record of many lightly damped modes
  // the orders that hold them all are the ones the block-coordinate iteration
  // no longer settles.
  for (int i = 0; i < static_cast<int>(out.orders.size()); ++i) {
    const OrderFit& o = out.orders[static_cast<std::size_t>(i)];
    if (!std::isfinite(o.bic)) continue;
    if (out.chosen < 0 || o.bic < out.orders[static_cast<std::size_t>(out.chosen)].bic) out.chosen = i;
  }
  return out;
}

NonResonantStart choose_non_resonant_start(const Record& data, const FrequencyResponse& h, const SrivcOptions& options,
                                           int output_derivatives,
                                           std::vector<std::pair<std::string, double>>* fitted_bic) {
  std::vector<NonResonantStart> starts = non_resonant_starts(h, {}, output_derivatives);
  const Eigen::Index settle = std::min<Eigen::Index>(options.settle_samples, data.size());
  const double N = static_cast<double>(data.size() - settle);
  int chosen = -1;
  double least = std::numeric_limits<double>::infinity();
  for (int i = 0; i < static_cast<int>(starts.size()); ++i) {
    AdditiveModel start;
    start.submodels = {starts[static_cast<std::size_t>(i)].submodel};
    double bic = std::numeric_limits<double>::infinity();
    try {
      std::vector<ModeFinding> findings;
      bic = bic_of(fit_physical(data, start, options, findings), N);
    } catch (const std::invalid_argument&) {
      // too few samples for its parameters
    }
    if (fitted_bic) fitted_bic->emplace_back(starts[static_cast<std::size_t>(i)].structure, bic);
    if (bic < least) {
      least = bic;
      chosen = i;
    }
  }
  return chosen < 0 ? NonResonantStart{} : std::move(starts[static_cast<std::size_t>(chosen)]);
}

}  // namespace modalwatch
