#include "metrics.hpp"

#include <prometheus/counter.h>
#include <prometheus/exposer.h>
#include <prometheus/family.h>
#include <prometheus/gauge.h>
#include <prometheus/histogram.h>
#include <prometheus/registry.h>

#include <algorithm>
#include <exception>
#include <iterator>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <utility>

#include "modalwatch/error.hpp"

namespace modalwatch {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kHertzPerRadPerSecond = 1.0 / (2.0 * std::numbers::pi);
constexpr const char* kListenKey = "daemon.metrics.listen";

double baseline_or_nan(const ModeMetrics& m, double v) { return m.status.baseline_ready ? v : kNaN; }

struct ModeSeries {
  const char* name;
  const char* help;
  double (*get)(const ModeMetrics&);
};

// One gauge per mode each.
constexpr ModeSeries kModeSeries[] = {
    {"modalwatch_mode_angular_frequency_radians_per_second", "Undamped natural frequency wn of the mode, rad/s.",
     [](const ModeMetrics& m) { return m.value.wn; }},
    {"modalwatch_mode_frequency_hertz", "Undamped natural frequency of the mode, wn / (2 pi), Hz.",
     [](const ModeMetrics& m) { return m.value.wn * kHertzPerRadPerSecond; }},
    {"modalwatch_mode_damping_ratio", "Damping ratio zeta of the mode.",
     [](const ModeMetrics& m) { return m.value.zeta; }},
    {"modalwatch_mode_gain", "Modal gain (DC gain of the submodel), output units per input unit.",
     [](const ModeMetrics& m) { return m.value.gain; }},
    {"modalwatch_mode_angular_frequency_stddev_radians_per_second", "Standard deviation of wn, rad/s.",
     [](const ModeMetrics& m) { return m.std_dev.wn; }},
    {"modalwatch_mode_frequency_stddev_hertz", "Standard deviation of the natural frequency, Hz.",
     [](const ModeMetrics& m) { return m.std_dev.wn * kHertzPerRadPerSecond; }},
    {"modalwatch_mode_damping_ratio_stddev", "Standard deviation of the damping ratio.",
     [](const ModeMetrics& m) { return m.std_dev.zeta; }},
    {"modalwatch_mode_gain_stddev", "Standard deviation of the modal gain, output units per input unit.",
     [](const ModeMetrics& m) { return m.std_dev.gain; }},
    {"modalwatch_mode_baseline_angular_frequency_radians_per_second", "Baseline wn, rad/s (NaN until known).",
     [](const ModeMetrics& m) { return baseline_or_nan(m, m.status.baseline.value.wn); }},
    {"modalwatch_mode_baseline_frequency_hertz", "Baseline natural frequency, Hz (NaN until known).",
     [](const ModeMetrics& m) { return baseline_or_nan(m, m.status.baseline.value.wn * kHertzPerRadPerSecond); }},
    {"modalwatch_mode_baseline_damping_ratio", "Baseline damping ratio (NaN until known).",
     [](const ModeMetrics& m) { return baseline_or_nan(m, m.status.baseline.value.zeta); }},
    {"modalwatch_mode_baseline_gain", "Baseline modal gain (NaN until known).",
     [](const ModeMetrics& m) { return baseline_or_nan(m, m.status.baseline.value.gain); }},
    {"modalwatch_mode_baseline_ready", "1 when the mode's baseline is known (configured, restored or learned).",
     [](const ModeMetrics& m) { return m.status.baseline_ready ? 1.0 : 0.0; }},
    {"modalwatch_mode_baseline_learned",
     "1 when the baseline was learned over faults.learn_window, 0 when configured or restored (or not yet known).",
     [](const ModeMetrics& m) { return m.status.baseline_ready && m.status.baseline.learned ? 1.0 : 0.0; }},
};

struct QuantitySeries {
  const char* name;
  const char* help;
  double (*get)(const QuantityStatus&);
};

// One gauge per mode and quantity each.
constexpr QuantitySeries kQuantitySeries[] = {
    {"modalwatch_mode_deviation_sigma", "Signed deviation from the baseline in standard deviations, (x - x0) / std.",
     [](const QuantityStatus& q) { return q.deviation_sigma; }},
    {"modalwatch_mode_deviation_ratio", "Signed relative deviation from the baseline, (x - x0) / |x0|.",
     [](const QuantityStatus& q) { return q.deviation_relative; }},
    {"modalwatch_mode_flag", "Fault flag: 0 none, 1 pending (past the thresholds, hold time running), 2 raised.",
     [](const QuantityStatus& q) { return q.flagged   ? 2.0
                                          : q.pending ? 1.0
                                                      : 0.0; }},
};

struct CounterSeries {
  const char* name;
  const char* help;
  std::uint64_t (*get)(const MetricsSnapshot&);
};

constexpr CounterSeries kCounterSeries[] = {
    {"modalwatch_samples_received_total", "Samples decoded from valid packets.",
     [](const MetricsSnapshot& s) { return s.counters.samples_received; }},
    {"modalwatch_samples_processed_total", "Samples passed to the estimator.",
     [](const MetricsSnapshot& s) { return s.counters.samples_processed; }},
    {"modalwatch_samples_dropped_total", "Samples dropped because the input ring or the warm-up backlog was full.",
     [](const MetricsSnapshot& s) { return s.counters.samples_dropped; }},
    {"modalwatch_samples_lost_total", "Samples lost in transport (sequence numbers skipped).",
     [](const MetricsSnapshot& s) { return s.counters.samples_lost; }},
    {"modalwatch_samples_nonfinite_total", "Samples with NaN or Inf in u, y or r.",
     [](const MetricsSnapshot& s) { return s.counters.samples_nonfinite; }},
    {"modalwatch_samples_duplicate_total", "Samples dropped for a repeated sequence number.",
     [](const MetricsSnapshot& s) { return s.counters.samples_duplicate; }},
    {"modalwatch_samples_out_of_order_total", "Samples dropped for a sequence number below the last accepted one.",
     [](const MetricsSnapshot& s) { return s.counters.samples_out_of_order; }},
    {"modalwatch_input_gaps_total", "Input gaps that reset the prefilter states.",
     [](const MetricsSnapshot& s) { return s.counters.gaps; }},
    {"modalwatch_decode_errors_total", "Packets the decoder rejected.",
     [](const MetricsSnapshot& s) { return s.counters.decode_errors; }},
    {"modalwatch_estimator_resets_total", "Estimator returns to its last good state.",
     [](const MetricsSnapshot& s) { return s.counters.resets; }},
    {"modalwatch_change_boosts_total", "Covariance boosts after the change test found a change of the output error.",
     [](const MetricsSnapshot& s) { return s.counters.change_boosts; }},
    {"modalwatch_mode_restores_total", "Estimator updates that returned a mode (or several) to its last good estimate after its gain changed sign.",
     [](const MetricsSnapshot& s) { return s.counters.mode_restores; }},
    {"modalwatch_loop_overruns_total", "Estimation loop ticks that ended after the next one was due.",
     [](const MetricsSnapshot& s) { return s.counters.overruns; }},
    {"modalwatch_flag_changes_total", "Fault flags raised or cleared.",
     [](const MetricsSnapshot& s) { return s.counters.flag_changes; }},
};

// modalwatch_state's label values, in the order the snapshot's state is derived.
enum State : int { warming_up = 0, learning = 1, running = 2, n_states = 3 };
constexpr const char* kStateNames[n_states] = {"warming_up", "learning", "running"};

State state_of(const MetricsSnapshot& s) {
  if (s.warming_up) return warming_up;
  for (int i = 0; i < s.n_modes; ++i)
    if (!s.modes[static_cast<std::size_t>(i)].status.baseline_ready) return learning;
  return running;
}

constexpr const char* kQuantityNames[kQuantities] = {"wn", "zeta", "gain"};

// host:port with a non-empty host and a decimal port 0..65535 (civetweb would
// also take a bare port, meaning every interface, and suffixes such as "s").
bool valid_listen_address(const std::string& a) {
  const std::size_t colon = a.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == a.size() || a.size() - colon > 6) return false;
  long port = 0;
  for (std::size_t i = colon + 1; i < a.size(); ++i) {
    if (a[i] < '0' || a[i] > '9') return false;
    port = port * 10 + (a[i] - '0');
  }
  return port <= 65535;
}

prometheus::Histogram::BucketBoundaries tick_bounds_seconds() {
  prometheus::Histogram::BucketBoundaries b;
  for (const std::int64_t ns : kTickBucketBoundsNs) b.push_back(static_cast<double>(ns) * 1e-9);
  return b;
}

}  // namespace

struct MetricsEndpoint::Impl {
  std::shared_ptr<prometheus::Registry> registry = std::make_shared<prometheus::Registry>();
  std::unique_ptr<prometheus::Exposer> exposer;
  std::vector<std::string> mode_names;
  // [series][mode] and [series][mode * kQuantities + quantity]
  std::vector<std::vector<prometheus::Gauge*>> mode_gauges, quantity_gauges;
  std::array<prometheus::Gauge*, n_states> state{};
  prometheus::Gauge* stale = nullptr;
  prometheus::Gauge* low_excitation = nullptr;
  prometheus::Gauge* misfit = nullptr;
  std::vector<prometheus::Counter*> counters;
  std::vector<std::uint64_t> counter_base;  // the totals last seen
  prometheus::Histogram* tick = nullptr;
  TickHistogram tick_base;
  std::vector<double> tick_increments = std::vector<double>(kTickBucketBoundsNs.size() + 1);
};

MetricsEndpoint::MetricsEndpoint(const MetricsSettings& settings, std::string axis, std::vector<std::string> mode_names)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  if (!valid_listen_address(settings.listen))
    throw InputError(kListenKey, "'" + settings.listen + "' is not host:port (e.g. 127.0.0.1:9464)");
  m.mode_names = std::move(mode_names);
  if (m.mode_names.size() > static_cast<std::size_t>(Daemon::kMaxModes))
    throw std::invalid_argument("MetricsEndpoint: more modes than Daemon::kMaxModes");
  const prometheus::Labels axis_label{{"axis", axis}};
  auto gauge_family = [&](const char* name, const char* help) -> prometheus::Family<prometheus::Gauge>& {
    return prometheus::BuildGauge().Name(name).Help(help).Labels(axis_label).Register(*m.registry);
  };

  for (const ModeSeries& series : kModeSeries) {
    auto& family = gauge_family(series.name, series.help);
    auto& gauges = m.mode_gauges.emplace_back();
    for (const std::string& mode : m.mode_names) gauges.push_back(&family.Add({{"mode", mode}}));
  }
  for (const QuantitySeries& series : kQuantitySeries) {
    auto& family = gauge_family(series.name, series.help);
    auto& gauges = m.quantity_gauges.emplace_back();
    for (const std::string& mode : m.mode_names)
      for (const char* quantity : kQuantityNames)
        gauges.push_back(&family.Add({{"mode", mode}, {"quantity", quantity}}));
  }
  auto& state = gauge_family("modalwatch_state",
                             "1 for the daemon's current state: warming_up (the estimator's warm-up window), learning "
                             "(a baseline is being learned), running (flagging); 0 for the others.");
  for (int s = 0; s < n_states; ++s) m.state[static_cast<std::size_t>(s)] = &state.Add({{"state", kStateNames[s]}});
  m.stale =
      &gauge_family("modalwatch_input_stale", "1 when no sample arrived for longer than daemon.stale_time.").Add({});
  m.low_excitation =
      &gauge_family("modalwatch_low_excitation", "1 when the excitation is too low for flagging.").Add({});
  m.misfit = &gauge_family("modalwatch_model_misfit",
                           "1 while the model leaves an output error above the noise level it had before the "
                           "estimator's last reset: the estimates are re-converging and no flag rises.")
                  .Add({});
  for (const CounterSeries& series : kCounterSeries)
    m.counters.push_back(&prometheus::BuildCounter()
                              .Name(series.name)
                              .Help(series.help)
                              .Labels(axis_label)
                              .Register(*m.registry)
                              .Add({}));
  m.counter_base.assign(m.counters.size(), 0);
  m.tick = &prometheus::BuildHistogram()
                .Name("modalwatch_loop_tick_duration_seconds")
                .Help("Time the estimation loop worked in a tick (wake-up to sleep), s.")
                .Labels(axis_label)
                .Register(*m.registry)
                .Add({}, tick_bounds_seconds());

  try {
    m.exposer = std::make_unique<prometheus::Exposer>(settings.listen, 1);
  } catch (const std::exception& e) {
    throw InputError(kListenKey, "cannot listen on '" + settings.listen + "': " + e.what());
  }
  m.exposer->RegisterCollectable(m.registry);
}

MetricsEndpoint::~MetricsEndpoint() = default;

int MetricsEndpoint::port() const {
  const std::vector<int> ports = impl_->exposer->GetListeningPorts();
  return ports.empty() ? 0 : ports.front();
}

void MetricsEndpoint::update(const MetricsSnapshot& s) {
  Impl& m = *impl_;
  const std::size_t n_modes = std::min(m.mode_names.size(), static_cast<std::size_t>(s.n_modes));
  for (std::size_t k = 0; k < std::size(kModeSeries); ++k)
    for (std::size_t i = 0; i < n_modes; ++i) m.mode_gauges[k][i]->Set(kModeSeries[k].get(s.modes[i]));
  for (std::size_t k = 0; k < std::size(kQuantitySeries); ++k)
    for (std::size_t i = 0; i < n_modes; ++i)
      for (std::size_t q = 0; q < kQuantities; ++q)
        m.quantity_gauges[k][i * kQuantities + q]->Set(kQuantitySeries[k].get(s.modes[i].status.quantity[q]));

  const State now = state_of(s);
  for (int st = 0; st < n_states; ++st) m.state[static_cast<std::size_t>(st)]->Set(st == now ? 1.0 : 0.0);
  m.stale->Set(s.stale ? 1.0 : 0.0);
  m.low_excitation->Set(s.low_excitation ? 1.0 : 0.0);
  m.misfit->Set(s.misfit ? 1.0 : 0.0);

  for (std::size_t k = 0; k < m.counters.size(); ++k) {
    const std::uint64_t total = kCounterSeries[k].get(s);
    if (total > m.counter_base[k]) m.counters[k]->Increment(static_cast<double>(total - m.counter_base[k]));
    m.counter_base[k] = total;
  }

  // The histogram as a whole: a bucket or the sum below its base means the
  // loop's histogram started over, which becomes the new base.
  bool restarted = s.tick.sum_ns < m.tick_base.sum_ns;
  std::uint64_t observed = 0;
  for (std::size_t b = 0; b < s.tick.buckets.size(); ++b) {
    restarted = restarted || s.tick.buckets[b] < m.tick_base.buckets[b];
    observed += s.tick.buckets[b] - m.tick_base.buckets[b];  // unsigned; unused when restarted
  }
  if (!restarted && observed > 0) {
    for (std::size_t b = 0; b < s.tick.buckets.size(); ++b)
      m.tick_increments[b] = static_cast<double>(s.tick.buckets[b] - m.tick_base.buckets[b]);
    m.tick->ObserveMultiple(m.tick_increments, static_cast<double>(s.tick.sum_ns - m.tick_base.sum_ns) * 1e-9);
  }
  m.tick_base = s.tick;
}

}  // namespace modalwatch
