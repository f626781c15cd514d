#include "modalwatch/io/messages.hpp"

#include <bit>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <modalwatch/sample_batch_t.hpp>
#include <modalwatch/sample_t.hpp>

namespace modalwatch {
namespace {

// Offsets in a sample_batch_t packet (after the 8-byte fingerprint).
constexpr int kBatchUtime = 8;
constexpr int kBatchPeriod = 16;
constexpr int kBatchFirstSeq = 24;
constexpr int kBatchCount = 32;
constexpr int kBatchArrays = 36;
static_assert(batch_wire_size(0) == kBatchArrays);

// Big-endian readers for a buffer whose size has already been checked. Own
// code rather than lcm_coretypes.h's __double_decode_array, which writes a
// double through an int64_t* (a strict-aliasing violation GCC warns about).
std::uint64_t get_u64(const void* buf, int offset) {
  const auto* p = static_cast<const unsigned char*>(buf) + offset;
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v = (v << 8) | p[i];
  return v;
}
std::int64_t get_i64(const void* buf, int offset) { return std::bit_cast<std::int64_t>(get_u64(buf, offset)); }
std::int32_t get_i32(const void* buf, int offset) {
  const auto* p = static_cast<const unsigned char*>(buf) + offset;
  std::uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v = (v << 8) | p[i];
  return std::bit_cast<std::int32_t>(v);
}
double get_f64(const void* buf, int offset) { return std::bit_cast<double>(get_u64(buf, offset)); }

DecodeResult fail(DecodeResult r, int& n_out) {
  n_out = 0;
  return r;
}

std::vector<std::uint8_t> encode_message(const auto& msg) {
  std::vector<std::uint8_t> buf(static_cast<std::size_t>(msg.getEncodedSize()));
  const int n = msg.encode(buf.data(), 0, static_cast<int>(buf.size()));
  if (n != static_cast<int>(buf.size())) throw std::runtime_error("LCM encode failed");
  return buf;
}

}  // namespace

const char* to_string(DecodeResult r) {
  switch (r) {
    case DecodeResult::ok:
      return "ok";
    case DecodeResult::truncated:
      return "truncated";
    case DecodeResult::trailing_bytes:
      return "trailing bytes";
    case DecodeResult::wrong_fingerprint:
      return "wrong fingerprint";
    case DecodeResult::bad_count:
      return "bad count";
    case DecodeResult::bad_period:
      return "bad sample period";
    case DecodeResult::bad_utime:
      return "bad utime";
    case DecodeResult::bad_seq:
      return "bad sequence number";
  }
  return "unknown";
}

std::int64_t sample_fingerprint() { return sample_t::getHash(); }
std::int64_t batch_fingerprint() { return sample_batch_t::getHash(); }

DecodeResult decode_sample(const void* data, int size, bool closed_loop, StampedSample* out, int capacity, int& n_out) {
  n_out = 0;
  if (data == nullptr || size < 8) return fail(DecodeResult::truncated, n_out);
  if (get_i64(data, 0) != sample_fingerprint()) return fail(DecodeResult::wrong_fingerprint, n_out);
  if (size < kSampleWireSize) return fail(DecodeResult::truncated, n_out);
  if (size > kSampleWireSize) return fail(DecodeResult::trailing_bytes, n_out);
  if (capacity < 1 || out == nullptr) return fail(DecodeResult::bad_count, n_out);
  StampedSample s;
  s.utime = get_i64(data, 8);
  s.seq = get_i64(data, 16);
  s.u = get_f64(data, 24);
  s.y = get_f64(data, 32);
  s.r = closed_loop ? get_f64(data, 40) : 0.0;
  if (s.utime < 0) return fail(DecodeResult::bad_utime, n_out);
  out[0] = s;
  n_out = 1;
  return DecodeResult::ok;
}

DecodeResult decode_batch(const void* data, int size, bool closed_loop, StampedSample* out, int capacity, int& n_out) {
  n_out = 0;
  if (data == nullptr || size < 8) return fail(DecodeResult::truncated, n_out);
  if (get_i64(data, 0) != batch_fingerprint()) return fail(DecodeResult::wrong_fingerprint, n_out);
  if (size < kBatchArrays) return fail(DecodeResult::truncated, n_out);
  const std::int32_t count = get_i32(data, kBatchCount);
  if (count < 1 || count > capacity || out == nullptr) return fail(DecodeResult::bad_count, n_out);
  const std::int64_t expected = kBatchArrays + std::int64_t{24} * count;
  if (size < expected) return fail(DecodeResult::truncated, n_out);
  if (size > expected) return fail(DecodeResult::trailing_bytes, n_out);

  const std::int64_t utime = get_i64(data, kBatchUtime);
  const double period = get_f64(data, kBatchPeriod);
  const std::int64_t first_seq = get_i64(data, kBatchFirstSeq);
  if (!std::isfinite(period) || !(period > 0.0)) return fail(DecodeResult::bad_period, n_out);
  if (utime < 0) return fail(DecodeResult::bad_utime, n_out);
  // The last sample's utime must fit an int64 (with margin for rounding).
  const double span_us = static_cast<double>(count - 1) * period * 1e6;
  if (!(span_us + static_cast<double>(utime) < 9.0e18)) return fail(DecodeResult::bad_period, n_out);
  if (first_seq > std::numeric_limits<std::int64_t>::max() - (count - 1)) return fail(DecodeResult::bad_seq, n_out);

  const int u0 = kBatchArrays;
  const int y0 = u0 + 8 * count;
  const int r0 = y0 + 8 * count;
  for (int i = 0; i < count; ++i) {
    StampedSample& s = out[i];
    s.utime = utime + std::llround(static_cast<double>(i) * period * 1e6);
    s.seq = first_seq + i;
    s.u = get_f64(data, u0 + 8 * i);
    s.y = get_f64(data, y0 + 8 * i);
    s.r = closed_loop ? get_f64(data, r0 + 8 * i) : 0.0;
  }
  n_out = count;
  return DecodeResult::ok;
}

DecodeResult decode_samples(const void* data, int size, bool closed_loop, StampedSample* out, int capacity,
                            int& n_out) {
  n_out = 0;
  if (data == nullptr || size < 8) return fail(DecodeResult::truncated, n_out);
  const std::int64_t hash = get_i64(data, 0);
  if (hash == sample_fingerprint()) return decode_sample(data, size, closed_loop, out, capacity, n_out);
  if (hash == batch_fingerprint()) return decode_batch(data, size, closed_loop, out, capacity, n_out);
  return fail(DecodeResult::wrong_fingerprint, n_out);
}

std::vector<std::uint8_t> encode_sample(const StampedSample& s) {
  sample_t msg;
  msg.utime = s.utime;
  msg.seq = s.seq;
  msg.u = s.u;
  msg.y = s.y;
  msg.r = s.r;
  return encode_message(msg);
}

std::vector<std::uint8_t> encode_batch(std::span<const StampedSample> samples, double sample_period) {
  if (samples.empty()) throw std::invalid_argument("encode_batch: empty slice");
  if (samples.size() > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max() / 24))
    throw std::invalid_argument("encode_batch: slice too large");
  sample_batch_t msg;
  msg.utime = samples.front().utime;
  msg.sample_period = sample_period;
  msg.first_seq = samples.front().seq;
  msg.u.reserve(samples.size());
  msg.y.reserve(samples.size());
  msg.r.reserve(samples.size());
  for (const StampedSample& s : samples) {
    msg.u.push_back(s.u);
    msg.y.push_back(s.y);
    msg.r.push_back(s.r);
  }
  msg.count = static_cast<std::int32_t>(msg.u.size());  // always from the arrays
  return encode_message(msg);
}

std::vector<std::uint8_t> encode_batch(const Record& rec, Eigen::Index begin, Eigen::Index count,
                                       std::int64_t utime_offset, std::int64_t first_seq_offset) {
  if (begin < 0 || count < 1 || begin + count > rec.size())
    throw std::invalid_argument("encode_batch: slice outside the record");
  if (count > std::numeric_limits<std::int32_t>::max() / 24)
    throw std::invalid_argument("encode_batch: slice too large");
  sample_batch_t msg;
  msg.utime = utime_offset + std::llround(rec.t(begin) * 1e6);
  msg.sample_period = rec.sample_time();
  msg.first_seq = first_seq_offset + begin;
  const auto n = static_cast<std::size_t>(count);
  msg.u.assign(rec.u.data() + begin, rec.u.data() + begin + count);
  msg.y.assign(rec.y.data() + begin, rec.y.data() + begin + count);
  if (rec.has_reference())
    msg.r.assign(rec.r.data() + begin, rec.r.data() + begin + count);
  else
    msg.r.assign(n, 0.0);
  msg.count = static_cast<std::int32_t>(msg.u.size());
  return encode_message(msg);
}

}  // namespace modalwatch
