// Input messages: lcm-gen types, the non-allocating decoder, the encoders, and
// one real in-process LCM round trip (memq://, one lcm::LCM instance, no mock).
#include "modalwatch/io/messages.hpp"

#include <gtest/gtest.h>

#include <lcm/lcm-cpp.hpp>

#include <modalwatch/estimates_t.hpp>
#include <modalwatch/fault_status_t.hpp>
#include <modalwatch/heartbeat_t.hpp>
#include <modalwatch/sample2_t.hpp>
#include <modalwatch/sample_batch2_t.hpp>
#include <modalwatch/sample_batch_t.hpp>
#include <modalwatch/sample_t.hpp>

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

using namespace modalwatch;

namespace {

using Bytes = std::vector<std::uint8_t>;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// Batch field offsets (after the 8-byte fingerprint), for patching packets.
constexpr int kUtime = 8, kPeriod = 16, kFirstSeq = 24, kCount = 32;

// Big-endian writers (LCM's wire order).
void put_u(Bytes& b, int off, std::uint64_t v, int n) {
  for (int i = n - 1; i >= 0; --i, v >>= 8) b[static_cast<std::size_t>(off + i)] = static_cast<std::uint8_t>(v);
}
void put_i32(Bytes& b, int off, std::int32_t v) { put_u(b, off, std::bit_cast<std::uint32_t>(v), 4); }
void put_i64(Bytes& b, int off, std::int64_t v) { put_u(b, off, std::bit_cast<std::uint64_t>(v), 8); }
void put_f64(Bytes& b, int off, double v) { put_u(b, off, std::bit_cast<std::uint64_t>(v), 8); }

std::vector<StampedSample> make_samples(int n, std::int64_t utime0, std::int64_t seq0, double period) {
  std::vector<StampedSample> s(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    auto& x = s[static_cast<std::size_t>(i)];
    x.utime = utime0 + std::llround(i * period * 1e6);
    x.seq = seq0 + i;
    x.u = std::sin(0.1 * i) + 0.25;
    x.y = -1.5 * i;
    x.r = 1e-3 * i * i;
  }
  return s;
}

struct Decoded {
  DecodeResult result = DecodeResult::ok;
  std::vector<StampedSample> samples;
};

enum class Kind { sample, batch, any };

Decoded decode(const Bytes& b, Kind kind, int capacity = 256, bool closed_loop = true, int size = -1, int inputs = 1) {
  Decoded d;
  d.samples.assign(static_cast<std::size_t>(capacity), StampedSample{});
  const int n = size < 0 ? static_cast<int>(b.size()) : size;
  int n_out = -1;
  switch (kind) {
    case Kind::sample:
      d.result = decode_sample(b.data(), n, closed_loop, d.samples.data(), capacity, n_out, inputs);
      break;
    case Kind::batch:
      d.result = decode_batch(b.data(), n, closed_loop, d.samples.data(), capacity, n_out, inputs);
      break;
    case Kind::any:
      d.result = decode_samples(b.data(), n, closed_loop, d.samples.data(), capacity, n_out, inputs);
      break;
  }
  EXPECT_GE(n_out, 0);
  if (d.result != DecodeResult::ok) {
    EXPECT_EQ(n_out, 0) << to_string(d.result);
  }
  d.samples.resize(static_cast<std::size_t>(n_out));
  return d;
}

void expect_same(const StampedSample& a, const StampedSample& b) {
  EXPECT_EQ(a.utime, b.utime);
  EXPECT_EQ(a.seq, b.seq);
  EXPECT_EQ(a.u, b.u);
  EXPECT_EQ(a.y, b.y);
  EXPECT_EQ(a.r, b.r);
  ASSERT_EQ(a.further_inputs, b.further_inputs);
  for (int j = 0; j < a.further_inputs; ++j)
    EXPECT_EQ(a.further_u[static_cast<std::size_t>(j)], b.further_u[static_cast<std::size_t>(j)]) << "input " << j + 2;
}

// make_samples with `inputs` inputs: input j of sample i is u + j (i + 1).
std::vector<StampedSample> make_samples(int n, int inputs, std::int64_t utime0, std::int64_t seq0, double period) {
  std::vector<StampedSample> s = make_samples(n, utime0, seq0, period);
  for (int i = 0; i < n; ++i) {
    auto& x = s[static_cast<std::size_t>(i)];
    x.further_inputs = inputs - 1;
    for (int j = 1; j < inputs; ++j) x.further_u[static_cast<std::size_t>(j - 1)] = x.u + j * (i + 1);
  }
  return s;
}

// Offsets in the new types: sample2_t's n_inputs, and sample_batch2_t's after its count.
constexpr int kSample2Inputs = 24, kBatch2Inputs = 36;

}  // namespace

TEST(Messages, GeneratedTypesHaveDistinctFingerprintsAndExpectedSizes) {
  EXPECT_NE(sample_fingerprint(), batch_fingerprint());
  EXPECT_NE(sample_fingerprint(), heartbeat_t::getHash());
  sample_t s{};
  EXPECT_EQ(s.getEncodedSize(), kSampleWireSize);
  sample_batch_t b{};
  b.count = 5;
  b.u.assign(5, 0.0);
  b.y.assign(5, 0.0);
  b.r.assign(5, 0.0);
  EXPECT_EQ(b.getEncodedSize(), batch_wire_size(5));
  // The output types exist and encode (array lengths set from the vectors).
  fault_status_t f{};
  f.version = fault_status_t::VERSION;
  f.state = "learning";
  f.modes.resize(2);
  f.modes[0].name = "m1";
  f.modes[1].name = "m2";
  f.modes[1].zeta.state = "raised";
  f.modes[1].zeta.deviation_sigma = -131.5;
  f.n_modes = static_cast<std::int32_t>(f.modes.size());
  Bytes buf(static_cast<std::size_t>(f.getEncodedSize()));
  EXPECT_EQ(f.encode(buf.data(), 0, static_cast<int>(buf.size())), static_cast<int>(buf.size()));
  fault_status_t g{};
  EXPECT_EQ(g.decode(buf.data(), 0, static_cast<int>(buf.size())), static_cast<int>(buf.size()));
  EXPECT_EQ(g.version, 2);
  EXPECT_EQ(g.state, "learning");
  EXPECT_EQ(g.modes[1].name, "m2");
  EXPECT_EQ(g.modes[1].zeta.state, "raised");
  EXPECT_EQ(g.modes[1].zeta.deviation_sigma, -131.5);
  EXPECT_EQ(fault_status_t::HEALTH_DECODE_ERRORS, 32);
  EXPECT_EQ(fault_status_t::HEALTH_OVERRUN, 64);
}

TEST(Messages, SampleRoundTrip) {
  StampedSample s{123456789, 42, 1.25, -3.5, kNaN};
  const Bytes b = encode_sample(s);
  ASSERT_EQ(static_cast<int>(b.size()), kSampleWireSize);
  for (Kind k : {Kind::sample, Kind::any}) {
    Decoded d = decode(b, k);
    ASSERT_EQ(d.result, DecodeResult::ok);
    ASSERT_EQ(d.samples.size(), 1u);
    EXPECT_EQ(d.samples[0].utime, s.utime);
    EXPECT_EQ(d.samples[0].seq, s.seq);
    EXPECT_EQ(d.samples[0].u, s.u);
    EXPECT_EQ(d.samples[0].y, s.y);
    EXPECT_TRUE(std::isnan(d.samples[0].r));  // non-finite values pass through
  }
  // Open loop: r is ignored (0), u and y kept.
  Decoded open = decode(b, Kind::sample, 1, false);
  ASSERT_EQ(open.result, DecodeResult::ok);
  EXPECT_EQ(open.samples[0].r, 0.0);
  EXPECT_EQ(open.samples[0].u, 1.25);
  // The generated decoder agrees.
  sample_t g{};
  ASSERT_EQ(g.decode(b.data(), 0, static_cast<int>(b.size())), kSampleWireSize);
  EXPECT_EQ(g.seq, 42);
  // A sample on the batch decoder is a wrong fingerprint.
  EXPECT_EQ(decode(b, Kind::batch).result, DecodeResult::wrong_fingerprint);
  // capacity 0
  EXPECT_EQ(decode(b, Kind::sample, 0).result, DecodeResult::bad_count);
  // negative utime
  Bytes neg = b;
  put_i64(neg, 8, -1);
  EXPECT_EQ(decode(neg, Kind::sample).result, DecodeResult::bad_utime);
}

TEST(Messages, BatchRoundTrip) {
  const double period = 1.0 / 4096.0;
  const auto in = make_samples(100, 1'700'000'000'000'000, 1000, period);
  const Bytes b = encode_batch(in, period);
  ASSERT_EQ(static_cast<int>(b.size()), batch_wire_size(100));
  for (Kind k : {Kind::batch, Kind::any}) {
    Decoded d = decode(b, k, 100);
    ASSERT_EQ(d.result, DecodeResult::ok);
    ASSERT_EQ(d.samples.size(), in.size());
    for (std::size_t i = 0; i < in.size(); ++i) expect_same(d.samples[i], in[i]);
  }
  EXPECT_EQ(decode(b, Kind::sample).result, DecodeResult::wrong_fingerprint);
  // Open loop zeroes r.
  Decoded open = decode(b, Kind::batch, 100, false);
  ASSERT_EQ(open.result, DecodeResult::ok);
  for (const auto& s : open.samples) EXPECT_EQ(s.r, 0.0);
  // The generated decoder reads the same packet identically.
  sample_batch_t g{};
  ASSERT_EQ(g.decode(b.data(), 0, static_cast<int>(b.size())), static_cast<int>(b.size()));
  ASSERT_EQ(g.count, 100);
  EXPECT_EQ(g.sample_period, period);
  EXPECT_EQ(g.first_seq, 1000);
  EXPECT_EQ(g.u[57], in[57].u);
  EXPECT_EQ(g.r[99], in[99].r);
}

TEST(Messages, NonFiniteValuesAreNotRejectedHere) {
  auto in = make_samples(3, 10, 1, 0.001);
  in[0].u = kNaN;
  in[1].y = kInf;
  in[2].r = -kInf;
  Decoded d = decode(encode_batch(in, 0.001), Kind::batch);
  ASSERT_EQ(d.result, DecodeResult::ok);
  ASSERT_EQ(d.samples.size(), 3u);
  EXPECT_TRUE(std::isnan(d.samples[0].u));
  EXPECT_EQ(d.samples[1].y, kInf);
  EXPECT_EQ(d.samples[2].r, -kInf);
}

TEST(Messages, RecordSliceEncodesAsBatch) {
  Record rec;
  const int n = 50;
  rec.t = Eigen::VectorXd::LinSpaced(n, 0.0, (n - 1) * 0.002);
  rec.u = Eigen::VectorXd::LinSpaced(n, 1.0, 2.0);
  rec.y = Eigen::VectorXd::LinSpaced(n, -1.0, 5.0);
  rec.r = Eigen::VectorXd::Constant(n, 0.5);
  const Bytes b = encode_batch(rec, 10, 20, 5'000'000, 7);
  Decoded d = decode(b, Kind::batch);
  ASSERT_EQ(d.result, DecodeResult::ok);
  ASSERT_EQ(d.samples.size(), 20u);
  for (int i = 0; i < 20; ++i) {
    const auto& s = d.samples[static_cast<std::size_t>(i)];
    EXPECT_EQ(s.utime, 5'000'000 + std::llround(rec.t(10 + i) * 1e6)) << i;
    EXPECT_EQ(s.seq, 7 + 10 + i);
    EXPECT_EQ(s.u, rec.u(10 + i));
    EXPECT_EQ(s.y, rec.y(10 + i));
    EXPECT_EQ(s.r, 0.5);
  }
  // Open-loop record: r encoded as 0.
  rec.r.resize(0);
  Decoded o = decode(encode_batch(rec, 0, n), Kind::batch);
  ASSERT_EQ(o.result, DecodeResult::ok);
  for (const auto& s : o.samples) EXPECT_EQ(s.r, 0.0);
  EXPECT_THROW(encode_batch(rec, 40, 20), std::invalid_argument);
  EXPECT_THROW(encode_batch(rec, 0, 0), std::invalid_argument);
}

TEST(Messages, EveryTruncatedPrefixIsRejected) {
  const Bytes sample = encode_sample({1, 2, 3.0, 4.0, 5.0});
  for (std::size_t len = 0; len < sample.size(); ++len)
    for (Kind k : {Kind::sample, Kind::any})
      EXPECT_EQ(decode(sample, k, 8, true, static_cast<int>(len)).result, DecodeResult::truncated)
          << "sample prefix " << len;
  const Bytes batch = encode_batch(make_samples(7, 100, 1, 0.01), 0.01);
  for (std::size_t len = 0; len < batch.size(); ++len)
    for (Kind k : {Kind::batch, Kind::any})
      EXPECT_EQ(decode(batch, k, 8, true, static_cast<int>(len)).result, DecodeResult::truncated)
          << "batch prefix " << len;
  // One byte too many.
  Bytes longer = sample;
  longer.push_back(0);
  EXPECT_EQ(decode(longer, Kind::any).result, DecodeResult::trailing_bytes);
  longer = batch;
  longer.push_back(0);
  EXPECT_EQ(decode(longer, Kind::any).result, DecodeResult::trailing_bytes);
  // Null data.
  int n_out = -1;
  StampedSample out[1];
  EXPECT_EQ(decode_samples(nullptr, 0, true, out, 1, n_out), DecodeResult::truncated);
  EXPECT_EQ(n_out, 0);
}

TEST(Messages, HeartbeatOnSampleChannelIsWrongFingerprint) {
  heartbeat_t hb{};
  hb.utime = 1;
  hb.state = "running";
  hb.uptime_us = 5;
  Bytes b(static_cast<std::size_t>(hb.getEncodedSize()));
  ASSERT_GT(hb.encode(b.data(), 0, static_cast<int>(b.size())), 0);
  for (Kind k : {Kind::sample, Kind::batch, Kind::any}) EXPECT_EQ(decode(b, k).result, DecodeResult::wrong_fingerprint);
}

TEST(Messages, CountMustBeWithinCapacityAndMatchThePacket) {
  const Bytes b = encode_batch(make_samples(10, 100, 1, 0.01), 0.01);
  EXPECT_EQ(decode(b, Kind::batch, 9).result, DecodeResult::bad_count);
  EXPECT_EQ(decode(b, Kind::batch, 10).result, DecodeResult::ok);
  EXPECT_EQ(decode(b, Kind::batch, 0).result, DecodeResult::bad_count);
  for (std::int32_t c : {0, -1, std::numeric_limits<std::int32_t>::min()}) {
    Bytes p = b;
    put_i32(p, kCount, c);
    EXPECT_EQ(decode(p, Kind::batch).result, DecodeResult::bad_count) << c;
  }
  // Count disagreeing with the arrays in the packet.
  Bytes fewer = b;
  put_i32(fewer, kCount, 9);
  EXPECT_EQ(decode(fewer, Kind::batch).result, DecodeResult::trailing_bytes);
  Bytes more = b;
  put_i32(more, kCount, 11);
  EXPECT_EQ(decode(more, Kind::batch).result, DecodeResult::truncated);
  // A huge count with a huge capacity must not read past the packet.
  Bytes huge = b;
  put_i32(huge, kCount, std::numeric_limits<std::int32_t>::max());
  std::vector<StampedSample> out(1);
  int n_out = -1;
  EXPECT_EQ(decode_batch(huge.data(), static_cast<int>(huge.size()), true, out.data(), std::numeric_limits<int>::max(),
                         n_out),
            DecodeResult::truncated);
  EXPECT_EQ(n_out, 0);
}

TEST(Messages, PeriodUtimeAndSeqAreValidated) {
  const Bytes b = encode_batch(make_samples(10, 100, 1, 0.01), 0.01);
  for (double p : {0.0, -0.01, kNaN, kInf, -kInf, 1e300}) {
    Bytes q = b;
    put_f64(q, kPeriod, p);
    EXPECT_EQ(decode(q, Kind::batch).result, DecodeResult::bad_period) << p;
  }
  Bytes t = b;
  put_i64(t, kUtime, -5);
  EXPECT_EQ(decode(t, Kind::batch).result, DecodeResult::bad_utime);
  Bytes s = b;
  put_i64(s, kFirstSeq, std::numeric_limits<std::int64_t>::max() - 8);
  EXPECT_EQ(decode(s, Kind::batch).result, DecodeResult::bad_seq);
  put_i64(s, kFirstSeq, std::numeric_limits<std::int64_t>::max() - 9);
  Decoded ok = decode(s, Kind::batch);
  ASSERT_EQ(ok.result, DecodeResult::ok);
  EXPECT_EQ(ok.samples.back().seq, std::numeric_limits<std::int64_t>::max());
}

// sample2_t and sample_batch2_t carry 1 .. 8 inputs; the generated decoders
// read the same packets, and a model of that many inputs gets every value.
TEST(Messages, Sample2AndBatch2RoundTripForEveryInputCount) {
  const double period = 1.0 / 4096.0;
  for (int inputs = 1; inputs <= kMaxInputs; ++inputs) {
    SCOPED_TRACE(inputs);
    const auto in = make_samples(37, inputs, 1'700'000'000'000'000, 5, period);
    const Bytes one = encode_sample2(in[3]);
    ASSERT_EQ(static_cast<int>(one.size()), sample2_wire_size(inputs));
    for (Kind k : {Kind::sample, Kind::any}) {
      const Decoded d = decode(one, k, 1, true, -1, inputs);
      ASSERT_EQ(d.result, DecodeResult::ok) << to_string(d.result);
      ASSERT_EQ(d.samples.size(), 1u);
      expect_same(d.samples[0], in[3]);
    }
    sample2_t g{};
    ASSERT_EQ(g.decode(one.data(), 0, static_cast<int>(one.size())), static_cast<int>(one.size()));
    ASSERT_EQ(g.n_inputs, inputs);
    EXPECT_EQ(g.u[static_cast<std::size_t>(inputs - 1)], in[3].input(inputs - 1));
    EXPECT_EQ(g.y, in[3].y);

    const Bytes many = encode_batch2(in, period);
    ASSERT_EQ(static_cast<std::int64_t>(many.size()), batch2_wire_size(37, inputs));
    for (Kind k : {Kind::batch, Kind::any}) {
      const Decoded d = decode(many, k, 37, true, -1, inputs);
      ASSERT_EQ(d.result, DecodeResult::ok) << to_string(d.result);
      ASSERT_EQ(d.samples.size(), in.size());
      for (std::size_t i = 0; i < in.size(); ++i) expect_same(d.samples[i], in[i]);
    }
    sample_batch2_t gb{};
    ASSERT_EQ(gb.decode(many.data(), 0, static_cast<int>(many.size())), static_cast<int>(many.size()));
    ASSERT_EQ(gb.count, 37);
    ASSERT_EQ(gb.n_inputs, inputs);
    EXPECT_EQ(gb.u[static_cast<std::size_t>(inputs - 1)][20], in[20].input(inputs - 1));
    EXPECT_EQ(gb.r[36], in[36].r);
    // A sample on the batch decoder and the other way round: wrong fingerprints.
    EXPECT_EQ(decode(one, Kind::batch, 1, true, -1, inputs).result, DecodeResult::wrong_fingerprint);
    EXPECT_EQ(decode(many, Kind::sample, 37, true, -1, inputs).result, DecodeResult::wrong_fingerprint);
  }
}

// A model of one input takes either version; one of several takes only the new
// types with its own number of inputs: a single-input packet or another count
// cannot say what the other inputs were, and is a decode error (bad_inputs).
TEST(Messages, AModelOfSeveralInputsTakesOnlyPacketsOfItsOwnInputCount) {
  const auto one_input = make_samples(4, 1, 100, 1, 0.01);
  const auto two_inputs = make_samples(4, 2, 100, 1, 0.01);
  // encode_sample and encode_batch pick the version by the inputs.
  EXPECT_EQ(static_cast<int>(encode_sample(one_input[0]).size()), kSampleWireSize);
  EXPECT_EQ(encode_sample(two_inputs[0]), encode_sample2(two_inputs[0]));
  EXPECT_EQ(static_cast<int>(encode_batch(one_input, 0.01).size()), batch_wire_size(4));
  EXPECT_EQ(encode_batch(two_inputs, 0.01), encode_batch2(two_inputs, 0.01));
  for (const Bytes& b : {encode_sample(one_input[0]), encode_sample2(one_input[0])})
    EXPECT_EQ(decode(b, Kind::sample, 1, true, -1, 1).result, DecodeResult::ok);
  for (const Bytes& b : {encode_batch(one_input, 0.01), encode_batch2(one_input, 0.01)})
    EXPECT_EQ(decode(b, Kind::batch, 4, true, -1, 1).result, DecodeResult::ok);
  for (const Bytes& b : {encode_sample(one_input[0]), encode_sample2(one_input[0])})
    EXPECT_EQ(decode(b, Kind::any, 1, true, -1, 2).result, DecodeResult::bad_inputs);
  for (const Bytes& b : {encode_batch(one_input, 0.01), encode_batch2(one_input, 0.01)})
    EXPECT_EQ(decode(b, Kind::any, 4, true, -1, 2).result, DecodeResult::bad_inputs);
  EXPECT_EQ(decode(encode_sample(two_inputs[0]), Kind::sample, 1, true, -1, 3).result, DecodeResult::bad_inputs);
  EXPECT_EQ(decode(encode_batch(two_inputs, 0.01), Kind::batch, 4, true, -1, 1).result, DecodeResult::bad_inputs);
  // The single-input decode leaves no further inputs behind in a reused record.
  std::vector<StampedSample> out(4);
  int n_out = 0;
  const Bytes two = encode_batch(two_inputs, 0.01), single = encode_batch(one_input, 0.01);
  ASSERT_EQ(decode_batch(two.data(), static_cast<int>(two.size()), true, out.data(), 4, n_out, 2), DecodeResult::ok);
  EXPECT_EQ(out[2].further_inputs, 1);
  ASSERT_EQ(decode_batch(single.data(), static_cast<int>(single.size()), true, out.data(), 4, n_out, 1),
            DecodeResult::ok);
  EXPECT_EQ(out[2].further_inputs, 0);
}

// Malformed new-type packets: every truncated prefix, a byte too many, an
// input count outside 1 .. 8 or disagreeing with the arrays, a batch count
// outside the capacity or disagreeing with the arrays, a bad period.
TEST(Messages, MalformedSample2AndBatch2AreRejected) {
  const auto in = make_samples(6, 3, 100, 1, 0.01);
  const Bytes sample = encode_sample2(in[0]), batch = encode_batch2(in, 0.01);
  for (std::size_t len = 0; len < sample.size(); ++len)
    EXPECT_EQ(decode(sample, Kind::any, 8, true, static_cast<int>(len), 3).result, DecodeResult::truncated)
        << "sample2 prefix " << len;
  for (std::size_t len = 0; len < batch.size(); ++len) {
    const DecodeResult r = decode(batch, Kind::any, 8, true, static_cast<int>(len), 3).result;
    EXPECT_TRUE(r == DecodeResult::truncated) << "batch2 prefix " << len << ": " << to_string(r);
  }
  for (const Bytes& b : {sample, batch}) {
    Bytes longer = b;
    longer.push_back(0);
    EXPECT_EQ(decode(longer, Kind::any, 8, true, -1, 3).result, DecodeResult::trailing_bytes);
  }
  for (int n : {0, -1, 9, 127, -128}) {
    Bytes s = sample, b = batch;
    s[kSample2Inputs] = static_cast<std::uint8_t>(n);
    b[kBatch2Inputs] = static_cast<std::uint8_t>(n);
    EXPECT_EQ(decode(s, Kind::sample, 8, true, -1, 3).result, DecodeResult::bad_inputs) << n;
    EXPECT_EQ(decode(b, Kind::batch, 8, true, -1, 3).result, DecodeResult::bad_inputs) << n;
  }
  // n_inputs disagreeing with the arrays: the size says so first.
  Bytes s2 = sample, b2 = batch;
  s2[kSample2Inputs] = 2;
  b2[kBatch2Inputs] = 4;
  EXPECT_EQ(decode(s2, Kind::sample, 8, true, -1, 2).result, DecodeResult::trailing_bytes);
  EXPECT_EQ(decode(b2, Kind::batch, 8, true, -1, 4).result, DecodeResult::truncated);
  EXPECT_EQ(decode(batch, Kind::batch, 5, true, -1, 3).result, DecodeResult::bad_count);
  for (std::int32_t c : {0, -1, std::numeric_limits<std::int32_t>::max()}) {
    Bytes p = batch;
    put_i32(p, kCount, c);
    const DecodeResult r = decode(p, Kind::batch, 8, true, -1, 3).result;
    EXPECT_TRUE(r == DecodeResult::bad_count || r == DecodeResult::truncated) << c << ": " << to_string(r);
  }
  Bytes fewer = batch;
  put_i32(fewer, kCount, 5);
  EXPECT_EQ(decode(fewer, Kind::batch, 8, true, -1, 3).result, DecodeResult::trailing_bytes);
  Bytes period = batch;
  put_f64(period, kPeriod, kNaN);
  EXPECT_EQ(decode(period, Kind::batch, 8, true, -1, 3).result, DecodeResult::bad_period);
  Bytes utime = sample;
  put_i64(utime, 8, -1);
  EXPECT_EQ(decode(utime, Kind::sample, 8, true, -1, 3).result, DecodeResult::bad_utime);
}

// A two-input record's slice encodes as a sample_batch2_t with each input.
TEST(Messages, RecordOfTwoInputsEncodesAsBatch2) {
  Record rec;
  const int n = 30;
  rec.t = Eigen::VectorXd::LinSpaced(n, 0.0, (n - 1) * 0.01);
  rec.u = Eigen::VectorXd::LinSpaced(n, 1.0, 2.0);
  rec.further_u = {Eigen::VectorXd::LinSpaced(n, -4.0, 4.0)};
  rec.y = Eigen::VectorXd::LinSpaced(n, -1.0, 5.0);
  const Bytes b = encode_batch(rec, 5, 20, 1'000'000, 0);
  EXPECT_EQ(static_cast<std::int64_t>(b.size()), batch2_wire_size(20, 2));
  const Decoded d = decode(b, Kind::batch, 20, false, -1, 2);
  ASSERT_EQ(d.result, DecodeResult::ok);
  for (int i = 0; i < 20; ++i) {
    const auto& s = d.samples[static_cast<std::size_t>(i)];
    EXPECT_EQ(s.seq, 5 + i);
    EXPECT_EQ(s.u, rec.u(5 + i));
    ASSERT_EQ(s.further_inputs, 1);
    EXPECT_EQ(s.further_u[0], rec.further_u[0](5 + i));
    EXPECT_EQ(s.y, rec.y(5 + i));
  }
}

// Random bytes under the new types' fingerprints, decoded for every model
// input count: no crash, and what is accepted agrees with lcm-gen's decoders.
TEST(Messages, RandomBytesOfTheNewTypesNeverCrash) {
  std::mt19937_64 rng(20261128);
  const int capacity = 64;
  std::vector<StampedSample> out(capacity);
  int accepted = 0;
  for (int iter = 0; iter < 10'000; ++iter) {
    const bool batch = iter % 2 == 1;
    std::size_t len = rng() % 700;
    Bytes b(len);
    for (auto& x : b) x = static_cast<std::uint8_t>(rng());
    const int inputs = 1 + static_cast<int>(rng() % kMaxInputs);
    if (len >= 8) put_i64(b, 0, batch ? batch2_fingerprint() : sample2_fingerprint());
    if (!batch && len > kSample2Inputs) {
      b[kSample2Inputs] = static_cast<std::uint8_t>(rng() % 3 == 0 ? rng() : static_cast<std::uint64_t>(inputs));
      if (rng() % 2) b.resize(static_cast<std::size_t>(sample2_wire_size(inputs)));
    }
    if (batch && len > kBatch2Inputs) {
      const std::int32_t c = static_cast<std::int32_t>(rng() % 20);
      put_i32(b, kCount, c);
      put_f64(b, kPeriod, 1e-3 * static_cast<double>(1 + rng() % 10));
      put_i64(b, kUtime, static_cast<std::int64_t>(rng() >> 4));
      put_i64(b, kFirstSeq, static_cast<std::int64_t>(rng() >> 4));
      b[kBatch2Inputs] = static_cast<std::uint8_t>(rng() % 3 == 0 ? rng() : static_cast<std::uint64_t>(inputs));
      if (rng() % 2) b.resize(static_cast<std::size_t>(batch2_wire_size(c, inputs)));
    }
    int n_out = -1;
    const DecodeResult r =
        decode_samples(b.data(), static_cast<int>(b.size()), true, out.data(), capacity, n_out, inputs);
    if (r != DecodeResult::ok) {
      ASSERT_EQ(n_out, 0);
      continue;
    }
    ++accepted;
    ASSERT_GE(n_out, 1);
    if (!batch) {
      sample2_t g{};
      ASSERT_EQ(g.decode(b.data(), 0, static_cast<int>(b.size())), static_cast<int>(b.size()));
      ASSERT_EQ(g.n_inputs, inputs);
      ASSERT_EQ(g.seq, out[0].seq);
      for (int j = 0; j < inputs; ++j) {
        const double gu = g.u[static_cast<std::size_t>(j)], ou = out[0].input(j);
        ASSERT_TRUE(gu == ou || (std::isnan(gu) && std::isnan(ou)));
      }
    } else {
      sample_batch2_t g{};
      ASSERT_EQ(g.decode(b.data(), 0, static_cast<int>(b.size())), static_cast<int>(b.size()));
      ASSERT_EQ(g.count, n_out);
      ASSERT_EQ(g.n_inputs, inputs);
      for (int i = 0; i < n_out; ++i)
        for (int j = 0; j < inputs; ++j) {
          const double gu = g.u[static_cast<std::size_t>(j)][static_cast<std::size_t>(i)];
          const double ou = out[static_cast<std::size_t>(i)].input(j);
          ASSERT_TRUE(gu == ou || (std::isnan(gu) && std::isnan(ou)));
        }
    }
  }
  EXPECT_GT(accepted, 1000);
}

// 10 000 seeded random buffers: no crash, and each is either rejected (n_out 0)
// or decoded into records that agree with the generated decoder.
TEST(Messages, RandomBytesNeverCrash) {
  std::mt19937_64 rng(20261122);
  const int capacity = 64;
  std::vector<StampedSample> out(capacity);
  int accepted = 0;
  int fingerprinted = 0;
  for (int iter = 0; iter < 10'000; ++iter) {
    const int mode = iter % 4;  // 0: pure noise, 1: sample hash, 2/3: batch hash
    std::size_t len = rng() % 600;
    Bytes b(len);
    for (auto& x : b) x = static_cast<std::uint8_t>(rng());
    if (mode != 0 && len >= 8) {
      put_i64(b, 0, mode == 1 ? sample_fingerprint() : batch_fingerprint());
      ++fingerprinted;
      if (mode == 3 && len >= 36) {
        // A plausible header so that the array path is exercised too.
        const std::int32_t c = static_cast<std::int32_t>(rng() % 80);
        put_i32(b, kCount, c);
        put_f64(b, kPeriod, 1e-3 * static_cast<double>(1 + rng() % 10));
        put_i64(b, kUtime, static_cast<std::int64_t>(rng() >> 4));
        put_i64(b, kFirstSeq, static_cast<std::int64_t>(rng() >> 4));
        if (rng() % 2) b.resize(static_cast<std::size_t>(batch_wire_size(c)));
      }
    }
    int n_out = -1;
    const DecodeResult r = decode_samples(b.data(), static_cast<int>(b.size()), true, out.data(), capacity, n_out);
    if (r != DecodeResult::ok) {
      ASSERT_EQ(n_out, 0);
      continue;
    }
    ++accepted;
    ASSERT_GE(n_out, 1);
    ASSERT_LE(n_out, capacity);
    for (int i = 0; i < n_out; ++i) {
      ASSERT_GE(out[static_cast<std::size_t>(i)].utime, 0);
      if (i > 0) {
        ASSERT_EQ(out[static_cast<std::size_t>(i)].seq, out[static_cast<std::size_t>(i - 1)].seq + 1);
        ASSERT_GE(out[static_cast<std::size_t>(i)].utime, out[static_cast<std::size_t>(i - 1)].utime);
      }
    }
    // Cross-check against lcm-gen's decoder (safe now: size and count validated).
    if (n_out == 1 && static_cast<int>(b.size()) == kSampleWireSize) {
      sample_t g{};
      ASSERT_EQ(g.decode(b.data(), 0, static_cast<int>(b.size())), kSampleWireSize);
      ASSERT_EQ(g.seq, out[0].seq);
      ASSERT_TRUE(g.u == out[0].u || (std::isnan(g.u) && std::isnan(out[0].u)))
          << g.u << " " << out[0].u << " " << std::bit_cast<std::uint64_t>(g.u) << " "
          << std::bit_cast<std::uint64_t>(out[0].u);
    } else {
      sample_batch_t g{};
      ASSERT_EQ(g.decode(b.data(), 0, static_cast<int>(b.size())), static_cast<int>(b.size()));
      ASSERT_EQ(g.count, n_out);
      ASSERT_EQ(g.first_seq, out[0].seq);
      ASSERT_EQ(g.utime, out[0].utime);
      for (int i = 0; i < n_out; ++i) {
        const double gy = g.y[static_cast<std::size_t>(i)];
        const double oy = out[static_cast<std::size_t>(i)].y;
        ASSERT_TRUE(gy == oy || (std::isnan(gy) && std::isnan(oy)));
      }
    }
  }
  EXPECT_GT(fingerprinted, 5000);
  EXPECT_GT(accepted, 100);  // the array path really ran
}

// Real LCM, in process: one lcm::LCM instance on memq:// (memq is per instance)
// publishes three batches and a heartbeat on the sample channel; the raw
// subscriber decodes them exactly as the daemon's LCM thread will.
namespace {
struct Collector {
  std::vector<StampedSample> samples;
  std::vector<StampedSample> buffer = std::vector<StampedSample>(256);
  int packets = 0;
  int ok = 0;
  int wrong_fingerprint = 0;
  // Subscribed through the C API, as the daemon does: liblcm 1.3.1's C++
  // subscribe() wrapper hands its callback a user_data that UBSan rejects.
  static void handle(const lcm_recv_buf_t* rbuf, const char* channel, void* self) {
    static_cast<Collector*>(self)->handle(rbuf, channel);
  }
  void handle(const lcm_recv_buf_t* rbuf, const std::string& channel) {
    EXPECT_EQ(channel, "MODALWATCH_SAMPLES");
    ++packets;
    int n_out = 0;
    const DecodeResult r = decode_samples(rbuf->data, static_cast<int>(rbuf->data_size), true, buffer.data(),
                                          static_cast<int>(buffer.size()), n_out);
    if (r == DecodeResult::ok) {
      ++ok;
      samples.insert(samples.end(), buffer.begin(), buffer.begin() + n_out);
    } else if (r == DecodeResult::wrong_fingerprint) {
      ++wrong_fingerprint;
    }
  }
};
}  // namespace

TEST(MessagesLcm, MemqPublishSubscribeThreeBatches) {
  lcm::LCM lc("memq://");
  ASSERT_TRUE(lc.good());
  Collector c;
  ASSERT_NE(lcm_subscribe(lc.getUnderlyingLCM(), "MODALWATCH_SAMPLES", &Collector::handle, &c), nullptr);

  const double period = 1.0 / 1024.0;
  const auto all = make_samples(3 * 32, 1'000'000, 1, period);
  for (int k = 0; k < 3; ++k) {
    const std::span<const StampedSample> slice(all.data() + 32 * k, 32);
    const Bytes b = encode_batch(slice, period);
    ASSERT_EQ(lc.publish("MODALWATCH_SAMPLES", b.data(), static_cast<unsigned>(b.size())), 0);
  }
  heartbeat_t hb{};
  hb.state = "running";
  ASSERT_EQ(lc.publish("MODALWATCH_SAMPLES", &hb), 0);

  for (int i = 0; i < 100 && c.packets < 4; ++i) ASSERT_GE(lc.handleTimeout(100), 0);
  ASSERT_EQ(c.packets, 4);
  EXPECT_EQ(c.ok, 3);
  EXPECT_EQ(c.wrong_fingerprint, 1);
  ASSERT_EQ(c.samples.size(), all.size());
  for (std::size_t i = 0; i < all.size(); ++i) expect_same(c.samples[i], all[i]);
}
