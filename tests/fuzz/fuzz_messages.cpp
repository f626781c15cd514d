// The LCM input path: every packet that reaches the subscriber goes through
// decode_samples. Properties beyond "no crash": an accepted packet yields
// 1..capacity records with valid utime and consecutive seq, and re-encoding
// them gives a packet that decodes to the same records.
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

bool same(const modalwatch::StampedSample& a, const modalwatch::StampedSample& b) {
  // Bitwise for u, y, r: NaN payloads must survive the round trip as well.
  return a.utime == b.utime && a.seq == b.seq && std::memcmp(&a.u, &b.u, sizeof a.u) == 0 &&
         std::memcmp(&a.y, &b.y, sizeof a.y) == 0 && std::memcmp(&a.r, &b.r, sizeof a.r) == 0;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace modalwatch;
  if (size > static_cast<std::size_t>(batch_wire_size(kCapacity))) return 0;
  const int n = static_cast<int>(size);
  for (const bool closed_loop : {false, true}) {
    int count = -1;
    const DecodeResult result = decode_samples(data, n, closed_loop, first, kCapacity, count);
    if (result != DecodeResult::ok) {
      check(count == 0);
      continue;
    }
    check(count >= 1 && count <= kCapacity);
    for (int i = 0; i < count; ++i) {
      check(first[i].utime >= 0);
      check(i == 0 || first[i].seq == first[i - 1].seq + 1);
      if (!closed_loop) check(first[i].r == 0.0);
    }
    // Re-encode and decode again: the same records (the sample's r is already 0
    // in open loop, so comparing bytes would be wrong there).
    std::vector<std::uint8_t> again;
    if (count == 1 && n == kSampleWireSize) {
      again = encode_sample(first[0]);
    } else {
      // The batch's period: bytes 16..23, a big-endian double after fingerprint and utime.
      std::uint64_t bits = 0;
      for (int i = 16; i < 24; ++i) bits = bits << 8 | data[i];
      double period = 0.0;
      std::memcpy(&period, &bits, sizeof period);
      again = encode_batch(std::span<const StampedSample>(first, static_cast<std::size_t>(count)), period);
    }
    int count2 = -1;
    check(decode_samples(again.data(), static_cast<int>(again.size()), closed_loop, second, kCapacity, count2) ==
          DecodeResult::ok);
    check(count2 == count);
    for (int i = 0; i < count; ++i) check(same(first[i], second[i]));
  }
  return 0;
}
