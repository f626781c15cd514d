#include "modalwatch/io/checkpoint.hpp"

#include <array>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <stdexcept>

#include "crc32.hpp"
#include "modalwatch/error.hpp"
#include "modalwatch/io/atomic_file.hpp"

namespace modalwatch {
namespace {

constexpr std::array<std::uint8_t, 8> kMagic = {'M', 'W', 'C', 'H', 'K', 'P', 'T', 0};
constexpr std::size_t kHeaderSize = 8 + 4 + 8;
constexpr std::uint32_t kMaxSubmodels = 64;
constexpr std::uint32_t kMaxName = 256;
constexpr std::uint32_t kMaxBaselines = 64;

constexpr std::array<std::uint32_t, 256> make_crc_table() {
  std::array<std::uint32_t, 256> t{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    t[i] = c;
  }
  return t;
}
constexpr auto kCrcTable = make_crc_table();

// ---------------------------------------------------------------- writing

class Writer {
 public:
  std::vector<std::uint8_t> bytes;
  void u8(std::uint8_t v) { bytes.push_back(v); }
  void u32(std::uint32_t v) {
    for (int i = 0; i < 4; ++i) bytes.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void u64(std::uint64_t v) {
    for (int i = 0; i < 8; ++i) bytes.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void i32(std::int32_t v) { u32(static_cast<std::uint32_t>(v)); }
  void i64(std::int64_t v) { u64(static_cast<std::uint64_t>(v)); }
  void f64(double v) { u64(std::bit_cast<std::uint64_t>(v)); }
  void str(const std::string& s) {
    u32(static_cast<std::uint32_t>(s.size()));
    bytes.insert(bytes.end(), s.begin(), s.end());
  }
  void vec(const Eigen::VectorXd& v) {
    for (Eigen::Index i = 0; i < v.size(); ++i) f64(v(i));
  }
  void mat(const Eigen::MatrixXd& m) {  // row-major
    for (Eigen::Index i = 0; i < m.rows(); ++i)
      for (Eigen::Index j = 0; j < m.cols(); ++j) f64(m(i, j));
  }
};

// The estimator state's values into the payload.
class StateBytes final : public StateWriter {
 public:
  explicit StateBytes(Writer& w) : w_(w) {}
  void flag(bool v, const char*) override { w_.u8(v); }
  void count(std::size_t v, const char*) override {
    if (v > kMaxSubmodels)
      throw std::invalid_argument("checkpoint: more than " + std::to_string(kMaxSubmodels) + " submodels or baselines");
    w_.u32(static_cast<std::uint32_t>(v));
  }
  void name(const std::string& v, const char*) override {
    if (v.size() > kMaxName) throw std::invalid_argument("checkpoint: submodel name longer than 256 bytes");
    w_.str(v);
  }
  void integer(std::int32_t v, const char*) override { w_.i32(v); }
  void counter(std::uint64_t v, const char*) override { w_.u64(v); }
  void real(double v, const char*) override { w_.f64(v); }
  void reals(const Eigen::VectorXd& v, const char*) override { w_.vec(v); }
  void matrix(const Eigen::MatrixXd& v, const char*) override { w_.mat(v); }

 private:
  Writer& w_;
};

// ---------------------------------------------------------------- reading

// Every read checks the remaining length first; every count is capped before
// anything is allocated from it.
class Reader {
 public:
  Reader(std::span<const std::uint8_t> b, std::size_t base, const std::string& source)
      : b_(b), base_(base), source_(source) {}
  [[noreturn]] void fail(const std::string& what) const {
    throw InputError(source_, "checkpoint: byte offset " + std::to_string(base_ + pos_) + ": " + what);
  }
  void need(std::size_t n, const char* what) const {
    if (b_.size() - pos_ < n)
      fail(std::string("truncated ") + what + " (" + std::to_string(n) + " bytes needed, " +
           std::to_string(b_.size() - pos_) + " left)");
  }
  std::uint64_t raw(int n, const char* what) {
    need(static_cast<std::size_t>(n), what);
    std::uint64_t v = 0;
    for (int i = 0; i < n; ++i) v |= static_cast<std::uint64_t>(b_[pos_ + i]) << (8 * i);
    pos_ += static_cast<std::size_t>(n);
    return v;
  }
  std::uint8_t u8(const char* what) { return static_cast<std::uint8_t>(raw(1, what)); }
  bool flag(const char* what) {
    const std::size_t at = pos_;
    const std::uint8_t v = u8(what);
    if (v > 1) {
      pos_ = at;
      std::string message = what;  // appended: GCC 12 warns falsely on std::string(what) + "..."
      message += ": " + std::to_string(v) + " is not a boolean (0 or 1)";
      fail(message);
    }
    return v == 1;
  }
  std::uint32_t u32(const char* what) { return static_cast<std::uint32_t>(raw(4, what)); }
  std::uint64_t u64(const char* what) { return raw(8, what); }
  std::int32_t i32(const char* what) { return static_cast<std::int32_t>(u32(what)); }
  std::int64_t i64(const char* what) { return static_cast<std::int64_t>(u64(what)); }
  double f64(const char* what) {
    const std::size_t at = pos_;
    const double v = std::bit_cast<double>(u64(what));
    if (!std::isfinite(v)) {
      pos_ = at;
      std::string message = what;
      message += " is not finite";
      fail(message);
    }
    return v;
  }
  std::uint32_t count(const char* what, std::uint32_t cap) {
    const std::size_t at = pos_;
    const std::uint32_t n = u32(what);
    if (n > cap) {
      pos_ = at;
      fail(std::string(what) + " " + std::to_string(n) + " exceeds the limit " + std::to_string(cap));
    }
    return n;
  }
  std::string str(const char* what, std::uint32_t cap) {
    const std::uint32_t n = count(what, cap);
    need(n, what);
    std::string s(reinterpret_cast<const char*>(b_.data() + pos_), n);
    pos_ += n;
    return s;
  }
  Eigen::VectorXd vec(Eigen::Index n, const char* what) {
    need(static_cast<std::size_t>(n) * 8, what);
    Eigen::VectorXd v(n);
    for (Eigen::Index i = 0; i < n; ++i) v(i) = f64(what);
    return v;
  }
  Eigen::MatrixXd mat(Eigen::Index n, const char* what) {
    need(static_cast<std::size_t>(n * n) * 8, what);
    Eigen::MatrixXd m(n, n);
    for (Eigen::Index i = 0; i < n; ++i)
      for (Eigen::Index j = 0; j < n; ++j) m(i, j) = f64(what);
    return m;
  }
  std::int32_t integer(const char* what, std::int32_t lo, std::int32_t hi) {
    const std::size_t at = pos_;
    const std::int32_t v = i32(what);
    if (v < lo || v > hi) {
      pos_ = at;
      fail(std::string(what) + " " + std::to_string(v) + " outside [" + std::to_string(lo) + ", " + std::to_string(hi) +
           "]");
    }
    return v;
  }
  std::size_t pos() const { return pos_; }
  std::size_t left() const { return b_.size() - pos_; }

 private:
  std::span<const std::uint8_t> b_;
  std::size_t base_;
  std::size_t pos_ = 0;
  const std::string& source_;
};

// The estimator state's values from the payload, each checked as it is read.
class StateFromBytes final : public StateReader {
 public:
  explicit StateFromBytes(Reader& r) : r_(r) {}
  bool flag(const char* what) override { return r_.flag(what); }
  std::size_t count(const char* what) override { return r_.count(what, kMaxSubmodels); }
  std::string name(const char* what) override { return r_.str(what, kMaxName); }
  std::int32_t integer(const char* what, std::int32_t lo, std::int32_t hi) override { return r_.integer(what, lo, hi); }
  std::uint64_t counter(const char* what) override { return r_.u64(what); }
  double real(const char* what) override { return r_.f64(what); }
  Eigen::VectorXd reals(Eigen::Index size, const char* what) override { return r_.vec(size, what); }
  Eigen::MatrixXd matrix(Eigen::Index size, const char* what) override { return r_.mat(size, what); }
  [[noreturn]] void fail(const std::string& what) override { r_.fail(what); }

 private:
  Reader& r_;
};

// FNV-1a, 64 bit.
struct Fnv {
  std::uint64_t h = 0xcbf29ce484222325ull;
  void bytes(const void* p, std::size_t n) {
    const auto* c = static_cast<const std::uint8_t*>(p);
    for (std::size_t i = 0; i < n; ++i) h = (h ^ c[i]) * 0x100000001b3ull;
  }
  void u64(std::uint64_t v) {
    std::uint8_t b[8];
    for (int i = 0; i < 8; ++i) b[i] = static_cast<std::uint8_t>(v >> (8 * i));
    bytes(b, 8);
  }
  void f64(double v) { u64(std::bit_cast<std::uint64_t>(v == 0.0 ? 0.0 : v)); }  // -0 == +0
  void str(const std::string& s) {
    u64(s.size());
    bytes(s.data(), s.size());
  }
};

}  // namespace

std::uint32_t crc32(std::span<const std::uint8_t> bytes) {
  std::uint32_t c = 0xFFFFFFFFu;
  for (std::uint8_t b : bytes) c = kCrcTable[(c ^ b) & 0xFFu] ^ (c >> 8);
  return c ^ 0xFFFFFFFFu;
}

std::uint64_t checkpoint_fingerprint(const Config& config) {
  Fnv f;
  f.str("modalwatch checkpoint fingerprint v1");
  f.f64(config.sample_time);
  f.u64(config.closed_loop ? 1 : 0);
  if (config.closed_loop) {
    f.u64(config.controller.numerator().size());
    for (double v : config.controller.numerator()) f.f64(v);
    f.u64(config.controller.denominator().size());
    for (double v : config.controller.denominator()) f.f64(v);
  }
  f.u64(config.model.submodels.size());
  for (std::size_t i = 0; i < config.model.submodels.size(); ++i) {
    const Submodel& s = config.model.submodels[i];
    f.str(s.name);
    f.u64(static_cast<std::uint64_t>(s.n));
    f.u64(static_cast<std::uint64_t>(s.m));
    f.u64(static_cast<std::uint64_t>(s.rigid_poles));
    // The sensor when it is not a position one: position adds nothing, so that
    // a position model's fingerprint does not depend on the key.
    if (s.output_derivatives != 0) {
      f.str("output");
      f.u64(static_cast<std::uint64_t>(s.output_derivatives));
    }
    // The input that drives it, with several: the state does not say (the
    // configuration does), and a checkpoint of a model whose submodels changed
    // inputs is another model's. One input adds nothing, as position does.
    if (config.model.n_inputs() > 1) {
      f.str("input");
      f.str(config.model.input_name(s.input));
    }
    const double lambda = i < config.estimator.forgetting.size() ? config.estimator.forgetting[i]
                          : i < config.submodel_settings.size()  ? config.submodel_settings[i].forgetting
                                                                 : 1.0;
    f.f64(lambda);
  }
  return f.h;
}

std::vector<std::uint8_t> encode_checkpoint(const Checkpoint& c) {
  // Refuse what decode_checkpoint would refuse, rather than write a file that
  // cannot be read (StateBytes refuses the estimator state's part).
  if (c.baselines.size() > kMaxBaselines)
    throw std::invalid_argument("checkpoint: more than " + std::to_string(kMaxSubmodels) + " submodels or baselines");
  Writer w;
  w.bytes.assign(kMagic.begin(), kMagic.end());
  w.u32(kCheckpointVersion);
  w.u64(0);  // payload length, filled in below
  w.u64(c.config_fingerprint);
  w.i64(c.last_utime);
  w.i64(c.last_seq);
  StateBytes state(w);
  c.estimator.write(state);

  w.u32(static_cast<std::uint32_t>(c.baselines.size()));
  for (const auto& b : c.baselines) {
    w.u8(b.has_value());
    if (b) {
      w.f64(b->value.wn);
      w.f64(b->value.zeta);
      w.f64(b->value.gain);
      w.u8(b->learned);
      for (const double v : b->covariance) w.f64(v);
    }
  }
  const std::uint64_t payload = w.bytes.size() - kHeaderSize;
  for (int i = 0; i < 8; ++i) w.bytes[12 + i] = static_cast<std::uint8_t>(payload >> (8 * i));
  const std::uint32_t crc = crc32(w.bytes);
  w.u32(crc);
  return std::move(w.bytes);
}

Checkpoint decode_checkpoint(std::span<const std::uint8_t> bytes, const std::string& source) {
  Reader h(bytes, 0, source);
  h.need(kMagic.size(), "magic");
  if (!std::equal(kMagic.begin(), kMagic.end(), bytes.begin())) h.fail("not a modalwatch checkpoint (wrong magic)");
  h.raw(8, "magic");
  const std::uint32_t version = h.u32("version");
  // Version 1 lacks stabilised forgetting's reference (theta_ref, P_ref): a
  // run resumed from it would stabilise toward another point than the run that
  // wrote it. Version 2 lacks the instruments' joint information, without which
  // the covariance the detector tests against is the submodels' own for a
  // memory. Refused, like any other version.
  if (version == 1 || version == 2)
    throw InputError(source, "checkpoint: byte offset 8: format version " + std::to_string(version) + " carries no " +
                                 (version == 1 ? "stabilised-forgetting reference" : "joint information") +
                                 "; this build reads version " + std::to_string(kCheckpointVersion) +
                                 " only (the estimator starts afresh)");
  if (version != kCheckpointVersion)
    throw InputError(source, "checkpoint: byte offset 8: format version " + std::to_string(version) +
                                 ", this build reads version " + std::to_string(kCheckpointVersion));
  const std::uint64_t length = h.u64("payload length");
  if (length > kMaxCheckpointPayload)
    throw InputError(source, "checkpoint: byte offset 12: payload length " + std::to_string(length) +
                                 " exceeds the limit " + std::to_string(kMaxCheckpointPayload));
  if (h.left() < length + 4)
    throw InputError(source, "checkpoint: byte offset " + std::to_string(bytes.size()) + ": truncated (" +
                                 std::to_string(kHeaderSize + length + 4) + " bytes expected, " +
                                 std::to_string(bytes.size()) + " present)");
  if (h.left() > length + 4)
    throw InputError(source, "checkpoint: byte offset " + std::to_string(kHeaderSize + length + 4) + ": " +
                                 std::to_string(h.left() - length - 4) + " trailing bytes");
  const std::size_t end = kHeaderSize + static_cast<std::size_t>(length);
  std::uint32_t stored = 0;
  for (int i = 0; i < 4; ++i) stored |= static_cast<std::uint32_t>(bytes[end + i]) << (8 * i);
#ifndef FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION  // fuzzing: let mutations reach the payload parser
  if (crc32(bytes.first(end)) != stored)
    throw InputError(source,
                     "checkpoint: byte offset " + std::to_string(end) + ": CRC-32 mismatch (the file is corrupt)");
#else
  (void)stored;
#endif

  Reader r(bytes.subspan(kHeaderSize, static_cast<std::size_t>(length)), kHeaderSize, source);
  Checkpoint c;
  c.config_fingerprint = r.u64("config fingerprint");
  c.last_utime = r.i64("last utime");
  c.last_seq = r.i64("last sequence number");
  StateFromBytes state(r);
  c.estimator = EstimatorState::read(state);

  const std::uint32_t nb = r.count("baseline count", kMaxBaselines);
  for (std::uint32_t i = 0; i < nb; ++i) {
    if (r.flag("baseline present")) {
      ModeBaseline b;
      b.value.wn = r.f64("baseline wn");
      b.value.zeta = r.f64("baseline zeta");
      b.value.gain = r.f64("baseline gain");
      b.learned = r.flag("baseline learned");
      for (double& v : b.covariance) v = r.f64("baseline covariance");
      c.baselines.emplace_back(b);
    } else {
      c.baselines.emplace_back(std::nullopt);
    }
  }
  if (r.left() != 0) r.fail(std::to_string(r.left()) + " unread bytes at the end of the payload");
  return c;
}

void write_checkpoint(const std::string& path, const Checkpoint& c) {
  const std::vector<std::uint8_t> bytes = encode_checkpoint(c);
  write_file_atomically(path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()), 0640);
}

Checkpoint read_checkpoint(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, std::string("cannot open checkpoint: ") + std::strerror(errno));
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) throw InputError(path, "cannot read checkpoint");
  if (static_cast<std::uint64_t>(size) > kMaxCheckpointPayload + kHeaderSize + 4)
    throw InputError(path, "checkpoint: " + std::to_string(size) + " bytes, larger than any valid checkpoint");
  in.seekg(0);
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(size));
  if (size > 0 && !in.read(reinterpret_cast<char*>(bytes.data()), size))
    throw InputError(path, "cannot read checkpoint");
  return decode_checkpoint(bytes, path);
}

}  // namespace modalwatch
