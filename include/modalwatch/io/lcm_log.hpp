#pragma once
// Records from LCM log files as lcm-logger writes them, parsed here rather than
// with liblcm's lcm_eventlog (which trusts the lengths in the file, and a
// record should be readable from any bytes without crashing).
//
// An event, all integers big-endian:
//   u32 sync word 0xEDA1DA01, i64 event number, i64 timestamp (us, logger clock),
//   i32 channel length, i32 data length, channel (no terminator), data.
// sample_t, sample_batch_t, sample2_t and sample_batch2_t events (chosen by
// fingerprint) become samples with the allocation-free decoders of
// messages.hpp, those of options.inputs inputs (Record::further_u after the
// first); events of another number of inputs are skipped and counted. The
// record's time is t = (utime - utime of the first sample) / 1e6 s; r is
// filled in closed loop.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "modalwatch/record.hpp"

namespace modalwatch {

inline constexpr std::uint32_t kLcmSyncWord = 0xEDA1DA01u;

struct LcmLogOptions {
  std::string channel;       // only events on this channel; empty: every channel
  bool closed_loop = false;  // keep r (else r is empty, as in an open-loop CSV)
  int inputs = 1;            // measured inputs per sample (the model's)
};

struct LcmLogRecord {
  Record record;
  std::vector<std::uint64_t> offsets;  // byte offset of the event each sample came from
  std::uint64_t events = 0;            // events in the file
  std::uint64_t sample_events = 0;     // events that gave samples
  std::uint64_t skipped_channel = 0;   // on another channel than options.channel
  std::uint64_t skipped_type = 0;      // not a sample_t or sample_batch_t (fingerprint)
  std::uint64_t skipped_invalid = 0;   // a sample type that failed to decode (size, count, period, ...)
  std::uint64_t skipped_inputs = 0;    // a sample type of another number of inputs than options.inputs
  std::uint64_t skipped_order = 0;     // samples whose utime or seq did not increase (duplicates, reordering)
  std::vector<std::string> channels;   // channels that carried samples
};

// True when the file starts with the LCM sync word (content, not the file name,
// decides). False for a missing or empty file.
bool is_lcm_log(const std::string& path);

// Parses a log in memory. Throws InputError naming `source` and the byte offset
// for a bad sync word, a negative or oversized length, or a truncated event,
// and when no sample is found.
LcmLogRecord parse_lcm_log(std::span<const std::uint8_t> bytes, const std::string& source,
                           const LcmLogOptions& options = {});
LcmLogRecord read_lcm_log(const std::string& path, const LcmLogOptions& options = {});

}  // namespace modalwatch
