// Allocation guard: proves that real-time threads do not touch the heap.
//
// Start-up allocates everything. Each real-time thread then calls
// mark_realtime_thread() with its name, and arm() switches the guard on: from
// then on every malloc, calloc, realloc, aligned allocation, new, free or
// delete on a marked thread is counted against that thread's name (and, when
// fatal mode is set, aborts the process with the name on stderr). Other
// threads (loggers, publishers, tools) are never counted.
//
// The hook into the allocator is chosen by CMake: in plain builds the project
// interposes malloc and friends over glibc; in sanitizer builds it registers
// the sanitizer's own allocation hooks.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

namespace trailnav::alloc_guard {

inline constexpr std::size_t kMaxThreadNames = 128;
inline constexpr std::size_t kThreadNameLength = 32;

struct ThreadAllocations {
  char name[kThreadNameLength] = {};
  std::uint64_t allocations = 0;
};

// Marks the calling thread as real-time under `name` (truncated to 31
// characters). Threads that share a name share one counter.
void mark_realtime_thread(const char* name) noexcept;
// The calling thread is no longer counted.
void unmark_current_thread() noexcept;
bool current_thread_is_realtime() noexcept;

// Switches counting on for all marked threads. Returns false if the allocator
// hook is not in place, in which case allocations cannot be seen.
bool arm() noexcept;
void disarm() noexcept;
bool armed() noexcept;

// When fatal, the first counted allocation aborts with the thread's name.
void set_fatal(bool fatal) noexcept;

// Heap operations counted on armed real-time threads since the last reset.
std::uint64_t total_allocations() noexcept;
// Counts per thread name, for names with at least one allocation; returns how
// many entries were written.
std::size_t report(std::span<ThreadAllocations> out) noexcept;
// Zeroes every counter (names stay registered).
void reset_counters() noexcept;

// True when this build's allocator hook is installed and sees allocations.
bool hook_installed() noexcept;

namespace detail {
// Called by the allocator hook for every heap operation.
void on_heap_operation() noexcept;
// Implemented by the platform hook file selected by CMake.
bool install_hook() noexcept;
}  // namespace detail

}  // namespace trailnav::alloc_guard
