#pragma once
// The daemon's checkpoint: the estimator state, the fault detector's baselines
// and the newest sample they include, so that a restart resumes without a new
// warm-up.
//
// File format (version 2), little-endian throughout:
//   offset 0   8 bytes  magic "MWCHKPT\0"
//          8   u32      format version (2; version 1, without stabilised
//                       forgetting's reference in the estimator state, is
//                       refused by name and the daemon starts with a warm-up)
//         12   u64      payload length L (at most kMaxCheckpointPayload)
//         20   L bytes  payload: fingerprint, last utime and sequence number,
//                       the estimator state (EstimatorState::write), baselines:
//                       u32 count, then per mode u8 present and, when present,
//                       f64 wn, zeta, gain, u8 learned, f64[9] covariance
//                       (row-major over wn, zeta, gain)
//       20+L   u32      CRC-32 (IEEE 802.3, as zlib) of bytes [0, 20+L)
// Doubles are IEEE-754 binary64 bit patterns, so a round trip is exact.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "modalwatch/estimator.hpp"
#include "modalwatch/fault_detector.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/model.hpp"

namespace modalwatch {

inline constexpr std::uint32_t kCheckpointVersion = 3;
inline constexpr std::uint64_t kMaxCheckpointPayload = 16u << 20;  // 16 MiB: far above any real model

struct Checkpoint {
  std::uint64_t config_fingerprint = 0;  // checkpoint_fingerprint(config) when written
  std::int64_t last_utime = 0;           // us, newest sample included
  std::int64_t last_seq = -1;            // its sequence number
  EstimatorState estimator;
  // Fault-detector baselines per mode (value, covariance, learned or configured);
  // nullopt = not yet known.
  std::vector<std::optional<ModeBaseline>> baselines;
};

// What a checkpoint must match: sample time, loop, controller, model structure
// (names, kinds, orders, the sensor, with several inputs the input of each),
// forgetting. Not: LCM, thresholds, logging, initial values.
// FNV-1a (64 bit) over a canonical little-endian serialisation of those.
std::uint64_t checkpoint_fingerprint(const Config& config);

// Throws std::invalid_argument for what the decoder would reject (more than 64
// submodels or baselines, a name longer than 256 bytes).
std::vector<std::uint8_t> encode_checkpoint(const Checkpoint& c);
// Never crashes on any bytes: checks magic, version, lengths (against the bytes
// that remain, before allocating), CRC, finiteness and structure; throws
// InputError naming `source`, the byte offset and what is wrong.
Checkpoint decode_checkpoint(std::span<const std::uint8_t> bytes, const std::string& source);

// Atomic: a temporary file in the same directory, fsync, rename over `path`,
// fsync the directory. Throws std::system_error (with errno, e.g. ENOSPC, EACCES)
// on failure and leaves the previous checkpoint intact.
void write_checkpoint(const std::string& path, const Checkpoint& c);
// InputError for a missing or unreadable file as well as for bad contents.
Checkpoint read_checkpoint(const std::string& path);

}  // namespace modalwatch
