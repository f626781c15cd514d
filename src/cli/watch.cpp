// `modalwatch watch`: subscribes to the daemon's estimates and fault status
// (the channels of the config's lcm: section) and prints one line per message.
#include <lcm/lcm.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>

#include <modalwatch/estimates_t.hpp>
#include <modalwatch/fault_status_t.hpp>

#include "commands.hpp"
#include "guarded.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/error.hpp"

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

void on_fault_status(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  auto& w = *static_cast<Watcher*>(user);
  Fault msg;
  if (msg.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) < 0) {
    std::printf("fault status: undecodable message (%u bytes)\n", rbuf->data_size);
    return;
  }
  if (w.statuses++ % w.args->every != 0) return;
  static const char* quantity[3] = {"wn", "zeta", "gain"};
  std::string flags;
  char buf[256];
  bool suppressed = false;
  for (int e = 0; e < msg.n_entries && e / 3 < msg.n_modes; ++e) {
    const int f = msg.flags[static_cast<std::size_t>(e)];
    if (f & Fault::FLAG_SUPPRESSED) suppressed = true;
    if (!(f & (static_cast<int>(Fault::FLAG_RAISED) | static_cast<int>(Fault::FLAG_PENDING)))) continue;
    std::snprintf(buf, sizeof buf, "%s%s.%s %s (%+.2f %%, %+.1f sigma)", flags.empty() ? "" : ", ",
                  msg.mode_names[static_cast<std::size_t>(e / 3)].c_str(), quantity[e % 3],
                  (f & Fault::FLAG_RAISED) ? "FLAGGED" : "pending", msg.deviation_percent[static_cast<std::size_t>(e)],
                  msg.deviation_sigma[static_cast<std::size_t>(e)]);
    flags += buf;
  }
  if (flags.empty()) flags = suppressed ? "none (suppressed: warm-up or low excitation)" : "none";
  std::string health;
  const std::pair<int, const char*> bits[] = {{Fault::HEALTH_ESTIMATOR_RESET, "estimator-reset"},
                                              {Fault::HEALTH_INPUT_GAP, "input-gap"},
                                              {Fault::HEALTH_RING_OVERFLOW, "ring-overflow"},
                                              {Fault::HEALTH_LOW_EXCITATION, "low-excitation"},
                                              {Fault::HEALTH_STALE_INPUT, "stale-input"},
                                              {Fault::HEALTH_DECODE_ERRORS, "decode-errors"}};
  for (const auto& [bit, name] : bits)
    if (msg.health & bit) (health += health.empty() ? "" : ",") += name;
  if (health.empty()) health = "ok";
  std::printf("faults    t = %9.3f s  | flags: %s | health: %s | received %lld, dropped %lld, nonfinite %lld, "
              "dup %lld, ooo %lld, gaps %lld, decode errors %lld\n",
              static_cast<double>(msg.utime) * 1e-6, flags.c_str(), health.c_str(),
              static_cast<long long>(msg.samples_received), static_cast<long long>(msg.samples_dropped),
              static_cast<long long>(msg.samples_nonfinite), static_cast<long long>(msg.samples_duplicate),
              static_cast<long long>(msg.samples_out_of_order), static_cast<long long>(msg.gaps),
              static_cast<long long>(msg.decode_errors));
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
