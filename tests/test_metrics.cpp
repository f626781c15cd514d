// The daemon's Prometheus endpoint: a real server on 127.0.0.1 (port 0: any
// free one), snapshots in, GET /metrics over a plain socket, and the exposition
// parsed back: exact names, labels and values.
#include "daemon/metrics.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <map>
#include <numbers>
#include <string>
#include <vector>

#include "modalwatch/error.hpp"

namespace modalwatch {
namespace {

// One sample line of the text exposition format: name{labels} value.
struct Series {
  std::string name;
  std::map<std::string, std::string> labels;
  double value = 0.0;
};

struct Scrape {
  int status = 0;
  std::string content_type;
  std::vector<Series> series;
  std::map<std::string, std::string> type;  // # TYPE name type
};

// HTTP/1.0, so the server closes the connection after the body and sends it
// neither chunked nor compressed.
std::string http_get(int port, const std::string& path) {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) throw std::runtime_error("socket failed");
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (connect(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0) {
    close(fd);
    throw std::runtime_error("connect failed");
  }
  const std::string request = "GET " + path + " HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n";
  std::size_t sent = 0;
  while (sent < request.size()) {
    const ssize_t n = send(fd, request.data() + sent, request.size() - sent, 0);
    if (n <= 0) break;
    sent += static_cast<std::size_t>(n);
  }
  std::string response;
  char buffer[4096];
  for (;;) {
    const ssize_t n = recv(fd, buffer, sizeof buffer, 0);
    if (n <= 0) break;
    response.append(buffer, static_cast<std::size_t>(n));
  }
  close(fd);
  return response;
}

Scrape scrape(int port) {
  const std::string response = http_get(port, "/metrics");
  Scrape s;
  const std::size_t head_end = response.find("\r\n\r\n");
  if (response.rfind("HTTP/1.", 0) != 0 || head_end == std::string::npos) return s;
  s.status = std::atoi(response.c_str() + response.find(' ') + 1);
  const std::string head = response.substr(0, head_end);
  const std::size_t ct = head.find("Content-Type: ");
  if (ct != std::string::npos) s.content_type = head.substr(ct + 14, head.find("\r\n", ct) - ct - 14);
  std::size_t pos = head_end + 4;
  while (pos < response.size()) {
    std::size_t eol = response.find('\n', pos);
    if (eol == std::string::npos) eol = response.size();
    const std::string line = response.substr(pos, eol - pos);
    pos = eol + 1;
    if (line.rfind("# TYPE ", 0) == 0) {
      const std::size_t sp = line.find(' ', 7);
      s.type[line.substr(7, sp - 7)] = line.substr(sp + 1);
      continue;
    }
    if (line.empty() || line[0] == '#') continue;
    Series x;
    const std::size_t brace = line.find('{');
    const std::size_t close_brace = line.rfind('}');
    std::size_t value_at = 0;
    if (brace != std::string::npos && close_brace != std::string::npos) {
      x.name = line.substr(0, brace);
      std::size_t p = brace + 1;  // key="value",... (no escapes in this test's values)
      while (p < close_brace) {
        const std::size_t eq = line.find("=\"", p);
        const std::size_t end = line.find('"', eq + 2);
        x.labels[line.substr(p, eq - p)] = line.substr(eq + 2, end - eq - 2);
        p = end + 1;
        if (p < close_brace && line[p] == ',') ++p;
      }
      value_at = close_brace + 2;
    } else {
      const std::size_t sp = line.find(' ');
      x.name = line.substr(0, sp);
      value_at = sp + 1;
    }
    x.value = std::strtod(line.c_str() + value_at, nullptr);  // also "Nan", "+Inf"
    s.series.push_back(std::move(x));
  }
  return s;
}

using Labels = std::map<std::string, std::string>;

// The value of the one series with exactly these labels; NaN-free failure when absent.
::testing::AssertionResult has_value(const Scrape& s, const std::string& name, const Labels& labels, double expected) {
  int found = 0;
  double value = 0.0;
  for (const Series& x : s.series)
    if (x.name == name && x.labels == labels) {
      ++found;
      value = x.value;
    }
  if (found != 1) return ::testing::AssertionFailure() << name << ": " << found << " series with these labels";
  const bool equal = std::isnan(expected) ? std::isnan(value) : value == expected;
  if (!equal) return ::testing::AssertionFailure() << name << " = " << value << ", expected " << expected;
  return ::testing::AssertionSuccess();
}

// A histogram bucket, `le` compared as a number (the server formats the bound).
::testing::AssertionResult has_bucket(const Scrape& s, const std::string& name, const Labels& labels, double le,
                                      double expected) {
  for (const Series& x : s.series) {
    if (x.name != name + "_bucket" || !x.labels.count("le")) continue;
    Labels rest = x.labels;
    const double bound = std::strtod(rest["le"].c_str(), nullptr);
    rest.erase("le");
    if (rest != labels || bound != le) continue;
    if (x.value == expected) return ::testing::AssertionSuccess();
    return ::testing::AssertionFailure() << name << "{le=" << le << "} = " << x.value << ", expected " << expected;
  }
  return ::testing::AssertionFailure() << name << ": no bucket le=" << le;
}

const std::vector<std::string> kModes = {"rigid", "flex"};

MetricsSnapshot example_snapshot() {
  MetricsSnapshot s;
  s.n_modes = 2;
  s.warming_up = false;
  ModeMetrics& rigid = s.modes[0];  // baseline not yet learned
  rigid.value = {2.0 * std::numbers::pi * 4.0, 0.5, 2.0};
  ModeMetrics& flex = s.modes[1];
  flex.value = {2.0 * std::numbers::pi * 50.0, 0.02, 1.5};
  flex.std_dev = {2.0 * std::numbers::pi * 0.25, 0.001, 0.05};
  flex.status.baseline.value = {2.0 * std::numbers::pi * 56.0, 0.025, 1.25};
  flex.status.baseline.learned = true;
  flex.status.baseline_ready = true;
  QuantityStatus& wn = flex.status.quantity[static_cast<int>(Quantity::wn)];
  wn = {.flagged = true, .deviation_sigma = -24.0, .deviation_relative = -0.125, .since = 12.0};
  QuantityStatus& zeta = flex.status.quantity[static_cast<int>(Quantity::zeta)];
  zeta = {.deviation_sigma = -5.0, .deviation_relative = -0.2, .since = 13.0, .pending = true};
  flex.status.quantity[static_cast<int>(Quantity::gain)] = {.deviation_sigma = 5.0, .deviation_relative = 0.2};
  s.counters.samples_received = 1000;
  s.counters.samples_processed = 990;
  s.counters.samples_dropped = 3;
  s.counters.decode_errors = 2;
  s.counters.flag_changes = 1;
  s.counters.samples_lost = 7;
  s.counters.change_boosts = 4;
  s.counters.mode_restores = 5;
  s.tick.record(3'000);          // le 5 us
  s.tick.record(5'000);          // le 5 us (the bound is inclusive)
  s.tick.record(700'000);        // le 1 ms
  s.tick.record(1'000'000'000);  // +Inf
  return s;
}

TEST(Metrics, TickHistogramCountsIntoItsBucketsWithoutCumulating) {
  TickHistogram h;
  h.record(3'000);
  h.record(5'000);
  h.record(5'001);
  h.record(200'000'000);
  EXPECT_EQ(h.buckets[0], 2u);
  EXPECT_EQ(h.buckets[1], 1u);  // (5 us, 10 us]
  EXPECT_EQ(h.buckets[kTickBucketBoundsNs.size()], 1u);
  EXPECT_EQ(h.count(), 4u);
  EXPECT_EQ(h.sum_ns, 200'013'001u);
}

TEST(Metrics, ExposesGaugesCountersAndHistogramWithTheirLabels) {
  MetricsEndpoint endpoint({"127.0.0.1:0"}, "x", kModes);
  ASSERT_GT(endpoint.port(), 0);
  MetricsSnapshot snap = example_snapshot();
  endpoint.update(snap);

  const Scrape s = scrape(endpoint.port());
  ASSERT_EQ(s.status, 200);
  EXPECT_EQ(s.content_type, "text/plain; charset=utf-8");

  const Labels flex{{"axis", "x"}, {"mode", "flex"}};
  const Labels rigid{{"axis", "x"}, {"mode", "rigid"}};
  EXPECT_TRUE(has_value(s, "modalwatch_mode_frequency_hertz", flex, 50.0));
  EXPECT_TRUE(
      has_value(s, "modalwatch_mode_angular_frequency_radians_per_second", flex, 2.0 * std::numbers::pi * 50.0));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_damping_ratio", flex, 0.02));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_gain", flex, 1.5));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_frequency_stddev_hertz", flex, 0.25));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_damping_ratio_stddev", flex, 0.001));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_gain_stddev", flex, 0.05));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_baseline_frequency_hertz", flex, 56.0));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_baseline_damping_ratio", flex, 0.025));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_baseline_gain", flex, 1.25));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_baseline_ready", flex, 1.0));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_baseline_learned", flex, 1.0));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_frequency_hertz", rigid, 4.0));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_baseline_frequency_hertz", rigid, std::nan("")));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_baseline_ready", rigid, 0.0));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_baseline_learned", rigid, 0.0));

  const Labels flex_wn{{"axis", "x"}, {"mode", "flex"}, {"quantity", "wn"}};
  const Labels flex_zeta{{"axis", "x"}, {"mode", "flex"}, {"quantity", "zeta"}};
  const Labels flex_gain{{"axis", "x"}, {"mode", "flex"}, {"quantity", "gain"}};
  EXPECT_TRUE(has_value(s, "modalwatch_mode_flag", flex_wn, 2.0));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_flag", flex_zeta, 1.0));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_flag", flex_gain, 0.0));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_flag", {{"axis", "x"}, {"mode", "rigid"}, {"quantity", "wn"}}, 0.0));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_deviation_sigma", flex_wn, -24.0));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_deviation_ratio", flex_wn, -0.125));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_deviation_ratio", flex_zeta, -0.2));

  const Labels axis{{"axis", "x"}};
  EXPECT_TRUE(has_value(s, "modalwatch_state", {{"axis", "x"}, {"state", "warming_up"}}, 0.0));
  EXPECT_TRUE(has_value(s, "modalwatch_state", {{"axis", "x"}, {"state", "learning"}}, 1.0));  // rigid's baseline
  EXPECT_TRUE(has_value(s, "modalwatch_state", {{"axis", "x"}, {"state", "running"}}, 0.0));
  EXPECT_TRUE(has_value(s, "modalwatch_input_stale", axis, 0.0));
  EXPECT_TRUE(has_value(s, "modalwatch_samples_received_total", axis, 1000.0));
  EXPECT_TRUE(has_value(s, "modalwatch_samples_processed_total", axis, 990.0));
  EXPECT_TRUE(has_value(s, "modalwatch_samples_dropped_total", axis, 3.0));
  EXPECT_TRUE(has_value(s, "modalwatch_samples_lost_total", axis, 7.0));
  EXPECT_TRUE(has_value(s, "modalwatch_decode_errors_total", axis, 2.0));
  EXPECT_TRUE(has_value(s, "modalwatch_estimator_resets_total", axis, 0.0));
  EXPECT_TRUE(has_value(s, "modalwatch_change_boosts_total", axis, 4.0));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_restores_total", axis, 5.0));
  EXPECT_TRUE(has_value(s, "modalwatch_flag_changes_total", axis, 1.0));
  EXPECT_EQ(s.type.at("modalwatch_samples_received_total"), "counter");
  EXPECT_EQ(s.type.at("modalwatch_mode_flag"), "gauge");
  EXPECT_EQ(s.type.at("modalwatch_loop_tick_duration_seconds"), "histogram");

  // Prometheus's buckets are cumulative (le): 2 ticks <= 5 us, 3 <= 1 ms, 4 in all.
  const std::string tick = "modalwatch_loop_tick_duration_seconds";
  EXPECT_TRUE(has_bucket(s, tick, axis, 5e-6, 2.0));
  EXPECT_TRUE(has_bucket(s, tick, axis, 500e-6, 2.0));
  EXPECT_TRUE(has_bucket(s, tick, axis, 1e-3, 3.0));
  EXPECT_TRUE(has_bucket(s, tick, axis, 0.1, 3.0));
  EXPECT_TRUE(has_bucket(s, tick, axis, INFINITY, 4.0));
  EXPECT_TRUE(has_value(s, tick + "_count", axis, 4.0));
  bool sum_found = false;
  for (const Series& x : s.series)
    if (x.name == tick + "_sum" && x.labels == axis) {
      sum_found = true;
      EXPECT_NEAR(x.value, 1.000708, 1e-12);
    }
  EXPECT_TRUE(sum_found);
}

TEST(Metrics, CountersAdvanceByTheDifferenceAndIgnoreARestart) {
  MetricsEndpoint endpoint({"127.0.0.1:0"}, "y", kModes);
  MetricsSnapshot snap = example_snapshot();
  endpoint.update(snap);
  snap.counters.samples_received = 1500;
  snap.counters.flag_changes = 2;
  snap.modes[1].status.quantity[0].flagged = false;  // cleared
  snap.tick.record(20'000);                          // le 25 us
  endpoint.update(snap);

  const Labels axis{{"axis", "y"}};
  const std::string tick = "modalwatch_loop_tick_duration_seconds";
  Scrape s = scrape(endpoint.port());
  EXPECT_TRUE(has_value(s, "modalwatch_samples_received_total", axis, 1500.0));
  EXPECT_TRUE(has_value(s, "modalwatch_flag_changes_total", axis, 2.0));
  EXPECT_TRUE(has_value(s, "modalwatch_mode_flag", {{"axis", "y"}, {"mode", "flex"}, {"quantity", "wn"}}, 0.0));
  EXPECT_TRUE(has_bucket(s, tick, axis, 10e-6, 2.0));
  EXPECT_TRUE(has_bucket(s, tick, axis, 25e-6, 3.0));
  EXPECT_TRUE(has_value(s, tick + "_count", axis, 5.0));

  // The source starts over (a restarted loop): the totals become the new base.
  MetricsSnapshot restarted = example_snapshot();
  restarted.counters.samples_received = 200;
  restarted.tick = TickHistogram{};
  restarted.tick.record(3'000);
  endpoint.update(restarted);
  s = scrape(endpoint.port());
  EXPECT_TRUE(has_value(s, "modalwatch_samples_received_total", axis, 1500.0));
  EXPECT_TRUE(has_value(s, tick + "_count", axis, 5.0));

  restarted.counters.samples_received = 300;
  restarted.tick.record(3'000);
  endpoint.update(restarted);
  s = scrape(endpoint.port());
  EXPECT_TRUE(has_value(s, "modalwatch_samples_received_total", axis, 1600.0));
  EXPECT_TRUE(has_bucket(s, tick, axis, 5e-6, 3.0));
  EXPECT_TRUE(has_value(s, tick + "_count", axis, 6.0));
}

void expect_listen_error(const std::string& address) {
  try {
    MetricsEndpoint endpoint({address}, "x", kModes);
    ADD_FAILURE() << address << ": no InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.location(), "daemon.metrics.listen") << address;
    EXPECT_NE(std::string(e.what()).find(address), std::string::npos) << e.what();
  }
}

TEST(Metrics, AnAddressThatCannotBeBoundIsAnInputError) {
  MetricsEndpoint taken({"127.0.0.1:0"}, "x", kModes);
  expect_listen_error("127.0.0.1:" + std::to_string(taken.port()));  // in use
  expect_listen_error("192.0.2.1:9464");                             // not this machine's (TEST-NET-1)
  expect_listen_error("localhost");                                  // no port
  expect_listen_error("127.0.0.1:65536");
  expect_listen_error("");
}

}  // namespace
}  // namespace modalwatch
