// modalwatch replay: a record onto LCM, as the motion controller would send it.
#include <lcm/lcm.h>
#include <time.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <span>
#include <stdexcept>
#include <vector>

#include "commands.hpp"
#include "guarded.hpp"
#include "modalwatch/io/records.hpp"

#include "modalwatch/error.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/io/messages.hpp"

namespace modalwatch::cli {
namespace {

struct LcmDeleter {
  void operator()(lcm_t* l) const { lcm_destroy(l); }
};

std::int64_t now_utime() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// Absolute sleep on the monotonic clock, so that pacing errors do not accumulate.
void sleep_until(const timespec& start, double seconds) {
  timespec when = start;
  const double whole = std::floor(seconds);
  when.tv_sec += static_cast<time_t>(whole);
  when.tv_nsec += static_cast<long>((seconds - whole) * 1e9);
  if (when.tv_nsec >= 1000000000L) {
    when.tv_sec += 1;
    when.tv_nsec -= 1000000000L;
  }
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &when, nullptr) == EINTR) {
  }
}

}  // namespace

int replay(const ReplayArgs& args) {
  return guarded("replay", [&] {
    const Config config = load_config(args.config);
    RecordReadOptions read_options;  // the daemon counts NaN samples and gaps: pass them on
    read_options.allow_nonfinite = true;
    read_options.allow_gaps = true;
    read_options.sample_time = config.sample_time;
    const RecordSource source(args.data, model_record_columns(args.columns, config.model, config.closed_loop),
                              args.channel, config.closed_loop);
    const Record rec = naming_column_options(source, [&] { return read_record(source, read_options); });
    if (config.closed_loop && !rec.has_reference())
      throw InputError(args.data, "closed loop (model.loop) needs a column 'r'");
    if (args.batch < 1) throw InputError("--batch", "must be >= 1");
    if (!(args.speed >= 0.0)) throw InputError("--speed", "must be >= 0");
    const std::string url = args.url.empty() ? config.lcm.url : args.url;
    std::unique_ptr<lcm_t, LcmDeleter> lcm(lcm_create(url.c_str()));
    if (!lcm)
      throw InputError(args.url.empty() ? config.source + ": key 'lcm.url'" : "--url", "LCM cannot open '" + url + "'");

    const bool batched = args.batch > 1;
    const std::string& channel = batched ? config.lcm.batches_channel : config.lcm.samples_channel;
    const std::int64_t start = args.start_utime ? *args.start_utime : now_utime();
    const std::int64_t offset = start - std::llround(rec.t(0) * 1e6);
    const double T = config.sample_time;
    const Eigen::Index N = rec.size();

    std::vector<StampedSample> buf(static_cast<std::size_t>(args.batch));
    timespec t0{};
    clock_gettime(CLOCK_MONOTONIC, &t0);
    const auto wall0 = std::chrono::steady_clock::now();
    std::uint64_t packets = 0, bytes = 0;
    for (Eigen::Index k = 0; k < N;) {
      // A batch is equidistant by definition: it ends early at a gap.
      Eigen::Index count = 1;
      if (batched)
        while (count < args.batch && k + count < N && std::abs(rec.t(k + count) - rec.t(k + count - 1) - T) <= 0.01 * T)
          ++count;
      // A packet leaves when its last sample has been taken.
      if (args.speed > 0.0) sleep_until(t0, (rec.t(k + count - 1) - rec.t(0)) / args.speed);
      for (Eigen::Index i = 0; i < count; ++i) {
        StampedSample& s = buf[static_cast<std::size_t>(i)];
        s.utime = offset + std::llround(rec.t(k + i) * 1e6);
        s.seq = k + i;  // sequence numbers from 0
        s.u = rec.u(k + i);
        s.y = rec.y(k + i);
        s.r = rec.has_reference() ? rec.r(k + i) : 0.0;
        s.further_inputs = rec.inputs() - 1;
        for (int j = 1; j < rec.inputs(); ++j) s.further_u[static_cast<std::size_t>(j - 1)] = rec.input(j)(k + i);
      }
      // A batch carries the configured period; its samples' utimes follow from it.
      const std::vector<std::uint8_t> msg =
          batched ? encode_batch(std::span<const StampedSample>(buf.data(), static_cast<std::size_t>(count)), T)
                  : encode_sample(buf[0]);
      if (lcm_publish(lcm.get(), channel.c_str(), msg.data(), static_cast<unsigned>(msg.size())) != 0)
        throw std::runtime_error("LCM publish on '" + channel + "' failed (" + url + ")");
      ++packets;
      bytes += msg.size();
      k += count;
    }
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
    const double span = rec.t(N - 1) - rec.t(0) + T;
    std::printf(
        "modalwatch replay: %lld samples in %llu %s packets (%llu bytes) on '%s' (%s)\n", static_cast<long long>(N),
        static_cast<unsigned long long>(packets),
        rec.inputs() > 1 ? (batched ? "sample_batch2_t" : "sample2_t") : (batched ? "sample_batch_t" : "sample_t"),
        static_cast<unsigned long long>(bytes), channel.c_str(), url.c_str());
    std::printf("%.3f s of record in %.3f s: %.0f samples/s, %.0f packets/s (%.2f x real time)\n", span, wall,
                static_cast<double>(N) / wall, static_cast<double>(packets) / wall, span / wall);
    return 0;
  });
}

}  // namespace modalwatch::cli
