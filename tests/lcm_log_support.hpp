#pragma once
// LCM logs written by LCM itself (the file:// provider, as lcm-logger writes
// them) from a simulated CSV record, for the suites that read them back
// (test_lcm_log) and that give them to the commands (test_lcm_log_commands).
#include <lcm/lcm.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "support.hpp"

#include "modalwatch/io/config.hpp"
#include "modalwatch/io/messages.hpp"
#include "modalwatch/io/records.hpp"
#include "modalwatch/simulator.hpp"

namespace modalwatch::test_support {

inline const std::string kConfig = test_support::source_file("config/paper-sim.yaml");
inline constexpr std::int64_t kStart = 1'700'000'000'000'000;  // us

class LcmLog : public ScratchDir {
 protected:
  // The paper's closed loop, 100 s at 20 Hz (2000 samples), through CSV: what a
  // user has on disk.
  Record csv_record(const std::string& csv) {
    const Config c = load_config(kConfig);
    ExperimentSpec e = *c.experiment;
    e.duration = 100.0;
    write_record(csv, simulate(*c.plant, e).record);
    return read_record(csv);
  }
  // Writes rec with LCM's own log writer: samples (batch 1) or batches on
  // `channel`, with unrelated events in between as a real log has.
  // Returns how many pairs of unrelated events it wrote.
  int write_log(const std::string& path, const Record& rec, const std::string& channel, int batch) {
    int pairs = 0;
    lcm_t* lcm = lcm_create(("file://" + path + "?mode=w").c_str());
    EXPECT_NE(lcm, nullptr);
    if (!lcm) return 0;
    const std::string other = "not samples";
    for (Eigen::Index k = 0; k < rec.size(); k += batch) {
      const Eigen::Index n = std::min<Eigen::Index>(batch, rec.size() - k);
      std::vector<StampedSample> s(static_cast<std::size_t>(n));
      for (Eigen::Index i = 0; i < n; ++i)
        s[i] = {kStart + std::llround(rec.t(k + i) * 1e6), k + i, rec.u(k + i), rec.y(k + i), rec.r(k + i)};
      const auto msg = batch == 1 ? encode_sample(s[0]) : encode_batch(s, 0.05);
      EXPECT_EQ(lcm_publish(lcm, channel.c_str(), msg.data(), static_cast<unsigned>(msg.size())), 0);
      if (k % 500 == 0) {
        ++pairs;
        lcm_publish(lcm, "MODALWATCH_HEARTBEAT", other.data(), static_cast<unsigned>(other.size()));
        lcm_publish(lcm, "OTHER_SAMPLES", msg.data(), static_cast<unsigned>(msg.size()));
      }
    }
    lcm_destroy(lcm);
    return pairs;
  }
};

}  // namespace modalwatch::test_support
