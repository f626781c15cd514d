#include "table.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>

#include "modalwatch/error.hpp"
#include "modalwatch/initial_modes.hpp"
#include "modalwatch/model_order.hpp"
#include "modalwatch/srivc.hpp"
#include "record_columns.hpp"

namespace modalwatch::cli {

void print_physical_findings(const std::vector<ModeFinding>& findings) {
  for (const auto& f : findings) {
    if (f.verdict == ModeVerdict::physical) continue;
    std::printf("WARNING: submodel %s is not a physical mode (%s): %s\n", f.submodel.c_str(), verdict_name(f.verdict),
                f.reason.c_str());
  }
}

AdditiveModel modes_from_data(const Record& data, int count, const SrivcOptions& fit, const std::string& data_name,
                              bool in_samples, const std::vector<std::string>& inputs, int output_derivatives) {
  const FrequencyResponse h = resolving_response(data, fit.closed_loop, fit.input_hold);
  AdditiveModel start = initial_modes(h, count, {}, inputs, output_derivatives);
  if (start.submodels.empty()) {
    SrivcOptions from_start = fit;
    from_start.settle_samples = 0;
    std::vector<std::pair<std::string, double>> bic;
    const NonResonantStart lag = choose_non_resonant_start(data, h, from_start, output_derivatives, &bic);
    if (lag.structure.empty())
      throw InputError(data_name, "no resonance peak in the frequency response estimate" +
                                      std::string(data.inputs() > 1 ? " (several inputs)" : "") +
                                      ": no mode to start from");
    std::printf(
        "WARNING: no resonance peak in the frequency response estimate over %.4g..%.4g %s: starting from %s "
        "(relative RMS error to it %.2g), the non-resonant structure whose fit has the least BIC:",
        lag.band_hz[0], lag.band_hz[1], frequency_unit(in_samples), lag.structure.c_str(), lag.relative_error);
    for (const auto& [structure, b] : bic) std::printf(" %s %.6g;", structure.c_str(), b);
    std::printf("\n");
    start.submodels.push_back(lag.submodel);
    return start;
  }
  const char* estimate = fit.closed_loop ? "S_yr/S_ur" : data.inputs() > 1 ? "|H|, H = S_yu S_uu^-1" : "H1 = S_yu/S_uu";
  std::printf("initial modes from the data (peaks of %s):", estimate);
  std::size_t found = 0;
  for (const auto& s : start.submodels) {
    if (s.input != 0) continue;  // one line per resonance, not per input
    ++found;
    std::printf(" %.5g %s (zeta %.3g)", modal_parameters(s).hz(), frequency_unit(in_samples), modal_parameters(s).zeta);
  }
  std::printf("\n");
  if (data.inputs() > 1) std::printf("each mode is one submodel per input (%d inputs)\n", data.inputs());
  if (static_cast<int>(found) < count)
    std::printf("WARNING: %d modes asked, the data show %zu resonance peaks above the noise: fitting %zu\n", count,
                found, found);
  return start;
}

bool non_resonant_instead(const Record& data, const FitResult& peak, const SrivcOptions& fit, bool in_samples,
                          int output_derivatives, AdditiveModel& start) {
  if (start.submodels.size() != 1 || data.inputs() != 1 || !start.submodels.front().is_mode()) return false;
  if (!peak.unstable_loop && peak.projections == 0) return false;
  const Eigen::Index settle = std::min<Eigen::Index>(fit.settle_samples, data.size());
  const Record used = data.segment(settle, data.size() - settle);
  const FrequencyResponse h = resolving_response(used, fit.closed_loop, fit.input_hold);
  std::vector<std::pair<std::string, double>> bic;
  const NonResonantStart structure = choose_non_resonant_start(data, h, fit, output_derivatives, &bic);
  const double peak_bic =
      peak.unstable_loop ? std::numeric_limits<double>::infinity() : bic_of(peak, static_cast<double>(used.size()));
  double least = std::numeric_limits<double>::infinity();
  for (const auto& b : bic) least = std::min(least, b.second);
  if (structure.structure.empty() || !(least < peak_bic)) return false;
  const ModalParameters p = modal_parameters(start.submodels.front());
  std::printf(
      "WARNING: the peak of the frequency response estimate at %.5g %s (zeta %.3g), fitted as a mode, %s: "
      "starting again from %s, the non-resonant structure whose fit has the least BIC (the mode's %.6g):",
      p.hz(), frequency_unit(in_samples), p.zeta,
      peak.unstable_loop ? "makes the loop with the controller diverge" : "needed a stability projection",
      structure.structure.c_str(), peak_bic);
  for (const auto& [name, b] : bic) std::printf(" %s %.6g;", name.c_str(), b);
  std::printf("\n");
  start.submodels = {structure.submodel};
  return true;
}

int output_kind(const Config& config, const std::optional<std::string>& option, bool from_data) {
  if (!option) return config.output_derivatives;
  const std::optional<int> z = output_derivatives_of(*option);
  if (!z) throw InputError("--output", "'" + *option + "' is not position, velocity or acceleration");
  if (!from_data && *z != config.output_derivatives)
    throw InputError("--output", std::string("the configured submodels measure ") +
                                     output_kind_name(config.output_derivatives) + " (model.output in " +
                                     config.source + "); --output is for modes started from the data (--modes)");
  return *z;
}

Hold output_hold(const Config& config, const AdditiveModel& start, double sample_time) {
  if (config.output_hold) return *config.output_hold;
  const Hold hold = default_output_hold(start, sample_time);
  if (hold == Hold::foh)
    std::printf("output hold foh: a starting mode above %g fs (model.output_hold unset)\n", kFohFromFraction);
  return hold;
}

void print_modal_table(const AdditiveModel& model, const std::vector<Eigen::MatrixXd>& covariances, bool in_samples) {
  // Several inputs: a last column names each submodel's input.
  const bool inputs = model.n_inputs() > 1;
  // A velocity or acceleration sensor: the gains stay the position response's DC gains.
  if (const int z = model.output_derivatives(); z != 0)
    std::printf("\noutput: %s; gain is the position response's DC gain b0 (output units %s per input unit)",
                output_kind_name(z), in_samples ? (z == 1 ? "* samples" : "* samples^2") : (z == 1 ? "* s" : "* s^2"));
  std::printf("\n%-10s %11s %10s %12s %10s %9s %9s %12s %10s%s\n", "submodel", in_samples ? "f [1/sample]" : "f [Hz]",
              "+-", in_samples ? "wn [rad/smp]" : "wn [rad/s]", "+-", "zeta", "+-", "gain", "+-",
              inputs ? "  input" : "");
  for (std::size_t i = 0; i < model.submodels.size(); ++i) {
    const Submodel& s = model.submodels[i];
    const Eigen::MatrixXd& c = covariances[i];
    const std::string input = inputs ? "  " + model.input_name(s.input) : "";
    if (s.is_mode()) {
      const ModalParameters p = modal_parameters(s);
      const ModalParameters sd = modal_std(s, c);
      std::printf("%-10s %11.5f %10.2e %12.5f %10.2e %9.5f %9.2e %12.5g %10.2e%s\n", s.name.c_str(), p.hz(),
                  sd.wn / (2 * std::numbers::pi), p.wn, sd.wn, p.zeta, sd.zeta, p.gain, sd.gain, input.c_str());
      continue;
    }
    // Rigid bodies and general transfer functions: their coefficients, and the
    // resonances of A when it has any.
    std::printf("%-10s n=%d m=%d l=%d", s.name.c_str(), s.n, s.m, s.rigid_poles);
    if (s.output_derivatives != 0) std::printf(" z=%d", s.output_derivatives);
    const Eigen::VectorXd th = s.theta();
    for (int j = 0; j < s.n_theta(); ++j) {
      const bool is_a = j < s.n;
      std::printf("  %s%d=%.6g(+-%.2g)", is_a ? "a" : "b", is_a ? j + 1 : j - s.n, th(j),
                  std::sqrt(std::max(0.0, c(j, j))));
    }
    std::printf("%s\n", input.c_str());
    for (const auto& r : resonances(s))
      std::printf("%-10s %11.5f %10s %12.5f %10s %9.5f\n", "", r.hz(), "", r.wn, "", r.zeta);
  }
}

}  // namespace modalwatch::cli
