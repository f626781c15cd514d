#include "modalwatch/io/messages.hpp"

#include <bit>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include <modalwatch/sample2_t.hpp>
#include <modalwatch/sample_batch2_t.hpp>
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
// Offsets in a sample2_t packet, and in a sample_batch2_t packet after its
// count: the number of inputs (one byte), then the arrays.
constexpr int kSample2Inputs = 24;
constexpr int kSample2Arrays = 25;
constexpr int kBatch2Inputs = 36;
constexpr int kBatch2Arrays = 37;
static_assert(sample2_wire_size(0) == kSample2Arrays + 16);
static_assert(batch2_wire_size(0, 0) == kBatch2Arrays);

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
int get_i8(const void* buf, int offset) {
  return static_cast<std::int8_t>(static_cast<const unsigned char*>(buf)[offset]);
}

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
    case DecodeResult::bad_inputs:
      return "bad number of inputs";
  }
  return "unknown";
}

std::int64_t sample_fingerprint() { return sample_t::getHash(); }
std::int64_t batch_fingerprint() { return sample_batch_t::getHash(); }
std::int64_t sample2_fingerprint() { return sample2_t::getHash(); }
std::int64_t batch2_fingerprint() { return sample_batch2_t::getHash(); }

namespace {

// A sample_t (fingerprint checked).
DecodeResult decode_sample1(const void* data, int size, bool closed_loop, StampedSample* out, int capacity, int& n_out,
                            int inputs) {
  if (size < kSampleWireSize) return fail(DecodeResult::truncated, n_out);
  if (size > kSampleWireSize) return fail(DecodeResult::trailing_bytes, n_out);
  if (capacity < 1 || out == nullptr) return fail(DecodeResult::bad_count, n_out);
  if (inputs != 1) return fail(DecodeResult::bad_inputs, n_out);
  StampedSample& s = out[0];
  s.utime = get_i64(data, 8);
  s.seq = get_i64(data, 16);
  s.u = get_f64(data, 24);
  s.y = get_f64(data, 32);
  s.r = closed_loop ? get_f64(data, 40) : 0.0;
  s.further_inputs = 0;
  if (s.utime < 0) return fail(DecodeResult::bad_utime, n_out);
  n_out = 1;
  return DecodeResult::ok;
}

// A sample2_t (fingerprint checked).
DecodeResult decode_sample2(const void* data, int size, bool closed_loop, StampedSample* out, int capacity, int& n_out,
                            int inputs) {
  if (size < kSample2Arrays) return fail(DecodeResult::truncated, n_out);
  const int n = get_i8(data, kSample2Inputs);
  if (n < 1 || n > kMaxInputs) return fail(DecodeResult::bad_inputs, n_out);
  if (size < sample2_wire_size(n)) return fail(DecodeResult::truncated, n_out);
  if (size > sample2_wire_size(n)) return fail(DecodeResult::trailing_bytes, n_out);
  if (capacity < 1 || out == nullptr) return fail(DecodeResult::bad_count, n_out);
  if (n != inputs) return fail(DecodeResult::bad_inputs, n_out);
  StampedSample& s = out[0];
  s.utime = get_i64(data, 8);
  s.seq = get_i64(data, 16);
  s.u = get_f64(data, kSample2Arrays);
  s.further_inputs = n - 1;
  for (int j = 1; j < n; ++j) s.further_u[static_cast<std::size_t>(j - 1)] = get_f64(data, kSample2Arrays + 8 * j);
  s.y = get_f64(data, kSample2Arrays + 8 * n);
  s.r = closed_loop ? get_f64(data, kSample2Arrays + 8 * n + 8) : 0.0;
  if (s.utime < 0) return fail(DecodeResult::bad_utime, n_out);
  n_out = 1;
  return DecodeResult::ok;
}

// A batch's header after its size checks: the period, the first utime and seq.
DecodeResult check_batch_header(const void* data, std::int32_t count, int& n_out) {
  const std::int64_t utime = get_i64(data, kBatchUtime);
  const double period = get_f64(data, kBatchPeriod);
  const std::int64_t first_seq = get_i64(data, kBatchFirstSeq);
  if (!std::isfinite(period) || !(period > 0.0)) return fail(DecodeResult::bad_period, n_out);
  if (utime < 0) return fail(DecodeResult::bad_utime, n_out);
  // The last sample's utime must fit an int64 (with margin for rounding).
  const double span_us = static_cast<double>(count - 1) * period * 1e6;
  if (!(span_us + static_cast<double>(utime) < 9.0e18)) return fail(DecodeResult::bad_period, n_out);
  if (first_seq > std::numeric_limits<std::int64_t>::max() - (count - 1)) return fail(DecodeResult::bad_seq, n_out);
  return DecodeResult::ok;
}

// A batch of `count` samples with `n` inputs whose arrays start at `arrays`:
// input j of sample i at arrays + 8 (j count + i), then y and r.
void decode_batch_samples(const void* data, bool closed_loop, int count, int n, int arrays, StampedSample* out) {
  const std::int64_t utime = get_i64(data, kBatchUtime);
  const double period = get_f64(data, kBatchPeriod);
  const std::int64_t first_seq = get_i64(data, kBatchFirstSeq);
  const int y0 = arrays + 8 * n * count;
  const int r0 = y0 + 8 * count;
  for (int i = 0; i < count; ++i) {
    StampedSample& s = out[i];
    s.utime = utime + std::llround(static_cast<double>(i) * period * 1e6);
    s.seq = first_seq + i;
    s.u = get_f64(data, arrays + 8 * i);
    s.further_inputs = n - 1;
    for (int j = 1; j < n; ++j)
      s.further_u[static_cast<std::size_t>(j - 1)] = get_f64(data, arrays + 8 * (j * count + i));
    s.y = get_f64(data, y0 + 8 * i);
    s.r = closed_loop ? get_f64(data, r0 + 8 * i) : 0.0;
  }
}

// A sample_batch_t (fingerprint checked).
DecodeResult decode_batch1(const void* data, int size, bool closed_loop, StampedSample* out, int capacity, int& n_out,
                           int inputs) {
  if (size < kBatchArrays) return fail(DecodeResult::truncated, n_out);
  const std::int32_t count = get_i32(data, kBatchCount);
  if (count < 1 || count > capacity || out == nullptr) return fail(DecodeResult::bad_count, n_out);
  const std::int64_t expected = kBatchArrays + std::int64_t{24} * count;
  if (size < expected) return fail(DecodeResult::truncated, n_out);
  if (size > expected) return fail(DecodeResult::trailing_bytes, n_out);
  if (const DecodeResult r = check_batch_header(data, count, n_out); r != DecodeResult::ok) return r;
  if (inputs != 1) return fail(DecodeResult::bad_inputs, n_out);
  decode_batch_samples(data, closed_loop, count, 1, kBatchArrays, out);
  n_out = count;
  return DecodeResult::ok;
}

// A sample_batch2_t (fingerprint checked).
DecodeResult decode_batch2(const void* data, int size, bool closed_loop, StampedSample* out, int capacity, int& n_out,
                           int inputs) {
  if (size < kBatch2Arrays) return fail(DecodeResult::truncated, n_out);
  const std::int32_t count = get_i32(data, kBatchCount);
  if (count < 1 || count > capacity || out == nullptr) return fail(DecodeResult::bad_count, n_out);
  const int n = get_i8(data, kBatch2Inputs);
  if (n < 1 || n > kMaxInputs) return fail(DecodeResult::bad_inputs, n_out);
  const std::int64_t expected = batch2_wire_size(count, n);
  if (size < expected) return fail(DecodeResult::truncated, n_out);
  if (size > expected) return fail(DecodeResult::trailing_bytes, n_out);
  if (const DecodeResult r = check_batch_header(data, count, n_out); r != DecodeResult::ok) return r;
  if (n != inputs) return fail(DecodeResult::bad_inputs, n_out);
  decode_batch_samples(data, closed_loop, count, n, kBatch2Arrays, out);
  n_out = count;
  return DecodeResult::ok;
}

}  // namespace

DecodeResult decode_sample(const void* data, int size, bool closed_loop, StampedSample* out, int capacity, int& n_out,
                           int inputs) {
  n_out = 0;
  if (data == nullptr || size < 8) return fail(DecodeResult::truncated, n_out);
  const std::int64_t hash = get_i64(data, 0);
  if (hash == sample_fingerprint()) return decode_sample1(data, size, closed_loop, out, capacity, n_out, inputs);
  if (hash == sample2_fingerprint()) return decode_sample2(data, size, closed_loop, out, capacity, n_out, inputs);
  return fail(DecodeResult::wrong_fingerprint, n_out);
}

DecodeResult decode_batch(const void* data, int size, bool closed_loop, StampedSample* out, int capacity, int& n_out,
                          int inputs) {
  n_out = 0;
  if (data == nullptr || size < 8) return fail(DecodeResult::truncated, n_out);
  const std::int64_t hash = get_i64(data, 0);
  if (hash == batch_fingerprint()) return decode_batch1(data, size, closed_loop, out, capacity, n_out, inputs);
  if (hash == batch2_fingerprint()) return decode_batch2(data, size, closed_loop, out, capacity, n_out, inputs);
  return fail(DecodeResult::wrong_fingerprint, n_out);
}

DecodeResult decode_samples(const void* data, int size, bool closed_loop, StampedSample* out, int capacity, int& n_out,
                            int inputs) {
  n_out = 0;
  if (data == nullptr || size < 8) return fail(DecodeResult::truncated, n_out);
  const std::int64_t hash = get_i64(data, 0);
  if (hash == sample_fingerprint() || hash == sample2_fingerprint())
    return decode_sample(data, size, closed_loop, out, capacity, n_out, inputs);
  if (hash == batch_fingerprint() || hash == batch2_fingerprint())
    return decode_batch(data, size, closed_loop, out, capacity, n_out, inputs);
  return fail(DecodeResult::wrong_fingerprint, n_out);
}

std::vector<std::uint8_t> encode_sample(const StampedSample& s) {
  if (s.further_inputs > 0) return encode_sample2(s);
  sample_t msg;
  msg.utime = s.utime;
  msg.seq = s.seq;
  msg.u = s.u;
  msg.y = s.y;
  msg.r = s.r;
  return encode_message(msg);
}

std::vector<std::uint8_t> encode_sample2(const StampedSample& s) {
  if (s.further_inputs < 0 || s.further_inputs >= kMaxInputs)
    throw std::invalid_argument("encode_sample2: 1 .. " + std::to_string(kMaxInputs) + " inputs");
  sample2_t msg;
  msg.utime = s.utime;
  msg.seq = s.seq;
  msg.n_inputs = static_cast<std::int8_t>(1 + s.further_inputs);
  msg.u.push_back(s.u);
  for (int j = 0; j < s.further_inputs; ++j) msg.u.push_back(s.further_u[static_cast<std::size_t>(j)]);
  msg.y = s.y;
  msg.r = s.r;
  return encode_message(msg);
}

namespace {

// The largest batch an int32 count and the packet's size can hold with n inputs.
void check_batch_size(std::size_t count, int inputs, const char* what) {
  if (count > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max() / (8 * (inputs + 2))))
    throw std::invalid_argument(std::string(what) + ": slice too large");
}

}  // namespace

std::vector<std::uint8_t> encode_batch(std::span<const StampedSample> samples, double sample_period) {
  if (samples.empty()) throw std::invalid_argument("encode_batch: empty slice");
  if (samples.front().further_inputs > 0) return encode_batch2(samples, sample_period);
  check_batch_size(samples.size(), 1, "encode_batch");
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

std::vector<std::uint8_t> encode_batch2(std::span<const StampedSample> samples, double sample_period) {
  if (samples.empty()) throw std::invalid_argument("encode_batch2: empty slice");
  const int inputs = 1 + samples.front().further_inputs;
  if (inputs < 1 || inputs > kMaxInputs)
    throw std::invalid_argument("encode_batch2: 1 .. " + std::to_string(kMaxInputs) + " inputs");
  check_batch_size(samples.size(), inputs, "encode_batch2");
  sample_batch2_t msg;
  msg.utime = samples.front().utime;
  msg.sample_period = sample_period;
  msg.first_seq = samples.front().seq;
  msg.n_inputs = static_cast<std::int8_t>(inputs);
  msg.u.assign(static_cast<std::size_t>(inputs), {});
  for (const StampedSample& s : samples) {
    if (s.further_inputs != inputs - 1) throw std::invalid_argument("encode_batch2: samples with different inputs");
    msg.u[0].push_back(s.u);
    for (int j = 1; j < inputs; ++j)
      msg.u[static_cast<std::size_t>(j)].push_back(s.further_u[static_cast<std::size_t>(j - 1)]);
    msg.y.push_back(s.y);
    msg.r.push_back(s.r);
  }
  msg.count = static_cast<std::int32_t>(msg.y.size());  // always from the arrays
  return encode_message(msg);
}

std::vector<std::uint8_t> encode_batch(const Record& rec, Eigen::Index begin, Eigen::Index count,
                                       std::int64_t utime_offset, std::int64_t first_seq_offset) {
  if (begin < 0 || count < 1 || begin + count > rec.size())
    throw std::invalid_argument("encode_batch: slice outside the record");
  const int inputs = rec.inputs();
  if (inputs > kMaxInputs)
    throw std::invalid_argument("encode_batch: at most " + std::to_string(kMaxInputs) + " inputs");
  check_batch_size(static_cast<std::size_t>(count), inputs, "encode_batch");
  const auto n = static_cast<std::size_t>(count);
  const auto slice = [&](const Eigen::VectorXd& v) {
    return std::vector<double>(v.data() + begin, v.data() + begin + count);
  };
  const std::int64_t utime = utime_offset + std::llround(rec.t(begin) * 1e6);
  const double period = rec.sample_time();
  const std::int64_t first_seq = first_seq_offset + begin;
  if (inputs > 1) {
    sample_batch2_t msg;
    msg.utime = utime;
    msg.sample_period = period;
    msg.first_seq = first_seq;
    msg.n_inputs = static_cast<std::int8_t>(inputs);
    for (int j = 0; j < inputs; ++j) msg.u.push_back(slice(rec.input(j)));
    msg.y = slice(rec.y);
    msg.r = rec.has_reference() ? slice(rec.r) : std::vector<double>(n, 0.0);
    msg.count = static_cast<std::int32_t>(msg.y.size());
    return encode_message(msg);
  }
  sample_batch_t msg;
  msg.utime = utime;
  msg.sample_period = period;
  msg.first_seq = first_seq;
  msg.u = slice(rec.u);
  msg.y = slice(rec.y);
  msg.r = rec.has_reference() ? slice(rec.r) : std::vector<double>(n, 0.0);
  msg.count = static_cast<std::int32_t>(msg.u.size());
  return encode_message(msg);
}

}  // namespace modalwatch
