#include "modalwatch/io/lcm_log.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>

#include "modalwatch/error.hpp"
#include "modalwatch/io/messages.hpp"

namespace modalwatch {
namespace {

constexpr std::size_t kEventHeader = 4 + 8 + 8 + 4 + 4;
// LCM limits channel names to 63 characters; anything far beyond is corruption.
constexpr std::int32_t kMaxChannel = 1024;

std::uint64_t be(const std::uint8_t* p, int n) {
  std::uint64_t v = 0;
  for (int i = 0; i < n; ++i) v = (v << 8) | p[i];
  return v;
}

[[noreturn]] void fail(const std::string& source, std::size_t offset, const std::string& what) {
  throw InputError(source, "LCM log: byte offset " + std::to_string(offset) + ": " + what);
}

}  // namespace

bool is_lcm_log(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::uint8_t b[4];
  if (!in.read(reinterpret_cast<char*>(b), 4)) return false;
  return be(b, 4) == kLcmSyncWord;
}

LcmLogRecord parse_lcm_log(std::span<const std::uint8_t> bytes, const std::string& source,
                           const LcmLogOptions& options) {
  LcmLogRecord out;
  std::vector<std::int64_t> utime, seq;
  std::vector<double> u, y, r;
  std::vector<std::vector<double>> further(static_cast<std::size_t>(std::max(0, options.inputs - 1)));
  std::vector<StampedSample> buf;
  std::size_t pos = 0;
  while (pos < bytes.size()) {
    const std::size_t at = pos;
    const std::size_t left = bytes.size() - pos;
    if (left < kEventHeader)
      fail(source, at,
           "truncated event header (" + std::to_string(left) + " of " + std::to_string(kEventHeader) + " bytes)");
    const std::uint8_t* p = bytes.data() + pos;
    const std::uint64_t sync = be(p, 4);
    if (sync != kLcmSyncWord) {
      char hex[16];
      std::snprintf(hex, sizeof hex, "0x%08llX", static_cast<unsigned long long>(sync));
      fail(source, at, std::string("bad sync word ") + hex + " (expected 0xEDA1DA01): not an LCM log or corrupt");
    }
    const auto channel_len = static_cast<std::int32_t>(static_cast<std::uint32_t>(be(p + 20, 4)));
    const auto data_len = static_cast<std::int32_t>(static_cast<std::uint32_t>(be(p + 24, 4)));
    if (channel_len < 0 || channel_len > kMaxChannel)
      fail(source, at + 20,
           "channel length " + std::to_string(channel_len) + " outside [0, " + std::to_string(kMaxChannel) + "]");
    if (data_len < 0) fail(source, at + 24, "negative data length " + std::to_string(data_len));
    const std::size_t body = static_cast<std::size_t>(channel_len) + static_cast<std::size_t>(data_len);
    if (left - kEventHeader < body)
      fail(source, at,
           "truncated event (" + std::to_string(kEventHeader + body) + " bytes announced, " + std::to_string(left) +
               " left)");
    pos += kEventHeader + body;
    ++out.events;
    const std::string_view channel(reinterpret_cast<const char*>(p + kEventHeader),
                                   static_cast<std::size_t>(channel_len));
    if (!options.channel.empty() && channel != options.channel) {
      ++out.skipped_channel;
      continue;
    }
    const std::uint8_t* data = p + kEventHeader + channel_len;
    if (data_len < 8) {
      ++out.skipped_type;
      continue;
    }
    const auto fp = static_cast<std::int64_t>(be(data, 8));
    if (fp != sample_fingerprint() && fp != batch_fingerprint() && fp != sample2_fingerprint() &&
        fp != batch2_fingerprint()) {
      ++out.skipped_type;
      continue;
    }
    // A batch holds at most (size - 36) / 24 samples: the buffer never exceeds the event.
    const int capacity = std::max(1, (data_len - batch_wire_size(0)) / 24);
    if (buf.size() < static_cast<std::size_t>(capacity)) buf.resize(static_cast<std::size_t>(capacity));
    int n = 0;
    const DecodeResult decoded =
        decode_samples(data, data_len, options.closed_loop, buf.data(), capacity, n, options.inputs);
    if (decoded != DecodeResult::ok) {
      ++(decoded == DecodeResult::bad_inputs ? out.skipped_inputs : out.skipped_invalid);
      continue;
    }
    ++out.sample_events;
    if (std::find(out.channels.begin(), out.channels.end(), channel) == out.channels.end())
      out.channels.emplace_back(channel);
    for (int i = 0; i < n; ++i) {
      const StampedSample& s = buf[static_cast<std::size_t>(i)];
      if (!utime.empty() && (s.utime <= utime.back() || s.seq <= seq.back())) {
        ++out.skipped_order;
        continue;
      }
      utime.push_back(s.utime);
      seq.push_back(s.seq);
      u.push_back(s.u);
      y.push_back(s.y);
      r.push_back(s.r);
      for (std::size_t j = 0; j < further.size(); ++j) further[j].push_back(s.further_u[j]);
      out.offsets.push_back(at);
    }
  }
  if (utime.empty())
    throw InputError(source,
                     "LCM log: no sample_t, sample_batch_t, sample2_t or sample_batch2_t events" +
                         (options.inputs > 1 ? " of " + std::to_string(options.inputs) + " inputs" : std::string()) +
                         (options.channel.empty() ? std::string() : " on channel '" + options.channel + "'") + " (" +
                         std::to_string(out.events) + " events, " + std::to_string(out.skipped_channel) +
                         " on other channels, " + std::to_string(out.skipped_type) + " of other types, " +
                         std::to_string(out.skipped_inputs) + " of another number of inputs, " +
                         std::to_string(out.skipped_invalid) + " invalid)");
  const auto N = static_cast<Eigen::Index>(utime.size());
  Record& rec = out.record;
  rec.t.resize(N);
  rec.u = Eigen::Map<const Eigen::VectorXd>(u.data(), N);
  rec.y = Eigen::Map<const Eigen::VectorXd>(y.data(), N);
  if (options.closed_loop) rec.r = Eigen::Map<const Eigen::VectorXd>(r.data(), N);
  for (const auto& v : further) rec.further_u.emplace_back(Eigen::Map<const Eigen::VectorXd>(v.data(), N));
  // Exact integer difference, one correctly rounded division: a CSV time of
  // k * 0.05 s printed as "0.05" reads back as the same double.
  for (Eigen::Index k = 0; k < N; ++k)
    rec.t(k) = static_cast<double>(utime[static_cast<std::size_t>(k)] - utime[0]) / 1e6;
  return out;
}

LcmLogRecord read_lcm_log(const std::string& path, const LcmLogOptions& options) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, std::string("cannot open: ") + std::strerror(errno));
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw InputError(path, "cannot read");
  return parse_lcm_log(bytes, path, options);
}

}  // namespace modalwatch
