#pragma once
// Per-thread heap-allocation counting (tests/allocation_counter.cpp replaces the
// global allocator in the test binaries that link it).
#include <cstdint>
#include <string>

// The sanitizers own malloc: there only operator new/delete are counted.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__) || defined(__SANITIZE_MEMORY__)
#define MODALWATCH_INTERPOSE_MALLOC 0
#else
#define MODALWATCH_INTERPOSE_MALLOC 1
#endif

namespace modalwatch::test_support {

struct AllocationCounts {
  std::uint64_t allocations = 0;    // operator new, malloc, calloc, realloc, aligned allocations
  std::uint64_t deallocations = 0;  // operator delete, free (of a non-null pointer)
};

// Counts the calling thread's allocations between start() and stop().
class AllocationCounter {
 public:
  static void start();
  static AllocationCounts stop();
};

// The calling thread's first counted allocation, symbolised; empty when there was
// none. Call after stop(): it allocates.
std::string first_allocation_trace();

}  // namespace modalwatch::test_support
