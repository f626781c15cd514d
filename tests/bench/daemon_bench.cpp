// modalwatch_daemon_bench: drives a running modalwatchd over LCM for
// scripts/measure/daemon_bench.sh (records are published by `modalwatch replay`).
//
//   latency  --config C --data D.csv --rate R --seconds S
//            one sample_t per packet at R Hz (cycling the record); sample k has
//            utime = start + k / R on the wall clock (CLOCK_REALTIME) and is sent
//            at that time; listens to the estimates and prints p50/p99/max of
//            (delivery time - utime of the newest sample included), split into
//            the sender's lateness (its send time - utime) and the rest, and the
//            daemon's drop counters. The delivery time is LCM's receive stamp
//            (the kernel's SO_TIMESTAMP of the datagram, else LCM's receive
//            thread's clock), not when this process got round to running its
//            handler thread (printed apart: it is this bench's own scheduling).
//            --trace F writes one line per estimate.
//   rate     --config C --data D.csv --rate R --seconds S [--batch N]
//            batches at R samples/s of wall time, the samples on the config's
//            sample grid (replay R / sample_rate_hz times faster than real
//            time); prints sent, received, dropped and processed.
//   machine  --seconds S
//            the machine's own latency floor, with nothing of modalwatch in it:
//            on every CPU at once, a thread sleeping to an absolute 500 us grid
//            measures its wake-up lateness (S/2 s), then a thread spinning on the
//            clock records every gap over 50 us, time the CPU was taken from it
//            (interrupts, higher-priority threads, and in a VM the host; S/2 s),
//            with the steal time /proc/stat counted meanwhile. Run under chrt
//            like the daemon, these bound what any wake-up on the latency path
//            can achieve: the path from a sample to its estimate has four.
#include <lcm/lcm.h>
#include <pthread.h>
#include <sched.h>
#include <sys/prctl.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>

#include <modalwatch/estimates_t.hpp>
#include <modalwatch/fault_status_t.hpp>

#include "modalwatch/error.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/io/messages.hpp"
#include "modalwatch/io/records.hpp"

namespace {

using namespace modalwatch;

std::int64_t realtime_us() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000 + ts.tv_nsec / 1000;
}

struct Listener {
  std::mutex mutex;
  struct Arrival {
    std::int64_t utime;    // of the estimate: its newest sample
    std::int64_t stamp;    // LCM's receive stamp (see the top of the file)
    std::int64_t handled;  // when this handler ran
  };
  std::vector<Arrival> arrivals;
  modalwatch::fault_status_t last_status;
  bool have_status = false;
  long long estimates = 0;
  long long processed = 0;  // samples_processed of the newest estimates
};

void on_estimates(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  const std::int64_t now = realtime_us();
  auto& l = *static_cast<Listener*>(user);
  modalwatch::estimates_t msg;
  if (msg.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) < 0) return;
  std::lock_guard<std::mutex> lock(l.mutex);
  l.arrivals.push_back({msg.utime, rbuf->recv_utime, now});
  ++l.estimates;
  l.processed = msg.samples_processed;
}

void on_status(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  auto& l = *static_cast<Listener*>(user);
  modalwatch::fault_status_t msg;
  if (msg.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) < 0) return;
  std::lock_guard<std::mutex> lock(l.mutex);
  l.last_status = msg;
  l.have_status = true;
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const auto i =
      static_cast<std::size_t>(std::min<double>(static_cast<double>(v.size() - 1), p * static_cast<double>(v.size())));
  return v[i];
}

// Sleeps until the wall-clock time `us` (absolute, CLOCK_REALTIME: the clock utime is on).
void sleep_until_us(std::int64_t us) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(us / 1'000'000);
  ts.tv_nsec = static_cast<long>(us % 1'000'000) * 1000;
  while (clock_nanosleep(CLOCK_REALTIME, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

void print_stats(const char* what, std::vector<double> v) {
  std::printf("    %-44s p50 %6.0f  p99 %6.0f  max %6.0f\n", what, percentile(v, 0.5), percentile(v, 0.99),
              percentile(v, 1.0));
}

std::int64_t mono_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// Steal time of all CPUs so far, in clock ticks (/proc/stat's 8th cpu column).
long long steal_ticks() {
  std::ifstream in("/proc/stat");
  std::string line;
  std::getline(in, line);
  std::istringstream fields(line);
  std::string cpu;
  long long v[8] = {};
  fields >> cpu;
  for (long long& x : v) fields >> x;
  return v[7];
}

// One thread per CPU, pinned, all running `body` at once.
template <class Body>
void on_every_cpu(int cpus, Body body) {
  std::vector<std::thread> threads;
  for (int c = 0; c < cpus; ++c)
    threads.emplace_back([c, &body] {
      cpu_set_t set;
      CPU_ZERO(&set);
      CPU_SET(c, &set);
      pthread_setaffinity_np(pthread_self(), sizeof set, &set);
      prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
      body(c);
    });
  for (auto& t : threads) t.join();
}

int machine_floor(double seconds) {
  const int cpus = static_cast<int>(sysconf(_SC_NPROCESSORS_ONLN));
  const double half = seconds / 2;
  const long long t0_steal = steal_ticks();
  const auto t0 = std::chrono::steady_clock::now();

  // 1. Timer wake-ups on a 500 us grid (the daemon's loop and publisher sleep so).
  constexpr std::int64_t kPeriod = 500'000;
  std::vector<std::vector<double>> late(static_cast<std::size_t>(cpus));
  on_every_cpu(cpus, [&](int c) {
    auto& v = late[static_cast<std::size_t>(c)];
    const auto n = static_cast<std::size_t>(half * 1e9 / kPeriod);
    v.reserve(n);
    std::int64_t next = mono_ns();
    for (std::size_t i = 0; i < n; ++i) {
      next += kPeriod;
      timespec ts{static_cast<time_t>(next / 1'000'000'000), static_cast<long>(next % 1'000'000'000)};
      while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
      }
      v.push_back(static_cast<double>(mono_ns() - next) * 1e-3);
    }
  });
  std::vector<double> all;
  for (const auto& v : late) all.insert(all.end(), v.begin(), v.end());
  const auto over_1ms = std::count_if(all.begin(), all.end(), [](double x) { return x > 1000.0; });
  const double p_over = static_cast<double>(over_1ms) / static_cast<double>(all.size());
  std::printf("machine: %d CPUs, %.0f s per probe\n", cpus, half);
  std::printf(
      "  timer wake-up lateness (us), %zu wake-ups: p50 %.0f  p99 %.0f  p99.9 %.0f  max %.0f;"
      " over 1 ms: %.3f %%\n",
      all.size(), percentile(all, 0.5), percentile(all, 0.99), percentile(all, 0.999), percentile(all, 1.0),
      100 * p_over);
  std::printf("    a path of 4 such wake-ups is over 1 ms at least %.2f %% of the time (1 - (1 - p)^4)\n",
              100 * (1 - std::pow(1 - p_over, 4)));

  // 2. Time taken from a spinning thread. It spins in 500 ms windows with 100 ms
  // of sleep between them: a SCHED_FIFO thread that spins longer is throttled
  // by the kernel (sched_rt_runtime_us, 950 ms of every second), which would
  // show up as 50 ms gaps that no real-time thread of the daemon ever meets.
  struct Gaps {
    long long over_50us = 0, over_1ms = 0;
    double lost_ns = 0, max_us = 0, spun_ns = 0;
  };
  std::vector<Gaps> gaps(static_cast<std::size_t>(cpus));
  on_every_cpu(cpus, [&](int c) {
    Gaps& g = gaps[static_cast<std::size_t>(c)];
    const std::int64_t end = mono_ns() + static_cast<std::int64_t>(half * 1e9);
    for (std::int64_t start = mono_ns(); start < end; start = mono_ns()) {
      const std::int64_t window_end = std::min(end, start + 500'000'000);
      std::int64_t prev = start;
      while (prev < window_end) {
        const std::int64_t t = mono_ns();
        const std::int64_t d = t - prev;
        if (d > 50'000) {
          ++g.over_50us;
          g.lost_ns += static_cast<double>(d);
          g.max_us = std::max(g.max_us, static_cast<double>(d) * 1e-3);
          if (d > 1'000'000) ++g.over_1ms;
        }
        prev = t;
      }
      g.spun_ns += static_cast<double>(prev - start);
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  });
  for (int c = 0; c < cpus; ++c) {
    const Gaps& g = gaps[static_cast<std::size_t>(c)];
    std::printf(
        "  CPU %d taken from a spinning thread: %lld gaps over 50 us, %lld over 1 ms (%.2f per s), longest %.0f us,"
        " %.2f %% of the time\n",
        c, g.over_50us, g.over_1ms, static_cast<double>(g.over_1ms) / (g.spun_ns * 1e-9), g.max_us,
        100 * g.lost_ns / g.spun_ns);
  }
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("  steal time (the host running something else on our CPUs): %.2f %% of CPU time\n",
              100.0 * static_cast<double>(steal_ticks() - t0_steal) / static_cast<double>(sysconf(_SC_CLK_TCK)) /
                  (elapsed * cpus));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"modalwatch_daemon_bench: benchmark driver for modalwatchd"};
  app.require_subcommand(1);
  std::string config_path, data_path;
  std::string trace_path;
  double rate = 4096.0, seconds = 10.0, skip = 6.0;
  int batch = 64;
  for (const char* name : {"latency", "rate"}) {
    auto* sub = app.add_subcommand(name, name);
    sub->add_option("--config,-c", config_path)->required();
    sub->add_option("--data,-d", data_path)->required();
    sub->add_option("--rate", rate);
    sub->add_option("--seconds", seconds);
    sub->add_option("--batch", batch)->check(CLI::Range(1, 8192));
    sub->add_option("--skip", skip, "latency: ignore estimates of the first SKIP s (warm-up fit)");
    sub->add_option("--trace", trace_path, "latency: one CSV line per estimate (utime, send time, arrival; us)");
  }
  auto* machine = app.add_subcommand("machine", "the machine's own wake-up latency and preemption");
  machine->add_option("--seconds", seconds);
  CLI11_PARSE(app, argc, argv);
  const std::string mode = app.get_subcommands().front()->get_name();
  if (mode == "machine") return machine_floor(seconds);
  try {
    const Config config = load_config(config_path);
    RecordReadOptions opts;
    opts.sample_time = config.sample_time;
    const Record rec = read_record(data_path, opts);
    lcm_t* lcm = lcm_create(config.lcm.url.c_str());
    if (!lcm) throw InputError(config_path, "cannot open LCM provider " + config.lcm.url);
    Listener listener;
    std::atomic<bool> stop{false};
    std::thread handler;
    lcm_subscribe(lcm, config.lcm.estimates_channel.c_str(), &on_estimates, &listener);
    lcm_subscribe(lcm, config.lcm.fault_status_channel.c_str(), &on_status, &listener);
    handler = std::thread([&] {
      while (!stop) lcm_handle_timeout(lcm, 20);
    });
    const Eigen::Index n = rec.size();
    const auto t0 = std::chrono::steady_clock::now();
    // Linux delays a sleeper's wake-up by up to its timer slack (50 us by
    // default): a sender late by that much would count as the daemon's latency.
    prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
    {
      const long long total = std::llround(rate * seconds);
      const double period = 1.0 / rate;                                     // wall clock
      const double grid = mode == "latency" ? period : config.sample_time;  // utime
      const int per_packet = mode == "latency" ? 1 : batch;
      const std::int64_t start_us = realtime_us() + 10'000;
      std::vector<StampedSample> buf(static_cast<std::size_t>(per_packet));
      std::vector<std::int64_t> sent_us(static_cast<std::size_t>(total), 0);  // wall clock after lcm_publish
      for (long long k = 0; k < total; k += per_packet) {
        const int m = static_cast<int>(std::min<long long>(per_packet, total - k));
        sleep_until_us(start_us + std::llround(static_cast<double>(k + m - 1) * period * 1e6));
        for (int i = 0; i < m; ++i) {
          const Eigen::Index j = (k + i) % n;
          auto& s = buf[static_cast<std::size_t>(i)];
          s.seq = k + i;
          s.utime = start_us + std::llround(static_cast<double>(k + i) * grid * 1e6);
          s.u = rec.u(j);
          s.y = rec.y(j);
          s.r = rec.has_reference() ? rec.r(j) : 0.0;
        }
        const auto bytes = m == 1 && mode == "latency"
                               ? encode_sample(buf[0])
                               : encode_batch(std::span<const StampedSample>(buf.data(), m), grid);
        if (m == 1 && mode == "latency")
          lcm_publish(lcm, config.lcm.samples_channel.c_str(), bytes.data(), static_cast<unsigned>(bytes.size()));
        else
          lcm_publish(lcm, config.lcm.batches_channel.c_str(), bytes.data(), static_cast<unsigned>(bytes.size()));
        sent_us[static_cast<std::size_t>(k + m - 1)] = realtime_us();
      }
      const double sent_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      // The daemon works through its backlog (sample time: a publish period of
      // samples must arrive before the next estimate), then the last status messages.
      std::this_thread::sleep_for(std::chrono::milliseconds(mode == "latency" ? 1500 : 4000));
      stop = true;
      handler.join();
      std::lock_guard<std::mutex> lock(listener.mutex);
      std::printf("%s: %lld samples in %.2f s (%.0f samples/s offered, %d per packet)\n", mode.c_str(), total, sent_s,
                  static_cast<double>(total) / sent_s, per_packet);
      if (listener.have_status) {
        const auto& s = listener.last_status;
        std::printf(
            "  daemon: sent %lld, received %lld, dropped %lld (ring full), processed %lld, duplicate %lld, out of "
            "order %lld, gaps %lld\n",
            total, static_cast<long long>(s.samples_received), static_cast<long long>(s.samples_dropped),
            listener.processed, static_cast<long long>(s.samples_duplicate),
            static_cast<long long>(s.samples_out_of_order), static_cast<long long>(s.gaps));
      } else {
        std::printf("  daemon: no fault status received\n");
      }
      if (mode == "latency") {
        // Without the warm-up window, its fit and the catch-up on the input held meanwhile.
        // The newest sample of an estimate is found from its utime (utime = start + k / R).
        // Delivery is LCM's receive stamp (see the top of the file); on loopback it
        // follows the daemon's lcm_publish by tens of microseconds.
        std::vector<double> delivered, late_sender, after_send, bench_receive, handled;
        std::FILE* trace = trace_path.empty() ? nullptr : std::fopen(trace_path.c_str(), "w");
        if (trace) std::fprintf(trace, "utime,seq,sent,stamp,handled\n");
        for (const auto& a : listener.arrivals) {
          if (a.utime < start_us + std::llround(skip * 1e6)) continue;
          const long long k = std::llround(static_cast<double>(a.utime - start_us) * 1e-6 / grid);
          if (k < 0 || k >= total || sent_us[static_cast<std::size_t>(k)] == 0) continue;
          const std::int64_t sent = sent_us[static_cast<std::size_t>(k)];
          delivered.push_back(static_cast<double>(a.stamp - a.utime));
          late_sender.push_back(static_cast<double>(sent - a.utime));
          after_send.push_back(static_cast<double>(a.stamp - sent));
          bench_receive.push_back(static_cast<double>(a.handled - a.stamp));
          handled.push_back(static_cast<double>(a.handled - a.utime));
          if (trace)
            std::fprintf(trace, "%lld,%lld,%lld,%lld,%lld\n", static_cast<long long>(a.utime), k,
                         static_cast<long long>(sent), static_cast<long long>(a.stamp),
                         static_cast<long long>(a.handled));
        }
        if (trace) std::fclose(trace);
        std::printf("  latency (us) over %zu estimates after the first %.0f s:\n", delivered.size(), skip);
        print_stats("sample utime -> estimate delivered", delivered);
        print_stats("  the sender's lateness (sent - utime)", late_sender);
        print_stats("  sample sent -> estimate delivered", after_send);
        print_stats("(delivered -> this bench's handler)", bench_receive);
        print_stats("(sample utime -> this bench's handler)", handled);
      }
    }
    lcm_destroy(lcm);
    return 0;
  } catch (const InputError& e) {
    std::fprintf(stderr, "modalwatch_daemon_bench: %s\n", e.what());
    return 2;
  }
}
