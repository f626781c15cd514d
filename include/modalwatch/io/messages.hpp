#pragma once
// The daemon's input messages (lcmtypes/modalwatch_sample_t.lcm,
// modalwatch_sample_batch_t.lcm and, for several measured inputs,
// modalwatch_sample2_t.lcm and modalwatch_sample_batch2_t.lcm) on the wire,
// without the generated types in the interface.
//
// Decoding
// - decode_sample, decode_batch and decode_samples parse the LCM wire format
//   themselves, straight into caller-owned StampedSamples: they never allocate
//   and never throw, so they may run on the LCM subscriber thread for every
//   packet. (The lcm-gen decode() resizes std::vectors to a count taken from
//   the packet: it allocates, and random bytes can make it ask for gigabytes.)
//   The generated types provide the fingerprints; the round-trip tests check
//   that both sides agree on the layout.
// - Each takes the model's number of inputs. decode_sample takes a sample_t or
//   a sample2_t, decode_batch a sample_batch_t or a sample_batch2_t, each by
//   its fingerprint, so one channel carries both versions; decode_samples any
//   of the four (an LCM log). A sample on the batch channel is a wrong
//   fingerprint. The single-input types suit a model of one input only; a
//   sample2_t or sample_batch2_t must carry exactly the model's inputs: any
//   other count (or a single-input type for a model of several) is bad_inputs.
// - Validated here: size (truncated or trailing bytes), fingerprint,
//   1 <= count <= capacity, 1 <= n_inputs <= kMaxInputs and the model's,
//   sample_period finite and > 0 and the batch's time span representable,
//   utime >= 0, first_seq + count - 1 without overflow. On any failure n_out
//   is 0 and nothing in `out` is meaningful.
// - NOT rejected here: non-finite u, y or r. The estimation side drops and
//   counts those per sample (a NaN in one sample must not cost its batch), and
//   sequence numbers (duplicates, order) are also its business.
// - closed_loop == false: r is ignored and set to 0 in every record, so that a
//   sender's unused (possibly NaN) reference does not get samples dropped.
//
// Encoding (tests, replay): a batch's count always comes from the slice size;
// samples of one input go out as the single-input types (which every version
// of the daemon reads), of several as the new ones.
#include <array>
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
  double u = 0.0;          // plant input (the first, with several)
  double y = 0.0;          // measured output
  double r = 0.0;          // reference (0 in open loop)
  // The inputs after u: further_u[0 .. further_inputs) (Sample's).
  std::int32_t further_inputs = 0;
  std::array<double, kMaxInputs - 1> further_u{};

  // Input j: u for j = 0, else further_u[j - 1] (j <= further_inputs, unchecked).
  double input(int j) const noexcept { return j == 0 ? u : further_u[static_cast<std::size_t>(j - 1)]; }
};
static_assert(std::is_trivially_copyable_v<StampedSample>);
static_assert(sizeof(StampedSample) == 104);

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
  bad_inputs,         // n_inputs outside 1 .. kMaxInputs, or not the model's number of inputs
};
const char* to_string(DecodeResult r);

// The lcm-gen fingerprints (the first 8 bytes of every packet).
std::int64_t sample_fingerprint();
std::int64_t batch_fingerprint();
std::int64_t sample2_fingerprint();
std::int64_t batch2_fingerprint();

// Exact wire sizes: 48 bytes for a sample, 36 + 24 count for a batch; with
// n inputs 41 + 8 n for a sample2_t, 37 + 8 (n + 2) count for a sample_batch2_t.
constexpr int kSampleWireSize = 8 + 8 + 8 + 3 * 8;
constexpr int batch_wire_size(int count) { return 8 + 8 + 8 + 8 + 4 + 3 * 8 * count; }
constexpr int sample2_wire_size(int inputs) { return 8 + 8 + 8 + 1 + 8 * inputs + 2 * 8; }
constexpr std::int64_t batch2_wire_size(int count, int inputs) {
  return 8 + 8 + 8 + 8 + 4 + 1 + std::int64_t{8} * (inputs + 2) * count;
}

// A sample_t or sample2_t packet into out[0] (capacity >= 1 required, else
// bad_count), for a model of `inputs` inputs.
DecodeResult decode_sample(const void* data, int size, bool closed_loop, StampedSample* out, int capacity, int& n_out,
                           int inputs = 1);
// A sample_batch_t or sample_batch2_t packet into out[0..count). Sample i gets
// utime = utime + llround(i * sample_period * 1e6), seq = first_seq + i.
DecodeResult decode_batch(const void* data, int size, bool closed_loop, StampedSample* out, int capacity, int& n_out,
                          int inputs = 1);
// Any of the four, chosen by fingerprint.
DecodeResult decode_samples(const void* data, int size, bool closed_loop, StampedSample* out, int capacity, int& n_out,
                            int inputs = 1);

// Encoders (allocate; not for the real-time path). A sample or slice with
// further inputs goes out as sample2_t / sample_batch2_t, one of a single
// input as sample_t / sample_batch_t; the *2 encoders always use the new type.
std::vector<std::uint8_t> encode_sample(const StampedSample& s);
std::vector<std::uint8_t> encode_sample2(const StampedSample& s);
// A batch from records: utime and first_seq from samples[0] (the other
// records' utime and seq are implied by sample_period and not checked), the
// number of inputs too. Requires a non-empty slice.
std::vector<std::uint8_t> encode_batch(std::span<const StampedSample> samples, double sample_period);
std::vector<std::uint8_t> encode_batch2(std::span<const StampedSample> samples, double sample_period);
// Samples [begin, begin + count) of a Record as a batch:
// utime = utime_offset + llround(rec.t(begin) * 1e6), sample_period =
// rec.sample_time(), first_seq = first_seq_offset + begin, r = 0 when the
// record has no reference, every input of the record.
std::vector<std::uint8_t> encode_batch(const Record& rec, Eigen::Index begin, Eigen::Index count,
                                       std::int64_t utime_offset = 0, std::int64_t first_seq_offset = 0);

}  // namespace modalwatch
