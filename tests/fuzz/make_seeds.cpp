// Writes seed inputs for the fuzz targets into <dir>/checkpoint and <dir>/lcm_log:
// a checkpoint of a warmed-up estimator and a small LCM log with samples,
// batches and other events (written by LCM's own file:// provider).
#include <lcm/lcm.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "modalwatch/io/checkpoint.hpp"
#include "modalwatch/io/messages.hpp"

using namespace modalwatch;

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_seeds DIR\n");
    return 2;
  }
  const std::filesystem::path dir = std::filesystem::absolute(argv[1]);
  std::filesystem::create_directories(dir / "checkpoint");
  std::filesystem::create_directories(dir / "lcm_log");

  AdditiveModel m;
  m.submodels = {make_mode("mode1", {2.0, 0.25, 3.0}), make_mode("mode2", {5.0, 0.025, 0.5}),
                 make_mode("mode3", {20.0, 0.1, 1.0})};
  EstimatorSettings s;
  s.sample_time = 0.05;
  RecursiveEstimator est(m, s);
  for (int k = 0; k < 400; ++k) {
    const double t = k * 0.05, u = std::sin(0.9 * t) + std::sin(4.7 * t) + std::sin(19.0 * t);
    est.step({t, u, 0.8 * u, u});
  }
  Checkpoint c;
  c.estimator = est.state();
  // One learned baseline with its covariance, one mode still learning, one configured.
  c.baselines = {ModeBaseline{{2.0, 0.25, 3.0}, {1e-4, 1e-6, 2e-5, 1e-6, 4e-6, 0.0, 2e-5, 0.0, 9e-4}, true},
                 std::nullopt, ModeBaseline{{20.0, 0.1, 1.0}, {}, false}};
  const auto bytes = encode_checkpoint(c);
  std::ofstream(dir / "checkpoint" / "warm.bin", std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));

  const std::string url = "file://" + (dir / "lcm_log" / "samples.lcm").string() + "?mode=w";
  lcm_t* lcm = lcm_create(url.c_str());
  if (!lcm) return 1;
  std::vector<StampedSample> batch;
  for (int k = 0; k < 12; ++k) {
    const StampedSample r{1000000 + 50000 * k, k, 0.1 * k, -0.2 * k, 0.3};
    const auto msg = encode_sample(r);
    lcm_publish(lcm, "MODALWATCH_SAMPLES", msg.data(), static_cast<unsigned>(msg.size()));
    batch.push_back({r.utime + 1000000, k + 100, r.u, r.y, r.r});
  }
  const auto b = encode_batch(batch, 0.05);
  lcm_publish(lcm, "MODALWATCH_BATCHES", b.data(), static_cast<unsigned>(b.size()));
  const std::string other = "heartbeat";
  lcm_publish(lcm, "OTHER", other.data(), static_cast<unsigned>(other.size()));
  lcm_destroy(lcm);
  std::printf("seeds in %s\n", dir.c_str());
  return 0;
}
