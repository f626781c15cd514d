// `modalwatch watch`: subscribes to the daemon's estimates and fault status
// (the channels of the config's lcm: section) and prints one line per message.
#include <lcm/lcm.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <ctime>
#include <string>

#include <modalwatch/estimates_t.hpp>
#include <modalwatch/fault_status_t.hpp>

#include "commands.hpp"
#include "guarded.hpp"
#include "modalwatch/error.hpp"
#include "modalwatch/io/config.hpp"

namespace modalwatch::cli {
namespace {

using Fault = modalwatch::fault_status_t;

struct Watcher {
  const WatchArgs* args = nullptr;
  long long estimates = 0, statuses = 0;
};

void on_estimates(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  auto& w = *static_cast<Watcher*>(user);
  modalwatch::estimates_t msg;
  if (msg.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) < 0) {
    std::printf("estimates: undecodable message (%u bytes)\n", rbuf->data_size);
    return;
  }
  if (w.estimates++ % w.args->every != 0) return;
  std::string line;
  char buf[256];
  std::snprintf(buf, sizeof buf, "t = %9.3f s  ", static_cast<double>(msg.utime) * 1e-6);
  line += buf;
  for (const auto& m : msg.modes) {
    if (m.wn > 0.0)
      std::snprintf(buf, sizeof buf, "| %s: f = %9.4f Hz (+-%.2g) zeta = %.4f  ", m.name.c_str(), m.hz,
                    m.wn_std / (2.0 * M_PI), m.zeta);
    else
      std::snprintf(buf, sizeof buf, "| %s: gain = %.5g  ", m.name.c_str(), m.gain);
    line += buf;
    if (std::isfinite(m.baseline_wn) && m.baseline_wn > 0.0) {
      std::snprintf(buf, sizeof buf, "[base %.4f Hz]  ", m.baseline_wn / (2.0 * M_PI));
      line += buf;
    }
  }
  std::snprintf(buf, sizeof buf, "| rms %.3g, %lld samples", msg.residual_rms,
                static_cast<long long>(msg.samples_processed));
  line += buf;
  std::printf("estimates %s\n", line.c_str());
  std::fflush(stdout);
}

// "hh:mm:ss.mmm", local wall-clock time now (when the message arrived).
std::string wall_clock_now() {
  const auto now = std::chrono::system_clock::now();
  const std::time_t secs = std::chrono::system_clock::to_time_t(now);
  const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000;
  std::tm local{};
  localtime_r(&secs, &local);
  char buf[32];
  std::snprintf(buf, sizeof buf, "%02d:%02d:%02d.%03d", local.tm_hour, local.tm_min, local.tm_sec,
                static_cast<int>(ms));
  return buf;
}

void on_fault_status(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  auto& w = *static_cast<Watcher*>(user);
  Fault msg;
  if (msg.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) < 0) {
    std::printf("fault status: undecodable message (%u bytes; a fault_status_t other than version %d?)\n",
                rbuf->data_size, static_cast<int>(Fault::VERSION));
    return;
  }
  if (w.statuses++ % w.args->every != 0) return;
  std::string flags;
  char buf[256];
  for (const auto& m : msg.modes) {
    const std::pair<const char*, const modalwatch::quantity_status_t*> quantities[] = {
        {"wn", &m.wn}, {"zeta", &m.zeta}, {"gain", &m.gain}};
    for (const auto& [name, q] : quantities) {
      if (q->state != "raised" && q->state != "pending") continue;
      std::snprintf(buf, sizeof buf, "%s%s.%s %s (%+.2f %%, %+.1f sigma) since t = %.3f s", flags.empty() ? "" : ", ",
                    m.name.c_str(), name, q->state == "raised" ? "FLAGGED" : "pending", q->deviation_percent,
                    q->deviation_sigma, q->since_t);
      flags += buf;
    }
  }
  // Whether flags can rise at all: not while warming up or learning baselines.
  if (flags.empty()) {
    if (msg.state == "warming_up")
      flags = "none (warming up: cannot flag yet)";
    else if (msg.state == "learning")
      flags = "none (learning baselines: cannot flag yet)";
    else if (msg.state == "no_input")
      flags = "none (no input yet)";
    else
      flags = (msg.health & Fault::HEALTH_LOW_EXCITATION) ? "none (suppressed: low excitation)" : "none";
  }
  std::printf(
      "faults    t = %9.3f s  %s  | %s | flags: %s | health: %s | received %lld, processed %lld, lost %lld, "
      "dropped %lld, nonfinite %lld, dup %lld, ooo %lld, gaps %lld, decode errors %lld, overruns %lld, "
      "restarts %lld\n",
      msg.t, wall_clock_now().c_str(), msg.state.c_str(), flags.c_str(), msg.health_text.c_str(),
      static_cast<long long>(msg.samples_received), static_cast<long long>(msg.samples_processed),
      static_cast<long long>(msg.samples_lost), static_cast<long long>(msg.samples_dropped),
      static_cast<long long>(msg.samples_nonfinite), static_cast<long long>(msg.samples_duplicate),
      static_cast<long long>(msg.samples_out_of_order), static_cast<long long>(msg.gaps),
      static_cast<long long>(msg.decode_errors), static_cast<long long>(msg.overruns),
      static_cast<long long>(msg.sender_restarts));
  std::fflush(stdout);
}

}  // namespace

int watch(const WatchArgs& args) {
  return guarded("watch", [&] {
    const Config config = load_config(args.config);
    if (args.every < 1) throw std::invalid_argument("--every must be >= 1");
    lcm_t* lcm = lcm_create(config.lcm.url.c_str());
    if (!lcm) throw InputError(args.config, "key 'lcm.url': cannot open LCM provider '" + config.lcm.url + "'");
    Watcher w;
    w.args = &args;
    lcm_subscribe(lcm, config.lcm.estimates_channel.c_str(), &on_estimates, &w);
    lcm_subscribe(lcm, config.lcm.fault_status_channel.c_str(), &on_fault_status, &w);
    std::fprintf(stderr, "modalwatch watch: %s on %s (%s, %s)\n", args.config.c_str(), config.lcm.url.c_str(),
                 config.lcm.estimates_channel.c_str(), config.lcm.fault_status_channel.c_str());
    const auto start = std::chrono::steady_clock::now();
    for (;;) {
      lcm_handle_timeout(lcm, 100);
      if (args.count > 0 && w.estimates >= args.count) break;
      const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (args.timeout > 0.0 && elapsed >= args.timeout) break;
    }
    lcm_destroy(lcm);
    return 0;
  });
}

}  // namespace modalwatch::cli
