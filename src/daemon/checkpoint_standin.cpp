// STAND-IN for the io branch's checkpoint (see checkpoint_standin.hpp): a small
// text file, parsed strictly.
#include "checkpoint_standin.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>

#include "modalwatch/error.hpp"

namespace modalwatch::standin {
namespace {

constexpr const char* kMagic = "modalwatch-checkpoint-standin 1";

struct Fnv {
  std::uint64_t h = 1469598103934665603ull;
  void bytes(const void* p, std::size_t n) {
    const auto* c = static_cast<const unsigned char*>(p);
    for (std::size_t i = 0; i < n; ++i) h = (h ^ c[i]) * 1099511628211ull;
  }
  void number(double v) { bytes(&v, sizeof v); }
  void integer(std::int64_t v) { bytes(&v, sizeof v); }
  void text(const std::string& s) {
    integer(static_cast<std::int64_t>(s.size()));
    bytes(s.data(), s.size());
  }
};

[[noreturn]] void fail_errno(const std::string& what) {
  throw std::system_error(errno, std::generic_category(), what);
}

void write_all(int fd, const std::string& data, const std::string& what) {
  const char* p = data.data();
  std::size_t left = data.size();
  while (left > 0) {
    const ssize_t n = ::write(fd, p, left);
    if (n < 0) {
      if (errno == EINTR) continue;
      fail_errno(what);
    }
    p += n;
    left -= static_cast<std::size_t>(n);
  }
}

}  // namespace

std::uint64_t checkpoint_fingerprint(const Config& config) {
  Fnv f;
  f.number(config.sample_time);
  f.integer(config.closed_loop ? 1 : 0);
  for (const double c : config.controller.numerator()) f.number(c);
  f.integer(-1);
  for (const double c : config.controller.denominator()) f.number(c);
  f.integer(-2);
  for (const auto& s : config.model.submodels) {
    f.text(s.name);
    f.integer(s.n);
    f.integer(s.m);
    f.integer(s.rigid_poles);
  }
  for (const auto& s : config.submodel_settings) f.number(s.forgetting);
  return f.h;
}

void write_checkpoint(const std::string& path, const Checkpoint& c) {
  std::ostringstream out;
  out.precision(17);
  out << kMagic << "\nfingerprint " << c.config_fingerprint << "\nlast_utime " << c.last_utime << "\nlast_seq "
      << c.last_seq << "\nsubmodels " << c.submodels.size() << "\n";
  for (std::size_t i = 0; i < c.submodels.size(); ++i) {
    const auto& p = c.submodels[i];
    out << p.wn << ' ' << p.zeta << ' ' << p.gain;
    const auto& b = i < c.baselines.size() ? c.baselines[i] : std::nullopt;
    if (b)
      out << " 1 " << b->wn << ' ' << b->zeta << ' ' << b->gain << '\n';
    else
      out << " 0 0 0 0\n";
  }
  out << "end\n";
  const std::filesystem::path target(path);
  const std::filesystem::path dir = target.has_parent_path() ? target.parent_path() : ".";
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) fail_errno("cannot create " + tmp);
  try {
    write_all(fd, out.str(), "cannot write " + tmp);
    if (::fsync(fd) != 0) fail_errno("cannot fsync " + tmp);
  } catch (...) {
    ::close(fd);
    ::unlink(tmp.c_str());
    throw;
  }
  if (::close(fd) != 0) {
    const int e = errno;
    ::unlink(tmp.c_str());
    errno = e;
    fail_errno("cannot close " + tmp);
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const int e = errno;
    ::unlink(tmp.c_str());
    errno = e;
    fail_errno("cannot rename " + tmp + " to " + path);
  }
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
}

Checkpoint read_checkpoint(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path, std::string("cannot open checkpoint: ") + std::strerror(errno));
  const auto bad = [&](const std::string& what) -> InputError { return InputError(path, "bad checkpoint: " + what); };
  std::string line;
  if (!std::getline(in, line) || line != kMagic) throw bad("not a modalwatch checkpoint");
  Checkpoint c;
  std::string key;
  std::size_t n = 0;
  if (!(in >> key >> c.config_fingerprint) || key != "fingerprint") throw bad("fingerprint");
  if (!(in >> key >> c.last_utime) || key != "last_utime") throw bad("last_utime");
  if (!(in >> key >> c.last_seq) || key != "last_seq") throw bad("last_seq");
  if (!(in >> key >> n) || key != "submodels" || n > 64) throw bad("submodels");
  for (std::size_t i = 0; i < n; ++i) {
    ModalParameters p, b;
    int has = 0;
    if (!(in >> p.wn >> p.zeta >> p.gain >> has >> b.wn >> b.zeta >> b.gain)) throw bad("submodel " + std::to_string(i));
    if (!std::isfinite(p.wn) || !std::isfinite(p.zeta) || !std::isfinite(p.gain) || !std::isfinite(b.wn) ||
        !std::isfinite(b.zeta) || !std::isfinite(b.gain))
      throw bad("non-finite value in submodel " + std::to_string(i));
    c.submodels.push_back(p);
    c.baselines.push_back(has ? std::optional<ModalParameters>(b) : std::nullopt);
  }
  if (!(in >> key) || key != "end") throw bad("truncated");
  return c;
}

}  // namespace modalwatch::standin
