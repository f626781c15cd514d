// `modalwatch track` as a user meets it: the real binary on real files, exit
// codes, est.csv's layout, and the summary on stderr. Accuracy is asserted in
// test_estimator, not here.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "../src/cli/number_format.hpp"
#include "support.hpp"

#include "modalwatch/io/csv.hpp"

namespace fs = std::filesystem;

namespace modalwatch {
namespace {

using test_support::Outcome;
Outcome run(const std::string& args) { return test_support::run_cli(args); }

bool contains(const std::string& text, const std::string& what) { return text.find(what) != std::string::npos; }

// The number after `key: ` in the summary, -1 when absent.
long long summary_count(const std::string& output, const std::string& key) {
  const std::string label = "\n  " + key + ": ";
  const auto at = output.find(label);
  if (at == std::string::npos) return -1;
  const std::size_t begin = at + label.size();
  std::size_t end = begin;
  while (end < output.size() && output[end] >= '0' && output[end] <= '9') ++end;
  return end > begin ? std::stoll(output.substr(begin, end - begin)) : -1;
}

std::string paper_config() { return test_support::source_file("config/paper-sim.yaml"); }

std::string expected_header() {
  std::string h = "t";
  for (const char* mode : {"mode1", "mode2", "mode3"})
    for (const char* q : {"_wn", "_zeta", "_gain", "_wn_std", "_zeta_std", "_gain_std"})
      h += std::string(",") + mode + q;
  return h + ",residual_rms,flags,resets";
}

class Track : public test_support::ScratchDir {
 public:
  Outcome track(const std::string& data, const std::string& out = "est.csv") const {
    return run("track --config " + paper_config() + " --data " + data + " --out " + path(out));
  }
  // Only the files a test wrote itself: no est.csv, no temporary left behind.
  std::vector<std::string> files() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir_)) names.push_back(e.path().filename().string());
    return names;
  }
};

std::string first_line(const std::string& file) {
  std::ifstream in(file);
  std::string line;
  std::getline(in, line);
  return line;
}

void expect_all_finite(const Table& est) {
  for (Eigen::Index i = 0; i < est.data.rows(); ++i)
    for (Eigen::Index j = 0; j < est.data.cols(); ++j)
      ASSERT_TRUE(std::isfinite(est.data(i, j))) << "row " << i + 2 << ", column " << est.columns[j];
}

TEST_F(Track, SimulatedRecordGivesOneFiniteRowPerSample) {
  const Outcome sim = run("simulate --config " + paper_config() + " --out " + path("d.csv") + " --duration 120");
  ASSERT_EQ(sim.code, 0) << sim.output;
  const Outcome r = track(path("d.csv"));
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(first_line(path("est.csv")), expected_header());
  const Table est = read_table(path("est.csv"));  // read_table rejects NaN and Inf
  EXPECT_EQ(est.data.rows(), 2400);
  expect_all_finite(est);
  const Table d = read_table(path("d.csv"));
  EXPECT_TRUE(est.data.col(0) == d.data.col(d.column("t")));
  // Summary on stderr, the modal table on stdout; no progress bar when stderr is not a terminal.
  for (const char* s : {"samples/s", "updates: ", "resets: ", "warm-up fit", "mode1", "mode3", "f [Hz]", "zeta"})
    EXPECT_TRUE(contains(r.output, s)) << s << "\n" << r.output;
  EXPECT_FALSE(contains(r.output, "\r")) << r.output;
  EXPECT_EQ(summary_count(r.output, "rejected non-finite"), 0) << r.output;
  EXPECT_EQ(summary_count(r.output, "gaps"), 0) << r.output;
  EXPECT_EQ(files().size(), 2u);  // d.csv and est.csv, no temporary left behind
}

// A record with a NaN sample, a 10 s gap, a sample of 1e12
// and 60 s of zero input (and setpoint) in the simulated closed-loop record.
std::string damaged_record(const std::string& clean_csv) {
  const Table d = read_table(clean_csv);
  const int ct = d.column("t"), cr = d.column("r"), cu = d.column("u"), cy = d.column("y");
  std::ostringstream out;
  out.precision(17);
  out << "t,r,u,y\n";
  for (Eigen::Index k = 0; k < d.data.rows(); ++k) {
    const double t = d.data(k, ct);
    double r = d.data(k, cr), u = d.data(k, cu), y = d.data(k, cy);
    if (t > 80.0 && t <= 90.0) continue;  // 10 s gap
    if (t > 150.0 && t <= 210.0) {
      // No input, no setpoint: the output is the noise alone (std 0.1, deterministic here).
      r = 0.0;
      u = 0.0;
      y = 0.1 * std::sin(12.9898 * static_cast<double>(k));
    }
    if (k == 1200) {  // t = 60
      out << t << "," << r << "," << u << ",nan\n";
      continue;
    }
    if (k == 2000) y = 1e12;  // t = 100
    out << t << "," << r << "," << u << "," << y << "\n";
  }
  return out.str();
}

TEST_F(Track, NaNGapOutlierAndSilenceAreCountedNeverNaN) {
  const Outcome sim = run("simulate --config " + paper_config() + " --out " + path("clean.csv") + " --duration 260");
  ASSERT_EQ(sim.code, 0) << sim.output;
  const std::string data = write("damaged.csv", damaged_record(path("clean.csv")));
  const Outcome r = track(data);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(first_line(path("est.csv")), expected_header());
  const Table est = read_table(path("est.csv"));
  EXPECT_EQ(est.data.rows(), 5200 - 200);  // one row per input row, the NaN row included
  expect_all_finite(est);

  EXPECT_EQ(summary_count(r.output, "rejected non-finite"), 1) << r.output;
  EXPECT_EQ(summary_count(r.output, "gaps"), 1) << r.output;
  EXPECT_GE(summary_count(r.output, "outliers"), 1) << r.output;
  EXPECT_GT(summary_count(r.output, "low-excitation samples"), 0) << r.output;
  // Visible per sample too: the flags column.
  const int flags = est.column("flags");
  unsigned all = 0;
  for (Eigen::Index k = 0; k < est.data.rows(); ++k) all |= static_cast<unsigned>(est.data(k, flags));
  EXPECT_TRUE(all & (1u << 1)) << "no sample flagged non-finite";
  EXPECT_TRUE(all & (1u << 3)) << "no sample flagged as a gap";
  EXPECT_TRUE(all & (1u << 4)) << "no sample flagged as an outlier";
}

TEST_F(Track, MissingDataFileIsBadInputAndWritesNothing) {
  const Outcome r = track(path("nonexistent.csv"));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_TRUE(contains(r.output, "nonexistent.csv")) << r.output;
  EXPECT_TRUE(files().empty());
}

TEST_F(Track, WrongColumnsAreBadInputAndWriteNothing) {
  const std::string data = write("bad.csv", "t,a,b\n0,0,0\n0.05,0,0\n0.1,0,0\n");
  const Outcome r = track(data);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_TRUE(contains(r.output, "'u'")) << r.output;
  EXPECT_EQ(files(), std::vector<std::string>{"bad.csv"});
}

TEST_F(Track, ClosedLoopWithoutReferenceIsBadInput) {
  const std::string data = write("noref.csv", "t,u,y\n0,0,0\n0.05,0,0\n0.1,0,0\n");
  const Outcome r = track(data);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_TRUE(contains(r.output, "'r'")) << r.output;
  EXPECT_EQ(files(), std::vector<std::string>{"noref.csv"});
}

TEST_F(Track, WrongSampleRateIsBadInput) {
  std::ostringstream s;
  s << "t,r,u,y\n";
  for (int k = 0; k < 50; ++k) s << k * 0.1 << ",0,0,0\n";  // 10 Hz, the config says 20
  const Outcome r = track(write("slow.csv", s.str()));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_TRUE(contains(r.output, "sample_rate_hz")) << r.output;
  EXPECT_EQ(files(), std::vector<std::string>{"slow.csv"});
}

// A long record at the wrong rate is rejected on its first block of rows, not
// after the whole record has been estimated; a record that starts right and
// goes wrong later is still caught by the check at the end.
TEST_F(Track, WrongSampleRateIsCaughtOnTheFirstBlockOfALongRecord) {
  std::ostringstream s;
  s << "t,r,u,y\n";
  for (int k = 0; k < 100000; ++k) s << k * 0.1 << ",0,0,0\n";
  const Outcome r = track(write("slow.csv", s.str()));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_TRUE(contains(r.output, "sample time 0.100000 s (median step of the first 4096 rows)")) << r.output;
  EXPECT_EQ(files(), std::vector<std::string>{"slow.csv"});

  std::ostringstream late;
  late << "t,r,u,y\n";
  for (int k = 0; k < 5000; ++k) late << k * 0.05 << ",0,0,0\n";          // 20 Hz for 5000 rows
  for (int k = 0; k < 20000; ++k) late << 250.0 + k * 0.1 << ",0,0,0\n";  // then 10 Hz
  const Outcome r2 = track(write("late.csv", late.str()));
  EXPECT_EQ(r2.code, 2) << r2.output;
  EXPECT_TRUE(contains(r2.output, "sample time 0.100000 s (median step)")) << r2.output;
  std::vector<std::string> left = files();
  std::sort(left.begin(), left.end());
  EXPECT_EQ(left, (std::vector<std::string>{"late.csv", "slow.csv"}));
}

TEST_F(Track, UnwritableOutputIsAnErrorAndLeavesNothing) {
  const Outcome sim = run("simulate --config " + paper_config() + " --out " + path("d.csv") + " --duration 10");
  ASSERT_EQ(sim.code, 0) << sim.output;
  const Outcome r = track(path("d.csv"), "no/such/dir/est.csv");
  EXPECT_NE(r.code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "cannot write")) << r.output;
  EXPECT_EQ(files(), std::vector<std::string>{"d.csv"});
}

// The record is streamed (read a block of rows at a time while estimating): a
// long record whose length is no multiple of the blocks gives all its rows,
// and a malformed row deep in it is named by its line, with nothing written.
TEST_F(Track, LongStreamedRecordGivesEveryRowAndAMalformedRowDeepInItIsNamed) {
  const Outcome sim = run("simulate --config " + paper_config() + " --out " + path("d.csv") + " --duration 6000");
  ASSERT_EQ(sim.code, 0) << sim.output;
  const Outcome r = track(path("d.csv"));
  ASSERT_EQ(r.code, 0) << r.output;
  const Table d = read_table(path("d.csv"));
  const Table est = read_table(path("est.csv"));
  ASSERT_EQ(d.data.rows(), 120000);  // 29.3 blocks of 4096 rows
  ASSERT_EQ(est.data.rows(), 120000);
  EXPECT_TRUE(est.data.col(0) == d.data.col(d.column("t")));
  EXPECT_TRUE(contains(r.output, "final estimate at t = 5999.95 s")) << r.output;

  // Line 100001 (data row 99999) gets a u that is no number.
  std::ifstream in(path("d.csv"));
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::size_t at = 0;
  for (int line = 1; line < 100001; ++line) at = text.find('\n', at) + 1;
  const std::size_t u_field = text.find(',', text.find(',', at) + 1) + 1;  // t,r,u,y
  text.replace(u_field, 0, "0x");
  write("bad.csv", text);
  const Outcome bad = track(path("bad.csv"), "est2.csv");
  EXPECT_EQ(bad.code, 2) << bad.output;
  EXPECT_TRUE(contains(bad.output, "bad.csv: row 100001, column 'u': not a number (got '0x")) << bad.output;
  std::vector<std::string> names = files();
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"bad.csv", "d.csv", "est.csv"}));  // no est2.csv, no temporary
}

TEST_F(Track, EmptyRecordIsBadInputAndWritesNothing) {
  const Outcome empty = track(write("empty.csv", ""));
  EXPECT_EQ(empty.code, 2) << empty.output;
  EXPECT_TRUE(contains(empty.output, "empty.csv: empty file")) << empty.output;
  const Outcome header = track(write("header.csv", "t,r,u,y\n"));
  EXPECT_EQ(header.code, 2) << header.output;
  EXPECT_TRUE(contains(header.output, "header.csv: no data rows")) << header.output;
  std::vector<std::string> names = files();
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"empty.csv", "header.csv"}));
}

// est.csv's standard deviations: write_6g is printf's "%.6g", exactly, on
// random bit patterns, on typical magnitudes, and next to the rounding and
// power-of-ten boundaries where its scaled product has to give way.
TEST(TrackNumberFormat, SixDigitsIsPrintfs) {
  std::mt19937_64 rng(20261122);
  long checked = 0, differ = 0;
  const auto check = [&](double v) {
    char expected[64], got[64];
    std::snprintf(expected, sizeof expected, "%.6g", v);
    char* end = cli::write_6g(got, v);
    ASSERT_LE(static_cast<std::size_t>(end - got), cli::kNumberChars);
    *end = '\0';
    ++checked;
    if (std::strcmp(expected, got) != 0 && ++differ <= 5) ADD_FAILURE() << expected << " != " << got;
  };
  for (int i = 0; i < 400000; ++i) {
    const std::uint64_t bits = rng();
    double v;
    std::memcpy(&v, &bits, sizeof v);
    check(v);
  }
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (int i = 0; i < 400000; ++i) check(unit(rng) * std::pow(10.0, static_cast<int>(rng() % 30) - 20));
  for (int p = -320; p <= 310; ++p)
    for (const double m : {1.0, 9.999995, 9.9999949999, 9.99999500001, 1.000005, 1.0000049999999, 1.234565, 5.0}) {
      const double v = m * std::pow(10.0, p);
      for (const double x : {v, std::nextafter(v, 0.0), std::nextafter(v, 1e308), -v}) check(x);
    }
  for (int i = 0; i < 200000; ++i) check(i * 1e-6 + 0.5e-6);  // halfway cases, as near as doubles get
  for (const double v : {0.0, -0.0, std::nan(""), HUGE_VAL, -HUGE_VAL, 5e-324, 1.7976931348623157e308}) check(v);
  EXPECT_EQ(differ, 0) << "of " << checked;
}

TEST_F(Track, MissingRequiredOptionIsBadInput) {
  const Outcome r = run("track --config " + paper_config() + " --data x.csv");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_TRUE(contains(r.output, "--out")) << r.output;
}

}  // namespace
}  // namespace modalwatch
