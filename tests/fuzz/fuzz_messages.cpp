// The LCM input path: every packet that reaches the subscriber goes through
// decode_samples, for the model's number of inputs (1 .. kMaxInputs; the
// fuzzer's packet is tried with each). Properties beyond "no crash": an
// accepted packet yields 1..capacity records with valid utime, consecutive seq
// and the model's inputs, and re-encoding them in the packet's own version
// gives a packet that decodes to the same records.
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <span>
#include <vector>

#include "modalwatch/io/messages.hpp"

namespace {
constexpr int kCapacity = 4096;
modalwatch::StampedSample first[kCapacity];
modalwatch::StampedSample second[kCapacity];

void check(bool ok) {
  if (!ok) std::abort();
}

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

bool same(const modalwatch::StampedSample& a, const modalwatch::StampedSample& b) {
  // Bitwise for the inputs, y, r: NaN payloads must survive the round trip as well.
  if (a.utime != b.utime || a.seq != b.seq || a.further_inputs != b.further_inputs) return false;
  for (int j = 0; j <= a.further_inputs; ++j)
    if (!same_bits(a.input(j), b.input(j))) return false;
  return same_bits(a.y, b.y) && same_bits(a.r, b.r);
}

std::int64_t fingerprint(const std::uint8_t* data) {
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v = v << 8 | data[i];
  return static_cast<std::int64_t>(v);
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace modalwatch;
  if (size > static_cast<std::size_t>(batch2_wire_size(kCapacity, kMaxInputs))) return 0;
  const int n = static_cast<int>(size);
  for (int inputs = 1; inputs <= kMaxInputs; ++inputs) {
    for (const bool closed_loop : {false, true}) {
      int count = -1;
      const DecodeResult result = decode_samples(data, n, closed_loop, first, kCapacity, count, inputs);
      if (result != DecodeResult::ok) {
        check(count == 0);
        continue;
      }
      check(count >= 1 && count <= kCapacity);
      for (int i = 0; i < count; ++i) {
        check(first[i].utime >= 0);
        check(first[i].further_inputs == inputs - 1);
        check(i == 0 || first[i].seq == first[i - 1].seq + 1);
        if (!closed_loop) check(first[i].r == 0.0);
      }
      // Re-encode in the packet's version and decode again: the same records
      // (the sample's r is already 0 in open loop, so comparing bytes would be
      // wrong there).
      const std::int64_t hash = fingerprint(data);
      std::vector<std::uint8_t> again;
      if (hash == sample_fingerprint()) {
        again = encode_sample(first[0]);
      } else if (hash == sample2_fingerprint()) {
        again = encode_sample2(first[0]);
      } else {
        // The batch's period: bytes 16..23, a big-endian double after fingerprint and utime.
        std::uint64_t bits = 0;
        for (int i = 16; i < 24; ++i) bits = bits << 8 | data[i];
        double period = 0.0;
        std::memcpy(&period, &bits, sizeof period);
        const std::span<const StampedSample> slice(first, static_cast<std::size_t>(count));
        again = hash == batch2_fingerprint() ? encode_batch2(slice, period) : encode_batch(slice, period);
      }
      int count2 = -1;
      check(decode_samples(again.data(), static_cast<int>(again.size()), closed_loop, second, kCapacity, count2,
                           inputs) == DecodeResult::ok);
      check(count2 == count);
      for (int i = 0; i < count; ++i) check(same(first[i], second[i]));
    }
  }
  return 0;
}
