// Heap-allocation counting for the zero-allocation tests (test_allocation,
// test_daemon_allocation): linked into those test binaries only.
//
// Replaces the global operator new/delete (every variant) with counting versions
// and, outside sanitizer builds, interposes the C allocator (malloc, calloc,
// realloc, aligned allocations, free), since Eigen's dynamic matrices allocate
// with std::malloc and never through operator new. Counting is per thread and
// only between AllocationCounter::start() and stop(), so other threads (the
// daemon's subscriber and publisher) may allocate. The first counted
// allocation's backtrace is recorded (execinfo backtrace() into a static buffer,
// no allocation) and symbolised with addr2line after counting has stopped, so a
// failure says what allocated.
#include "allocation_counter.hpp"

#include <dlfcn.h>
#include <execinfo.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <new>
#include <sstream>
#include <string>

// ---------------------------------------------------------------------------
// Counting
namespace {

constexpr int kMaxFrames = 64;
// Plain thread-locals with constant initialisation: static TLS, no lazy
// construction, safe inside malloc.
thread_local bool t_counting = false;
thread_local bool t_in_hook = false;
thread_local modalwatch::test_support::AllocationCounts t_counts;
thread_local void* t_frames[kMaxFrames];
thread_local int t_frame_count = 0;
thread_local const char* t_first_kind = nullptr;
thread_local std::size_t t_first_size = 0;

void note_allocation(const char* kind, std::size_t size) {
  if (!t_counting || t_in_hook) return;
  ++t_counts.allocations;
  if (t_frame_count == 0) {
    t_in_hook = true;
    t_frame_count = backtrace(t_frames, kMaxFrames);
    t_first_kind = kind;
    t_first_size = size;
    t_in_hook = false;
  }
}

void note_deallocation(const void* p) {
  if (p && t_counting && !t_in_hook) ++t_counts.deallocations;
}

}  // namespace

#if MODALWATCH_INTERPOSE_MALLOC
// glibc's documented way to replace the allocator: define these in the
// executable; the real implementation stays reachable as __libc_*.
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);
void __libc_free(void*);

void* malloc(std::size_t size) noexcept {
  note_allocation("malloc", size);
  return __libc_malloc(size);
}
void* calloc(std::size_t n, std::size_t size) noexcept {
  note_allocation("calloc", n * size);
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t size) noexcept {
  note_allocation("realloc", size);
  return __libc_realloc(p, size);
}
void free(void* p) noexcept {
  note_deallocation(p);
  __libc_free(p);
}
void* memalign(std::size_t alignment, std::size_t size) noexcept {
  note_allocation("memalign", size);
  return __libc_memalign(alignment, size);
}
void* aligned_alloc(std::size_t alignment, std::size_t size) noexcept {
  note_allocation("aligned_alloc", size);
  return __libc_memalign(alignment, size);
}
int posix_memalign(void** out, std::size_t alignment, std::size_t size) noexcept {
  if (alignment < sizeof(void*) || (alignment & (alignment - 1)) != 0) return 22;  // EINVAL
  note_allocation("posix_memalign", size);
  void* p = __libc_memalign(alignment, size);
  if (!p) return 12;  // ENOMEM
  *out = p;
  return 0;
}
void* valloc(std::size_t size) noexcept {
  note_allocation("valloc", size);
  return __libc_memalign(static_cast<std::size_t>(sysconf(_SC_PAGESIZE)), size);
}
void* pvalloc(std::size_t size) noexcept {
  note_allocation("pvalloc", size);
  const auto page = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
  return __libc_memalign(page, (size + page - 1) / page * page);
}
}  // extern "C"
#define RAW_MALLOC __libc_malloc
#define RAW_FREE __libc_free
#define RAW_MEMALIGN __libc_memalign
#else
// Out of line, so that GCC does not see operator new's memory reach free()
// (-Wmismatched-new-delete): here operator new is malloc by definition.
[[gnu::noinline]] void raw_free(void* p) noexcept { std::free(p); }
#define RAW_MALLOC std::malloc
#define RAW_FREE raw_free
#define RAW_MEMALIGN(a, s) std::aligned_alloc((a), ((s) + (a)-1) / (a) * (a))
#endif

namespace {

void* counted_new(std::size_t size, const char* kind) {
  note_allocation(kind, size);
  return RAW_MALLOC(size == 0 ? 1 : size);
}
void* counted_new_aligned(std::size_t size, std::align_val_t al, const char* kind) {
  note_allocation(kind, size);
  const auto a = static_cast<std::size_t>(al);
  return RAW_MEMALIGN(a < sizeof(void*) ? sizeof(void*) : a, size == 0 ? a : size);
}
void counted_delete(void* p) {
  note_deallocation(p);
  RAW_FREE(p);
}

}  // namespace

void* operator new(std::size_t n) {
  if (void* p = counted_new(n, "operator new")) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) {
  if (void* p = counted_new(n, "operator new[]")) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept { return counted_new(n, "operator new(nothrow)"); }
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  return counted_new(n, "operator new[](nothrow)");
}
void* operator new(std::size_t n, std::align_val_t a) {
  if (void* p = counted_new_aligned(n, a, "operator new(aligned)")) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n, std::align_val_t a) {
  if (void* p = counted_new_aligned(n, a, "operator new[](aligned)")) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
  return counted_new_aligned(n, a, "operator new(aligned, nothrow)");
}
void* operator new[](std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
  return counted_new_aligned(n, a, "operator new[](aligned, nothrow)");
}
void operator delete(void* p) noexcept { counted_delete(p); }
void operator delete[](void* p) noexcept { counted_delete(p); }
void operator delete(void* p, std::size_t) noexcept { counted_delete(p); }
void operator delete[](void* p, std::size_t) noexcept { counted_delete(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { counted_delete(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { counted_delete(p); }
void operator delete(void* p, std::align_val_t) noexcept { counted_delete(p); }
void operator delete[](void* p, std::align_val_t) noexcept { counted_delete(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { counted_delete(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { counted_delete(p); }
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept { counted_delete(p); }
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept { counted_delete(p); }

namespace modalwatch::test_support {

void AllocationCounter::start() {
  // backtrace() loads libgcc's unwinder on first use (which allocates): do that now.
  void* warm[4];
  backtrace(warm, 4);
  t_counts = {};
  t_frame_count = 0;
  t_first_kind = nullptr;
  t_counting = true;
}

AllocationCounts AllocationCounter::stop() {
  t_counting = false;
  return t_counts;
}

// The first counted allocation, symbolised (call after Counting::stop()).
std::string first_allocation_trace() {
  if (t_frame_count == 0) return "";
  std::ostringstream out;
  out << "first allocation: " << t_first_kind << " of " << t_first_size << " bytes, at\n";
  for (int i = 0; i < t_frame_count; ++i) {
    Dl_info info{};
    std::string where;
    if (dladdr(t_frames[i], &info) && info.dli_fname) {
      Dl_info self{};
      dladdr(reinterpret_cast<void*>(&first_allocation_trace), &self);
      std::string file = info.dli_fname;
      if (info.dli_fbase == self.dli_fbase) {  // this executable: dli_fname is argv[0]
        char exe[4096];
        const ssize_t len = readlink("/proc/self/exe", exe, sizeof exe - 1);
        if (len > 0) file.assign(exe, static_cast<std::size_t>(len));
      }
      // Return addresses point after the call: look up the byte before.
      const auto offset =
          static_cast<std::uintptr_t>(static_cast<char*>(t_frames[i]) - static_cast<char*>(info.dli_fbase)) - 1;
      char cmd[4096];
      std::snprintf(cmd, sizeof cmd, "addr2line -C -f -i -p -e '%s' 0x%zx 2>/dev/null", file.c_str(),
                    static_cast<std::size_t>(offset));
      if (FILE* p = popen(cmd, "r")) {
        char line[2048];
        while (std::fgets(line, sizeof line, p)) where += line;
        pclose(p);
      }
      if (where.empty() || where.rfind("??", 0) == 0) {
        char raw[64];
        std::snprintf(raw, sizeof raw, "+0x%zx ", static_cast<std::size_t>(offset));
        where = file + raw + (info.dli_sname ? info.dli_sname : "") + "\n";
      }
    }
    out << "  #" << i << " " << (where.empty() ? "?\n" : where);
  }
  // And the raw frames, as glibc prints them.
  std::fflush(stderr);
  backtrace_symbols_fd(t_frames, t_frame_count, 2);
  return out.str();
}

}  // namespace modalwatch::test_support
