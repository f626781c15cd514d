// Writes seed inputs for the fuzz targets into <dir>/checkpoint, <dir>/lcm_log
// and <dir>/messages: a checkpoint of a warmed-up estimator, a small LCM log
// with samples and batches of one input and of two and other events (written
// by LCM's own file:// provider), and one packet of each input type.
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
  std::filesystem::create_directories(dir / "messages");
  const auto write = [](const std::filesystem::path& path, const std::vector<std::uint8_t>& bytes) {
    std::ofstream(path, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  };

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
  // Two inputs: the same samples with a second input, as sample2_t and sample_batch2_t.
  std::vector<StampedSample> two = batch;
  for (std::size_t k = 0; k < two.size(); ++k) {
    two[k].utime += 1000000;
    two[k].seq += 100;
    two[k].further_inputs = 1;
    two[k].further_u[0] = 0.5 - 0.1 * static_cast<double>(k);
  }
  const auto s2 = encode_sample2(two[0]);
  const auto b2 = encode_batch2(two, 0.05);
  lcm_publish(lcm, "MODALWATCH_SAMPLES", s2.data(), static_cast<unsigned>(s2.size()));
  lcm_publish(lcm, "MODALWATCH_BATCHES", b2.data(), static_cast<unsigned>(b2.size()));
  write(dir / "messages" / "sample.bin", encode_sample(batch[0]));
  write(dir / "messages" / "batch.bin", b);
  write(dir / "messages" / "sample2.bin", s2);
  write(dir / "messages" / "batch2.bin", b2);
  const std::string other = "heartbeat";
  lcm_publish(lcm, "OTHER", other.data(), static_cast<unsigned>(other.size()));
  lcm_destroy(lcm);
  std::printf("seeds in %s\n", dir.c_str());
  return 0;
}
