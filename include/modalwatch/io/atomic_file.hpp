#pragma once
// The one way modalwatch replaces a file: written to a temporary file in the
// same directory, fsync'd, renamed over the target, and the directory fsync'd,
// so that a reader (or the next start after a power cut) sees the old file or
// the new one whole, never a torn one.
#include <sys/types.h>

#include <cstddef>
#include <string>
#include <string_view>

namespace modalwatch {

// Streaming form, for outputs too large to hold (track's est.csv). Errors throw
// std::system_error carrying errno (ENOSPC, EACCES, ...) with a message that
// names the file; the target is left as it was.
class AtomicFile {
 public:
  explicit AtomicFile(std::string path, mode_t mode = 0644);
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  ~AtomicFile();  // without commit(): the temporary is removed

  void write(const void* data, std::size_t size);
  void write(std::string_view text) { write(text.data(), text.size()); }
  // Makes the new contents the file's; call once.
  void commit();

  const std::string& path() const { return path_; }

 private:
  [[noreturn]] void fail(const std::string& what, int err);

  std::string path_, tmp_;
  mode_t mode_;
  int fd_ = -1;
  bool committed_ = false;
};

// The whole contents at once.
void write_file_atomically(const std::string& path, std::string_view contents, mode_t mode = 0644);

}  // namespace modalwatch
