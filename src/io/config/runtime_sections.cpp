// The sections of the running estimator: estimator:, lcm:, daemon:, faults:.
#include "sections.hpp"

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
// ---------------------------------------------------------------- estimator

}  // namespace

// The `estimator:` keys; every one is optional and defaults to EstimatorSettings'.
void parse_estimator(const Map& est, double sample_time, EstimatorSettings& e) {
  est.allow({"block_iterations",
             "refinements",
             "update_divisor",
             "warmup",
             "fit_on_warmup",
             "warmup_iterations",
             "initial_covariance_relative",
             "random_walk",
             "covariance_bound",
             "stabilisation",
             "min_memory",
             "settled_memory",
             "damping_deadband",
             "divergence_ratio",
             "change_ratio",
             "change_threshold",
             "change_hold",
             "gap_factor",
             "outlier_sigma",
             "residual_window",
             "low_excitation_ratio",
             "low_excitation_window"},
            "estimator");
  constexpr long long kIntMax = std::numeric_limits<int>::max();
  const auto count = [&](std::string_view key, long long lo, int& out) {
    if (const auto v = est.get(key)) out = static_cast<int>(v->integer(lo, kIntMax));
  };
  count("block_iterations", 1, e.block_iterations);
  count("refinements", 0, e.refinements);
  count("update_divisor", 1, e.update_divisor);
  count("warmup_iterations", 1, e.warmup_iterations);
  if (const auto w = est.get("warmup")) {
    const double seconds = w->at_least(0.0);
    const double samples = std::round(seconds / sample_time);
    if (seconds > 0.0 && samples < 1.0) w->fail("shorter than one sample period (use 0 for no warm-up)");
    if (samples > static_cast<double>(kIntMax)) w->fail("too long: more than " + std::to_string(kIntMax) + " samples");
    e.warmup_samples = static_cast<int>(samples);
  }
  if (const auto v = est.get("fit_on_warmup")) e.fit_on_warmup = v->boolean();
  if (const auto v = est.get("initial_covariance_relative")) e.initial_covariance_relative = v->positive();
  if (const auto v = est.get("random_walk")) e.random_walk = v->at_least(0.0);
  if (const auto v = est.get("covariance_bound")) e.covariance_bound = v->above(1.0);
  if (const auto v = est.get("stabilisation")) e.stabilisation = v->at_least(0.0);
  if (const auto v = est.get("min_memory")) e.min_memory = v->at_least(0.0);
  if (const auto v = est.get("settled_memory")) e.settled_memory = v->at_least(0.0);
  if (const auto v = est.get("damping_deadband")) e.damping_deadband = v->at_least(0.0);
  if (const auto v = est.get("divergence_ratio")) e.divergence_ratio = v->above(1.0);
  if (const auto v = est.get("change_ratio")) {
    e.change_ratio = v->number();
    if (!(e.change_ratio == 0.0 || e.change_ratio > 1.0)) v->fail("must be 0 (off) or > 1");
  }
  if (const auto v = est.get("change_threshold")) e.change_threshold = v->positive();
  if (const auto v = est.get("change_hold")) e.change_hold = v->at_least(0.0);
  if (const auto v = est.get("gap_factor")) e.gap_factor = v->above(1.0);
  if (const auto v = est.get("outlier_sigma")) e.outlier_sigma = v->positive();
  if (const auto v = est.get("residual_window")) e.residual_window = v->at_least(0.0);
  if (const auto v = est.get("low_excitation_ratio")) {
    e.low_excitation_ratio = v->number();
    if (!(e.low_excitation_ratio >= 0.0 && e.low_excitation_ratio < 1.0)) v->fail("must be in [0, 1)");
  }
  if (const auto v = est.get("low_excitation_window")) e.low_excitation_window = v->at_least(0.0);
}

void parse_lcm(const Map& m, LcmSettings& lcm) {
  m.allow({"url", "channels"}, "lcm");
  if (const auto v = m.get("url")) {
    lcm.url = v->text();
    if (lcm.url.find("://") == std::string::npos)
      v->fail("expected an LCM URL such as udpm://239.255.76.67:7667?ttl=0 or memq://");
  }
  if (const auto c = m.get("channels")) {
    const Map ch(*c);
    ch.allow({"samples", "batches", "estimates", "fault_status", "heartbeat"}, "lcm.channels");
    const std::pair<const char*, std::string*> names[] = {{"samples", &lcm.samples_channel},
                                                          {"batches", &lcm.batches_channel},
                                                          {"estimates", &lcm.estimates_channel},
                                                          {"fault_status", &lcm.fault_status_channel},
                                                          {"heartbeat", &lcm.heartbeat_channel}};
    for (const auto& [key, out] : names)
      if (const auto v = ch.get(key)) *out = v->text();
    // One channel for two purposes would feed the daemon its own output.
    for (std::size_t i = 0; i < std::size(names); ++i)
      for (std::size_t j = i + 1; j < std::size(names); ++j)
        if (*names[i].second == *names[j].second)
          (ch.get(names[j].first) ? *ch.get(names[j].first) : ch.self())
              .fail("channel '" + *names[j].second + "' is also lcm.channels." + names[i].first);
  }
}

namespace {

// ---------------------------------------------------------------- daemon

}  // namespace

void parse_daemon(const Map& d, Config& config, const std::filesystem::path& dir, bool gap_factor_given) {
  d.allow({"loop_rate_hz", "publish_period", "heartbeat_period", "gap_time", "stale_time", "sample_ring",
           "snapshot_ring", "warmup_backlog", "realtime_priority", "checkpoint", "log_level", "metrics"},
          "daemon");
  DaemonSettings& s = config.daemon;
  if (const auto v = d.get("loop_rate_hz")) {
    s.loop_rate_hz = v->positive();
    if (s.loop_rate_hz > 100000.0) v->fail("must be <= 100000 (a tick shorter than 10 us is a busy loop)");
  }
  if (const auto v = d.get("publish_period")) {
    s.publish_period = v->positive();
    if (s.publish_period < config.sample_time) v->fail("must be at least one sample period");
  }
  if (const auto v = d.get("heartbeat_period")) s.heartbeat_period = v->positive();
  if (const auto v = d.get("gap_time")) {
    if (gap_factor_given) v->fail_plain("give daemon.gap_time or estimator.gap_factor, not both");
    const double gap = v->positive();
    if (!(gap > config.sample_time))
      v->fail("must exceed the sample period " + format_number(config.sample_time) + " s");
    config.estimator.gap_factor = gap / config.sample_time;
  }
  if (const auto v = d.get("stale_time")) s.stale_time = v->positive();
  constexpr long long kRingMax = 1LL << 24;
  if (const auto v = d.get("sample_ring")) s.sample_ring = static_cast<int>(v->integer(16, kRingMax));
  if (const auto v = d.get("snapshot_ring")) s.snapshot_ring = static_cast<int>(v->integer(2, 65536));
  if (const auto v = d.get("warmup_backlog")) {
    s.warmup_backlog = v->positive();
    if (s.warmup_backlog / config.sample_time > static_cast<double>(kRingMax))
      v->fail("must hold at most " + std::to_string(kRingMax) + " samples (" +
              format_number(std::floor(static_cast<double>(kRingMax) * config.sample_time)) +
              " s at this sample rate)");
  }
  if (const auto v = d.get("realtime_priority")) s.realtime_priority = static_cast<int>(v->integer(0, 99));
  if (const auto c = d.get("checkpoint")) {
    const Map m(*c);
    m.allow({"path", "period"}, "daemon.checkpoint");
    const Value path = m.require("path");
    const std::filesystem::path file(path.text());
    s.checkpoint_path = (file.is_absolute() ? file : dir / file).lexically_normal().string();
    if (const auto p = m.get("period")) s.checkpoint_period = p->positive();
  }
  if (const auto v = d.get("log_level"))
    s.log_level = v->choice({"trace", "debug", "info", "warn", "error", "critical", "off"});
  if (const auto c = d.get("metrics")) {
    const Map m(*c);
    m.allow({"listen"}, "daemon.metrics");
    if (const auto v = m.get("listen")) {
      // An empty string (listen: "") turns the endpoint off, as an absent key does.
      const std::string listen = v->node().IsNull()     ? std::string()
                                 : v->node().IsScalar() ? v->node().Scalar()
                                                        : v->text();
      if (!listen.empty()) {
        const auto colon = listen.rfind(':');
        const std::string port = colon == std::string::npos ? std::string() : listen.substr(colon + 1);
        long long number = 0;
        const bool digits = !port.empty() && port.size() <= 5 &&
                            std::all_of(port.begin(), port.end(), [](char ch) { return ch >= '0' && ch <= '9'; });
        if (digits) number = std::stoll(port);
        if (colon == 0 || colon == std::string::npos || !digits || number < 1 || number > 65535)
          v->fail("expected host:port, e.g. 127.0.0.1:9464 (port 1..65535)");
      }
      s.metrics_listen = listen;
    }
  }
}

namespace {

// ---------------------------------------------------------------- faults

void parse_thresholds(const Map& m, FaultThresholds& th) {
  m.allow({"sigma", "relative", "hold", "clear_fraction", "clear_time"}, "thresholds");
  if (const auto v = m.get("sigma")) th.sigma_threshold = v->positive();
  if (const auto v = m.get("relative")) th.relative_threshold = v->positive();
  if (const auto v = m.get("hold")) th.hold_time = v->at_least(0.0);
  if (const auto v = m.get("clear_fraction")) {
    th.clear_fraction = v->number();
    if (!(th.clear_fraction > 0.0 && th.clear_fraction < 1.0)) v->fail("must be in (0, 1)");
  }
  if (const auto v = m.get("clear_time")) th.clear_time = v->at_least(0.0);
}

// A configured baseline's `std:`: each of wn (or frequency_hz), zeta, gain
// optional, 0 (exact) when not given.
ModalParameters parse_baseline_std(const Map& m) {
  m.allow({"wn", "frequency_hz", "zeta", "gain"}, "a baseline's std");
  ModalParameters sd{0.0, 0.0, 0.0};
  sd.wn = one_of(m, "wn", "frequency_hz", kTwoPi, false).value_or(0.0);
  if (const auto v = m.get(m.has("wn") ? "wn" : "frequency_hz"); v && sd.wn < 0.0) v->fail("must be >= 0");
  if (const auto v = m.get("zeta")) sd.zeta = v->at_least(0.0);
  if (const auto v = m.get("gain")) sd.gain = v->at_least(0.0);
  return sd;
}

}  // namespace

void parse_faults(const Map& f, Config& config) {
  f.allow({"learn_window", "false_alarm_interval", "cusum_shift", "settle_std_fraction", "settle_change_fraction", "wn",
           "zeta", "gain", "baselines"},
          "faults");
  FaultSettings& s = config.faults;
  if (const auto v = f.get("learn_window")) s.learn_window = v->positive();
  if (const auto v = f.get("false_alarm_interval")) s.false_alarm_interval = v->positive();
  if (const auto v = f.get("cusum_shift")) s.cusum_shift = v->positive();
  if (const auto v = f.get("settle_std_fraction")) s.settle_std_fraction = v->positive();
  if (const auto v = f.get("settle_change_fraction")) s.settle_change_fraction = v->positive();
  const char* names[kQuantities] = {"wn", "zeta", "gain"};
  for (int q = 0; q < kQuantities; ++q)
    if (const auto v = f.get(names[q])) parse_thresholds(Map(*v), s.thresholds[static_cast<std::size_t>(q)]);
  if (const auto b = f.get("baselines")) {
    const Map m(*b);
    Keys modes;
    for (const auto& sub : config.model.submodels)
      if (sub.is_resonance()) modes.push_back(sub.name);
    m.allow(modes, "faults.baselines (the model's modes)");
    for (std::size_t i = 0; i < config.model.submodels.size(); ++i)
      if (const auto v = m.get(config.model.submodels[i].name)) {
        const Map mode(*v);
        mode.allow({"wn", "frequency_hz", "zeta", "gain", "std"}, "a baseline");
        s.baselines[i] = parse_modal(mode);
        if (const auto sd = mode.get("std")) s.baseline_std[i] = parse_baseline_std(Map(*sd));
      }
  }
}

}  // namespace modalwatch::config_detail
