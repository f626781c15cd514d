// Missing data through `modalwatch track` on the flexible beam (4096 Hz, a
// flexible mode at 90 Hz with zeta = 0.01): clusters of gaps and runs of
// non-finite samples are missing information, never new information. The
// flexible mode's estimate must stay with that of the same record without them,
// with no reset and no inflated standard deviation.
#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "support.hpp"

#include "modalwatch/io/csv.hpp"

namespace modalwatch {
namespace {

using test_support::Outcome;
Outcome run(const std::string& args) { return test_support::run_cli(args); }

std::string beam_config() { return test_support::source_file("config/flexible-beam.yaml"); }

constexpr double kRate = 4096.0;
constexpr double kDuration = 35.0;     // s: before the flexible mode's drift (t = 40 s)
constexpr double kFirstDamage = 12.0;  // s: well after the 5 s warm-up

// The largest difference of the flexible mode's estimate from the reference run
// at the same sample times, from kFirstDamage on: wn relative, zeta absolute,
// and the largest ratio of its std (wn and zeta).
struct Difference {
  double wn = 0.0, zeta = 0.0, std_ratio = 0.0;
  double resets = 0.0;
};

Difference difference(const Table& ref, const Table& est) {
  const int t = ref.column("t"), wn = ref.column("flex_wn"), zeta = ref.column("flex_zeta");
  const int wn_std = ref.column("flex_wn_std"), zeta_std = ref.column("flex_zeta_std"), resets = ref.column("resets");
  Difference d;
  Eigen::Index j = 0;
  for (Eigen::Index i = 0; i < est.data.rows(); ++i) {
    const long long k = std::llround(est.data(i, t) * kRate);
    while (j < ref.data.rows() && std::llround(ref.data(j, t) * kRate) < k) ++j;
    if (j == ref.data.rows() || std::llround(ref.data(j, t) * kRate) != k) continue;
    if (est.data(i, t) < kFirstDamage) continue;
    d.wn = std::max(d.wn, std::abs(est.data(i, wn) / ref.data(j, wn) - 1.0));
    d.zeta = std::max(d.zeta, std::abs(est.data(i, zeta) - ref.data(j, zeta)));
    d.std_ratio = std::max(
        {d.std_ratio, est.data(i, wn_std) / ref.data(j, wn_std), est.data(i, zeta_std) / ref.data(j, zeta_std)});
    d.resets = std::max(d.resets, est.data(i, resets));
  }
  return d;
}

// The record's rows, each line as written by `simulate` (t,r,u,y).
std::vector<std::string> rows(const std::string& csv) {
  std::ifstream in(csv);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

double time_of(const std::string& row) { return std::stod(row.substr(0, row.find(','))); }

class TrackMissingData : public test_support::ScratchDir {
 protected:
  void SetUp() override {
    ScratchDir::SetUp();
    const Outcome sim = run("simulate --config " + beam_config() + " --out " + path("clean.csv") + " --duration " +
                            std::to_string(kDuration));
    ASSERT_EQ(sim.code, 0) << sim.output;
    const Outcome r = track(path("clean.csv"), "clean_est.csv");
    ASSERT_EQ(r.code, 0) << r.output;
  }
  Outcome track(const std::string& data, const std::string& out) const {
    return run("track --no-progress --config " + beam_config() + " --data " + data + " --out " + path(out));
  }
};

// Three clusters of five 2 ms gaps 0.3 s apart, a quiet second between
// clusters: each gap restarts the prefilters from rest, and an update on their
// transient biases the lightly damped mode (zeta 0.01 went to 0.04-0.07).
TEST_F(TrackMissingData, ClustersOfGapsLeaveTheFlexibleModeAsWithoutThem) {
  std::vector<std::pair<double, double>> holes;
  double start = kFirstDamage;
  for (int cluster = 0; cluster < 3; ++cluster) {
    for (int g = 0; g < 5; ++g) holes.emplace_back(start + 0.3 * g, start + 0.3 * g + 0.002);
    start += 4 * 0.3 + 0.002 + 1.0;
  }
  std::ostringstream out;
  const auto lines = rows(path("clean.csv"));
  out << lines[0] << "\n";
  std::size_t dropped = 0;
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const double t = time_of(lines[i]);
    if (std::any_of(holes.begin(), holes.end(), [&](const auto& h) { return t > h.first && t <= h.second; })) {
      ++dropped;
      continue;
    }
    out << lines[i] << "\n";
  }
  ASSERT_GT(dropped, 100u);
  const Outcome r = track(write("gaps.csv", out.str()), "gaps_est.csv");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("gaps: 15"), std::string::npos) << r.output;
  const Difference d = difference(read_table(path("clean_est.csv")), read_table(path("gaps_est.csv")));
  EXPECT_EQ(d.resets, 0.0);
  EXPECT_LT(d.wn, 0.005);    // 0.5 % of wn
  EXPECT_LT(d.zeta, 0.005);  // half the true damping
  EXPECT_LT(d.std_ratio, 2.0);
}

// Ten NaN outputs in a row (t = 20 s) and ten infinite inputs in a row
// (t = 25 s): skipped like a gap, no reset (which froze the estimates and
// inflated their std some 50 times).
TEST_F(TrackMissingData, RunsOfNonFiniteSamplesAreSkippedWithoutAReset) {
  std::ostringstream out;
  const auto lines = rows(path("clean.csv"));
  out << lines[0] << "\n";
  int nan_y = 0, inf_u = 0;
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const double t = time_of(lines[i]);
    std::vector<std::string> cell;
    std::stringstream row(lines[i]);
    for (std::string c; std::getline(row, c, ',');) cell.push_back(c);
    ASSERT_EQ(cell.size(), 4u);  // t,r,u,y
    if (t >= 20.0 && nan_y < 10) {
      cell[3] = "nan";
      ++nan_y;
    } else if (t >= 25.0 && inf_u < 10) {
      cell[2] = "inf";
      ++inf_u;
    }
    out << cell[0] << "," << cell[1] << "," << cell[2] << "," << cell[3] << "\n";
  }
  const Outcome r = track(write("nonfinite.csv", out.str()), "nonfinite_est.csv");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("rejected non-finite: 20"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("resets: 0"), std::string::npos) << r.output;
  const Difference d = difference(read_table(path("clean_est.csv")), read_table(path("nonfinite_est.csv")));
  EXPECT_EQ(d.resets, 0.0);
  EXPECT_LT(d.wn, 0.005);
  EXPECT_LT(d.zeta, 0.005);
  EXPECT_LT(d.std_ratio, 2.0);
}

// The flexible beam whose flex mode loses 15 % stiffness over t = 30..32 s, at
// 4096 Hz in closed loop: one lost packet of 64 samples (16 ms) during the
// drift. Restarting the filters held every update for the slowest mode's
// decay and then the output error's, and the flag came 1.4-2.0 s late;
// bridged by the plant's loop with the model standing in, the updates go on.
class TrackGapDuringADrift : public test_support::ScratchDir {
 protected:
  static std::string drift_config() { return test_support::source_file("config/flexible-beam-drift.yaml"); }
  // The time flex wn is first flagged by `track --faults` on the record with
  // the samples in [hole, hole + 64 T) removed (hole < 0: none); NaN if never.
  double flex_wn_flag(double hole) {
    const std::string name = hole < 0.0 ? "clean" : "hole-" + std::to_string(hole);
    std::ostringstream out;
    const auto lines = rows(path("drift.csv"));
    out << lines[0] << "\n";
    for (std::size_t i = 1; i < lines.size(); ++i) {
      const double t = time_of(lines[i]);
      if (hole >= 0.0 && t >= hole && t < hole + 64.0 / kRate) continue;
      out << lines[i] << "\n";
    }
    const Outcome r = run("track --no-progress --config " + drift_config() + " --data " +
                          write(name + ".csv", out.str()) + " --out " + path(name + "_est.csv") + " --faults " +
                          path(name + "_flags.csv"));
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_NE(r.output.find(hole < 0.0 ? "gaps: 0" : "gaps: 1"), std::string::npos) << r.output;
    std::ifstream flags(path(name + "_flags.csv"));
    std::string line;
    std::getline(flags, line);  // header: t,mode,quantity,event,...
    while (std::getline(flags, line)) {
      if (line.find(",flex,wn,raised,") != std::string::npos) return time_of(line);
    }
    return std::nan("");
  }
  void SetUp() override {
    ScratchDir::SetUp();
    const Outcome sim = run("simulate --config " + drift_config() + " --out " + path("drift.csv"));
    ASSERT_EQ(sim.code, 0) << sim.output;
  }
};

TEST_F(TrackGapDuringADrift, ALostPacketDuringTheDriftBarelyDelaysItsFlag) {
  const double clean = flex_wn_flag(-1.0);
  ASSERT_GT(clean, 32.0);  // the flag comes once the drift is past the threshold
  ASSERT_LT(clean, 34.0);
  // At the start of the drift, and in its middle, where the model lags most.
  // (Between the square-wave setpoint's steps: a gap that holds a step is not
  // bridged, as the setpoint's path through it is not known.)
  EXPECT_NEAR(flex_wn_flag(30.15), clean, 0.25);
  EXPECT_NEAR(flex_wn_flag(31.1), clean, 0.25);
}

}  // namespace
}  // namespace modalwatch
