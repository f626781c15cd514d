// modalwatch_network_weather: publishes a record on LCM as a controller behind
// a bad network would, for scripts/check/network_weather.sh. Batches of
// --batch samples at --speed times real time, with, drawn from --seed:
//   --loss P          each packet lost with probability P (never sent)
//   --duplicate P     each packet sent twice with probability P
//   --reorder P       each packet held and sent after the next with probability P
//   --gap-clusters N  N clusters of three controller pauses (20-60 ms each,
//                     150 ms apart): samples that never exist, seq goes on
//   --nan-bursts N    N bursts of 5-50 samples with y = NaN
//   --restart-at T    (repeatable) at record time T the sender restarts: seq
//                     and utime start again from 0 and --start-utime
// Events start after --quiet-until s of record time (the warm-up) and keep
// --clear-of s away from each --clear-at time (the fault's flag time).
// At the end it prints what it did, one key=value per line, for the script's
// sums, and one "restart record_t=T" line per restart.
#include <lcm/lcm.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>

#include "modalwatch/error.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/io/messages.hpp"
#include "modalwatch/io/records.hpp"

namespace {

using namespace modalwatch;

struct Span {
  double begin, end;  // record time, s
};

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"modalwatch_network_weather: a record onto LCM through bad weather"};
  std::string config_path, data, url;
  double speed = 1.0, loss = 0.0, duplicate = 0.0, reorder = 0.0, quiet_until = 6.0, clear_of = 3.0;
  int batch = 64, gap_clusters = 0, nan_bursts = 0;
  unsigned seed = 1;
  std::int64_t start_utime = 1'000'000;
  std::vector<double> restarts, clear_at;
  app.add_option("--config", config_path)->required();
  app.add_option("--data", data)->required();
  app.add_option("--url", url);
  app.add_option("--speed", speed);
  app.add_option("--batch", batch);
  app.add_option("--seed", seed);
  app.add_option("--loss", loss);
  app.add_option("--duplicate", duplicate);
  app.add_option("--reorder", reorder);
  app.add_option("--gap-clusters", gap_clusters);
  app.add_option("--nan-bursts", nan_bursts);
  app.add_option("--restart-at", restarts);
  app.add_option("--start-utime", start_utime);
  app.add_option("--quiet-until", quiet_until);
  app.add_option("--clear-at", clear_at);
  app.add_option("--clear-of", clear_of);
  CLI11_PARSE(app, argc, argv);
  try {
    const Config config = load_config(config_path);
    RecordReadOptions options;
    options.sample_time = config.sample_time;
    const Record rec = read_record(RecordSource(data, {}, {}, config.closed_loop), options);
    const Eigen::Index N = rec.size();
    const double T = config.sample_time;
    const double t_end = rec.t(N - 1);
    lcm_t* lcm = lcm_create((url.empty() ? config.lcm.url : url).c_str());
    if (!lcm) throw std::runtime_error("cannot open LCM " + url);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    // A time for an event, away from the fault's flag time and the restarts.
    const auto event_time = [&](double length) {
      for (;;) {
        const double t = quiet_until + unit(rng) * (t_end - quiet_until - length - 1.0);
        bool clear = true;
        for (double c : clear_at) clear = clear && (t + length < c - clear_of || t > c + clear_of);
        for (double r : restarts) clear = clear && std::abs(t - r) > 1.0;
        if (clear) return t;
      }
    };
    std::vector<Span> pauses, nans;
    for (int c = 0; c < gap_clusters; ++c) {
      double t = event_time(0.6);
      for (int i = 0; i < 3; ++i, t += 0.15) pauses.push_back({t, t + 0.02 + 0.04 * unit(rng)});
    }
    for (int b = 0; b < nan_bursts; ++b) {
      const double t = event_time(0.02);
      nans.push_back({t, t + (5 + static_cast<int>(unit(rng) * 45)) * T});
    }
    std::sort(restarts.begin(), restarts.end());
    const auto inside = [](const std::vector<Span>& spans, double t) {
      for (const Span& s : spans)
        if (t >= s.begin && t < s.end) return true;
      return false;
    };

    std::uint64_t packets = 0, sent_unique = 0, lost = 0, duplicated = 0, late = 0, nan_sent = 0, skipped = 0;
    std::size_t next_restart = 0;
    std::int64_t seq = 0;
    double epoch_t = rec.t(0);       // record time of utime = start_utime
    std::vector<std::uint8_t> held;  // a packet held back to be sent after the next
    std::uint64_t held_samples = 0;
    const auto publish = [&](const std::vector<std::uint8_t>& bytes) {
      lcm_publish(lcm, config.lcm.batches_channel.c_str(), bytes.data(), static_cast<unsigned>(bytes.size()));
      ++packets;
    };
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<StampedSample> buf;
    for (Eigen::Index k = 0; k < N;) {
      const double t = rec.t(k);
      if (next_restart < restarts.size() && t >= restarts[next_restart]) {
        ++next_restart;
        seq = 0;
        epoch_t = t;
        std::printf("restart record_t=%.6f\n", t);
      }
      if (inside(pauses, t)) {  // the controller paused: no sample, no seq
        ++skipped;
        ++k;
        continue;
      }
      // One packet: up to `batch` samples, ending at a pause or a restart.
      buf.clear();
      while (k < N && static_cast<int>(buf.size()) < batch) {
        const double tk = rec.t(k);
        if (inside(pauses, tk) || (next_restart < restarts.size() && tk >= restarts[next_restart])) break;
        StampedSample s;
        s.utime = start_utime + std::llround((tk - epoch_t) * 1e6);
        s.seq = seq++;
        s.u = rec.u(k);
        s.y = inside(nans, tk) ? std::numeric_limits<double>::quiet_NaN() : rec.y(k);
        s.r = rec.has_reference() ? rec.r(k) : 0.0;
        buf.push_back(s);
        ++k;
      }
      std::this_thread::sleep_until(t0 + std::chrono::duration<double>((rec.t(k - 1) - rec.t(0)) / speed));
      const auto n = static_cast<std::uint64_t>(buf.size());
      const bool weather = t >= quiet_until;
      if (weather && unit(rng) < loss) {
        lost += n;
        continue;
      }
      const std::vector<std::uint8_t> bytes = encode_batch(buf, T);
      std::uint64_t nan_here = 0;
      for (const StampedSample& s : buf) nan_here += std::isnan(s.y) ? 1 : 0;
      sent_unique += n;
      nan_sent += nan_here;
      if (weather && held.empty() && unit(rng) < reorder) {
        held = bytes;
        held_samples = n;
        continue;
      }
      publish(bytes);
      if (!held.empty()) {
        publish(held);
        late += held_samples;
        held.clear();
      }
      if (weather && unit(rng) < duplicate) {
        publish(bytes);
        duplicated += n;
      }
    }
    if (!held.empty()) publish(held);  // at the end it is merely the last
    lcm_destroy(lcm);
    std::printf(
        "packets=%llu\nsent_unique=%llu\nlost=%llu\nduplicated=%llu\nlate=%llu\nnan_sent=%llu\n"
        "skipped=%llu\npauses=%zu\nnan_bursts=%zu\nrestarts=%zu\n",
        static_cast<unsigned long long>(packets), static_cast<unsigned long long>(sent_unique),
        static_cast<unsigned long long>(lost), static_cast<unsigned long long>(duplicated),
        static_cast<unsigned long long>(late), static_cast<unsigned long long>(nan_sent),
        static_cast<unsigned long long>(skipped), pauses.size(), nans.size(), restarts.size());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "modalwatch_network_weather: %s\n", e.what());
    return 2;
  }
}
