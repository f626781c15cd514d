#pragma once
// The daemon's input messages (lcmtypes/modalwatch_sample_t.lcm and
// modalwatch_sample_batch_t.lcm) on the wire, without the generated types in
// the interface.
//
// Decoding
// - decode_sample, decode_batch and decode_samples parse the LCM wire format
//   themselves, straight into caller-owned SampleRecords: they never allocate
//   and never throw, so they may run on the LCM subscriber thread for every
//   packet. (The lcm-gen decode() resizes std::vectors to a count taken from
//   the packet: it allocates, and random bytes can make it ask for gigabytes.)
//   The generated types provide the fingerprints; the round-trip tests check
//   that both sides agree on the layout.
// - decode_samples chooses the type by the packet's fingerprint, so one
//   channel may carry both; decode_sample and decode_batch accept only their
//   own type (a sample on the batch channel is a wrong fingerprint).
// - Validated here: size (truncated or trailing bytes), fingerprint,
//   1 <= count <= capacity, sample_period finite and > 0 and the batch's time
//   span representable, utime >= 0, first_seq + count - 1 without overflow.
//   On any failure n_out is 0 and nothing in `out` is meaningful.
// - NOT rejected here: non-finite u, y or r. The estimation side drops and
//   counts those per sample (a NaN in one sample must not cost its batch), and
//   sequence numbers (duplicates, order) are also its business.
// - closed_loop == false: r is ignored and set to 0 in every record, so that a
//   sender's unused (possibly NaN) reference does not get samples dropped.
//
// Encoding (tests, replay): a batch's count always comes from the slice size.
#include <cstdint>
#include <span>
#include <type_traits>
#include <vector>

#include <Eigen/Core>

#include "modalwatch/record.hpp"

namespace modalwatch {

// One sample, as pushed into the SPSC ring from the LCM thread.
struct StampedSample {
  std::int64_t utime = 0;  // us, sample time (controller clock)
  std::int64_t seq = 0;    // sequence number
  double u = 0.0;          // plant input
  double y = 0.0;          // measured output
  double r = 0.0;          // reference (0 in open loop)
};
static_assert(std::is_trivially_copyable_v<StampedSample>);
static_assert(sizeof(StampedSample) == 40);

enum class DecodeResult : int {
  ok = 0,
  truncated,          // shorter than the fingerprint, the header or the arrays
  trailing_bytes,     // longer than the type (or the batch's count) implies
  wrong_fingerprint,  // another LCM type (or garbage)
  bad_count,          // batch count < 1 or > capacity
  bad_period,         // sample_period not finite, <= 0, or the batch spans
                      // more time than an int64 utime can hold
  bad_utime,          // utime < 0
  bad_seq,            // first_seq + count - 1 overflows int64
};
const char* to_string(DecodeResult r);

// The lcm-gen fingerprints (the first 8 bytes of every packet).
std::int64_t sample_fingerprint();
std::int64_t batch_fingerprint();

// Exact wire sizes: 48 bytes for a sample, 36 + 24 count for a batch.
constexpr int kSampleWireSize = 8 + 8 + 8 + 3 * 8;
constexpr int batch_wire_size(int count) { return 8 + 8 + 8 + 8 + 4 + 3 * 8 * count; }

// A sample_t packet into out[0] (capacity >= 1 required, else bad_count).
DecodeResult decode_sample(const void* data, int size, bool closed_loop, StampedSample* out, int capacity, int& n_out);
// A sample_batch_t packet into out[0..count). Sample i gets
// utime = utime + llround(i * sample_period * 1e6), seq = first_seq + i.
DecodeResult decode_batch(const void* data, int size, bool closed_loop, StampedSample* out, int capacity, int& n_out);
// Either of the two, chosen by fingerprint.
DecodeResult decode_samples(const void* data, int size, bool closed_loop, StampedSample* out, int capacity, int& n_out);

// Encoders (allocate; not for the real-time path).
std::vector<std::uint8_t> encode_sample(const StampedSample& s);
// A batch from records: utime and first_seq from samples[0] (the other
// records' utime and seq are implied by sample_period and not checked).
// Requires a non-empty slice.
std::vector<std::uint8_t> encode_batch(std::span<const StampedSample> samples, double sample_period);
// Samples [begin, begin + count) of a Record as a batch:
// utime = utime_offset + llround(rec.t(begin) * 1e6), sample_period =
// rec.sample_time(), first_seq = first_seq_offset + begin, r = 0 when the
// record has no reference.
std::vector<std::uint8_t> encode_batch(const Record& rec, Eigen::Index begin, Eigen::Index count,
                                       std::int64_t utime_offset = 0, std::int64_t first_seq_offset = 0);

}  // namespace modalwatch
