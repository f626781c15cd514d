// LCM logs as records: logs written by LCM itself read back equal to the CSV
// record they came from, through read_lcm_log and through RecordReader in
// blocks; corrupt logs are InputErrors naming the byte offset.
#include <cstdint>
#include <fstream>
#include <iterator>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "lcm_log_support.hpp"
#include "support.hpp"

#include "modalwatch/io/lcm_log.hpp"
#include "modalwatch/io/records.hpp"

namespace modalwatch {
namespace {

using test_support::error_of;
using test_support::LcmLog;

// u, y and r are the CSV's doubles bit for bit; t goes through an integer
// microsecond utime, so it matches to 1 us (0.15000000000000002 s in the CSV is
// 150000 us, read back as 0.15).
void expect_same(const Record& a, const Record& b) {
  ASSERT_EQ(a.size(), b.size());
  ASSERT_TRUE(b.has_reference());
  EXPECT_EQ(a.u, b.u);
  EXPECT_EQ(a.y, b.y);
  EXPECT_EQ(a.r, b.r);
  EXPECT_LT((a.t - b.t).cwiseAbs().maxCoeff(), 0.5e-6);
}

TEST_F(LcmLog, LogsWrittenByLcmReadBackAsTheCsvRecord) {
  const Record csv = csv_record(path("run.csv"));
  for (int batch : {1, 64}) {
    const std::string log = path("run" + std::to_string(batch) + ".lcm");
    const int pairs = write_log(log, csv, "MODALWATCH_SAMPLES", batch);
    ASSERT_TRUE(is_lcm_log(log));
    EXPECT_FALSE(is_lcm_log(path("run.csv")));
    LcmLogOptions o;
    o.channel = "MODALWATCH_SAMPLES";
    o.closed_loop = true;
    const LcmLogRecord r = read_lcm_log(log, o);
    expect_same(csv, r.record);
    EXPECT_EQ(r.sample_events, static_cast<std::uint64_t>((2000 + batch - 1) / batch));
    EXPECT_EQ(r.skipped_channel, 2u * pairs) << "heartbeat and OTHER_SAMPLES events";
    EXPECT_EQ(r.skipped_type, 0u);
    EXPECT_EQ(r.skipped_order, 0u);
    // Without a channel the copies on OTHER_SAMPLES are duplicates by sequence number.
    o.channel.clear();
    const LcmLogRecord all = read_lcm_log(log, o);
    EXPECT_EQ(all.skipped_type, static_cast<std::uint64_t>(pairs));
    EXPECT_GT(all.skipped_order, 0u);
    EXPECT_EQ(all.channels.size(), 2u);
    o.closed_loop = false;
    o.channel = "MODALWATCH_SAMPLES";
    EXPECT_FALSE(read_lcm_log(log, o).record.has_reference());
  }
}

// RecordReader, track's block source, hands out a log's samples as it hands
// out the CSV's: the same blocks, and read_record's samples.
TEST_F(LcmLog, RecordReaderDeliversALogInBlocksAsItDeliversTheCsv) {
  const Record csv = csv_record(path("run.csv"));
  write_log(path("run.lcm"), csv, "MODALWATCH_SAMPLES", 64);
  RecordReadOptions options;
  options.allow_gaps = true;
  options.sample_time = 0.05;
  const RecordSource log_source(path("run.lcm"), {}, "MODALWATCH_SAMPLES", true);
  const Record whole = read_record(log_source, options);
  expect_same(csv, whole);
  RecordReader from_log(log_source, options);
  RecordReader from_csv(path("run.csv"), options);
  EXPECT_TRUE(from_log.has_reference());
  EXPECT_TRUE(from_csv.has_reference());
  Record a, b;
  Eigen::Index at = 0;
  for (;;) {
    const std::size_t n = from_log.read(a, 300);
    ASSERT_EQ(from_csv.read(b, 300), n);
    if (n == 0) break;
    ASSERT_EQ(a.size(), static_cast<Eigen::Index>(n));
    EXPECT_EQ(a.t, whole.t.segment(at, a.size()));
    EXPECT_EQ(a.u, whole.u.segment(at, a.size()));
    EXPECT_EQ(a.y, whole.y.segment(at, a.size()));
    EXPECT_EQ(a.r, whole.r.segment(at, a.size()));
    expect_same(b, a);
    at += a.size();
    EXPECT_EQ(from_log.fraction_read(), static_cast<double>(at) / 2000.0);
  }
  EXPECT_EQ(at, 2000);
  EXPECT_EQ(from_csv.fraction_read(), 1.0);
}

TEST_F(LcmLog, CorruptLogsAreInputErrorsNamingTheByteOffset) {
  const Record csv = csv_record(path("run.csv"));
  const std::string log = path("run.lcm");
  write_log(log, csv.segment(0, 10), "S", 1);
  std::ifstream in(log, std::ios::binary);
  const std::vector<std::uint8_t> good{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  // Events: 28-byte header, channel "S", 48-byte sample_t; the first two events
  // (a sample and the k % 500 == 0 heartbeat) start at 0 and 77.
  ASSERT_EQ(parse_lcm_log(good, "x").record.size(), 10);
  constexpr std::size_t kSecond = 28 + 1 + 48;
  // Event boundaries: a cut there is a shorter, valid log.
  std::vector<std::size_t> ends;
  for (std::size_t pos = 0; pos < good.size();) {
    const auto be32 = [&](std::size_t at) {
      return (std::size_t{good[at]} << 24) | (std::size_t{good[at + 1]} << 16) | (std::size_t{good[at + 2]} << 8) |
             good[at + 3];
    };
    pos += 28 + be32(pos + 20) + be32(pos + 24);
    ends.push_back(pos);
  }
  ASSERT_EQ(ends.back(), good.size());
  for (std::size_t n = 1; n < good.size(); ++n) {
    if (std::find(ends.begin(), ends.end(), n) != ends.end()) {
      EXPECT_NO_THROW(parse_lcm_log(std::span(good).first(n), "cut.lcm"));
      continue;
    }
    const std::string msg = error_of([&] { parse_lcm_log(std::span(good).first(n), "cut.lcm"); });
    EXPECT_NE(msg.find("cut.lcm: LCM log: byte offset"), std::string::npos) << n << ": " << msg;
    EXPECT_NE(msg.find("truncated"), std::string::npos) << n << ": " << msg;
  }
  auto b = good;
  b[kSecond] = 0x00;
  EXPECT_NE(error_of([&] { parse_lcm_log(b, "sync.lcm"); }).find("byte offset 77: bad sync word 0x00A1DA01"),
            std::string::npos);
  b = good;
  b[kSecond + 24] = 0x80;  // data length of the second event negative
  EXPECT_NE(error_of([&] { parse_lcm_log(b, "neg.lcm"); }).find("byte offset 101: negative data length"),
            std::string::npos);
  b = good;
  b[kSecond + 20] = 0x7F;  // channel length absurd
  EXPECT_NE(error_of([&] { parse_lcm_log(b, "chan.lcm"); }).find("byte offset 97: channel length"), std::string::npos);
  b = good;
  b[kSecond + 25] = 0x7F;  // data length beyond the file
  EXPECT_NE(error_of([&] { parse_lcm_log(b, "long.lcm"); }).find("byte offset 77: truncated event"), std::string::npos);
  // A corrupt sample packet inside a well-formed event is skipped and counted.
  b = good;
  b[28 + 1 + 3] ^= 0xFF;                                   // fingerprint of the first sample
  EXPECT_EQ(parse_lcm_log(b, "fp.lcm").skipped_type, 2u);  // it and the heartbeat
  // Random bytes behind a sync word: an InputError or a record, never a crash.
  std::mt19937 rng(7);
  for (int trial = 0; trial < 2000; ++trial) {
    std::vector<std::uint8_t> r = good;
    const int flips = 1 + static_cast<int>(rng() % 8);
    for (int f = 0; f < flips; ++f) r[rng() % r.size()] = static_cast<std::uint8_t>(rng());
    r.resize(rng() % (r.size() + 1));
    try {
      parse_lcm_log(r, "fuzz");
    } catch (const InputError&) {
    }
  }
}

}  // namespace
}  // namespace modalwatch
