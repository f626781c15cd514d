#include "stabilisation.hpp"

#include <cmath>
#include <complex>
#include <cstdio>
#include <filesystem>
#include <numbers>

#include "json_writer.hpp"
#include "modalwatch/initial_modes.hpp"
#include "modalwatch/io/atomic_file.hpp"
#include "modalwatch/io/csv.hpp"
#include "plot_script.hpp"
#include "record_columns.hpp"

namespace modalwatch::cli {

void print_order_selection(const OrderSelection& selection, bool in_samples) {
  std::printf(
      "number of modes from the data (lowest BIC; * stable in frequency within 1 %% and damping within 5 %% "
      "of the order below, . in frequency only):\n");
  std::printf("%5s %14s %9s %10s  modes found: %s (zeta)\n", "modes", "BIC", "fit %", "converged",
              frequency_unit(in_samples));
  for (std::size_t i = 0; i < selection.orders.size(); ++i) {
    const OrderFit& o = selection.orders[i];
    std::printf("%5d %14.6g %9.2f %10s ", o.modes, o.bic, o.fit.fit_percent, o.fit.converged ? "yes" : "no");
    for (const StabilisedMode& m : o.diagram)
      std::printf(" %.5g%s (%.3g)", m.modal.hz(), m.stable ? "*" : (m.stable_frequency ? "." : ""), m.modal.zeta);
    std::printf("%s\n", static_cast<int>(i) == selection.chosen ? "   <- chosen" : "");
  }
}

void write_stabilisation(const std::string& dir, const OrderSelection& selection, const Record& data, bool closed_loop,
                         bool in_samples, const std::string& plot_script) {
  std::filesystem::create_directories(dir);
  JsonWriter j;
  j.begin_object().key("orders").begin_array(JsonWriter::Layout::lines);
  for (const OrderFit& o : selection.orders) {
    j.begin_object().key("modes").value(o.modes).key("bic").value(o.bic).key("fit_percent").value(o.fit.fit_percent, 6);
    j.key("converged").value(o.fit.converged).key("modes_found").value(static_cast<int>(o.diagram.size()));
    j.end_object();
  }
  j.end_array();
  j.key("chosen").value(selection.chosen < 0 ? 0 : selection.orders[static_cast<std::size_t>(selection.chosen)].modes);
  j.key("time_unit").value(in_samples ? "samples" : "s");
  write_file_atomically(dir + "/summary.json", j.end_object().finish());

  Eigen::Index rows = 0;
  for (const OrderFit& o : selection.orders) rows += static_cast<Eigen::Index>(o.diagram.size());
  Eigen::MatrixXd t(rows, 8);
  Eigen::Index r = 0;
  for (std::size_t i = 0; i < selection.orders.size(); ++i)
    for (const StabilisedMode& m : selection.orders[i].diagram)
      t.row(r++) << selection.orders[i].modes, selection.orders[i].bic, m.modal.hz(), m.modal.zeta, m.modal.gain,
          m.stable_frequency ? 1.0 : 0.0, m.stable ? 1.0 : 0.0, static_cast<int>(i) == selection.chosen ? 1.0 : 0.0;
  write_table(dir + "/stabilisation.csv",
              {"modes", "bic", "f_hz", "zeta", "gain", "stable_frequency", "stable", "chosen"}, t);

  const FrequencyResponse h = frequency_response(data, closed_loop);
  const Eigen::Index F = h.frequency_hz.size() - 1;  // without DC
  Eigen::MatrixXd f(F, 6);
  for (Eigen::Index k = 0; k < F; ++k) {
    const double hz = h.frequency_hz(k + 1);
    const std::complex<double> m = h.response(k + 1);
    const std::complex<double> g =
        selection.chosen < 0 ? std::complex<double>(NAN, NAN)
                             : selection.orders[static_cast<std::size_t>(selection.chosen)].fit.model.response(
                                   2.0 * std::numbers::pi * hz);
    f.row(k) << hz, std::abs(m), std::arg(m) * 180.0 / std::numbers::pi, h.coherence(k + 1), std::abs(g),
        std::arg(g) * 180.0 / std::numbers::pi;
  }
  write_table(dir + "/frf.csv",
              {"f_hz", "mag_measured", "phase_measured_deg", "coherence", "mag_model", "phase_model_deg"}, f);
  if (plot_script.empty()) return;
  const PlotOutcome plot = run_plot_script(plot_script, dir);
  if (!plot.made) std::printf("WARNING: no stabilisation.png: %s\n", plot.failure.c_str());
}

}  // namespace modalwatch::cli
