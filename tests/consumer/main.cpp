// Uses the installed core library as another project would: simulates a known
// plant of two lightly damped modes under a PRBS input with output noise, fits
// the additive SRIVC model from a start 10 % off, and exits 1 unless every
// mode's natural frequency is within 1 % and its damping within 20 % of the truth.
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "modalwatch/model.hpp"
#include "modalwatch/simulator.hpp"
#include "modalwatch/srivc.hpp"

int main() {
  using namespace modalwatch;
  const std::vector<ModalParameters> truth = {{12.0, 0.05, 1.0}, {45.0, 0.03, 0.4}};

  PlantSpec plant;
  AdditiveModel initial;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const std::string name = "mode" + std::to_string(i + 1);
    PlantMode mode;
    mode.modal = truth[i];
    mode.submodel = make_mode(name, truth[i]);
    plant.modes.push_back(mode);
    initial.submodels.push_back(make_mode(name, {truth[i].wn * 1.1, truth[i].zeta * 0.8, truth[i].gain * 1.1}));
  }
  plant.snr_db = 30.0;

  ExperimentSpec experiment;
  experiment.sample_time = 0.005;
  experiment.duration = 60.0;
  experiment.seed = 7;
  experiment.excitation.kind = SignalSpec::Kind::prbs;
  experiment.excitation.register_bits = 12;
  experiment.excitation.amplitude = 1.0;

  const SimulationResult sim = simulate(plant, experiment);
  const FitResult fit = fit_srivc(sim.record, initial, SrivcOptions{});

  bool ok = fit.model.submodels.size() == truth.size();
  for (std::size_t i = 0; ok && i < truth.size(); ++i) {
    const ModalParameters est = modal_parameters(fit.model.submodels[i]);
    const double wn_error = std::abs(est.wn - truth[i].wn) / truth[i].wn;
    const double zeta_error = std::abs(est.zeta - truth[i].zeta) / truth[i].zeta;
    const bool mode_ok = wn_error <= 0.01 && zeta_error <= 0.20;
    std::printf("%s: wn %.4f rad/s (truth %.4f, error %.3f %%), zeta %.4f (truth %.4f, error %.1f %%) %s\n",
                fit.model.submodels[i].name.c_str(), est.wn, truth[i].wn, 100.0 * wn_error, est.zeta, truth[i].zeta,
                100.0 * zeta_error, mode_ok ? "ok" : "FAIL");
    ok = ok && mode_ok;
  }
  std::printf("fit %.2f %%, %d iterations, %s\n", fit.fit_percent, fit.iterations, ok ? "PASS" : "FAIL");
  return ok ? 0 : 1;
}
