// Cache-line prefetch hints for the per-point loops that scatter into
// megabyte grids (the obstacle map, the terrain grid): they find a batch of
// points' cells first, ask for them, and update the batch after.
#pragma once

namespace trailnav {

// Asks for the cache line holding *p ahead of a write (or a read). A hint:
// no effect where the compiler has no such builtin.
inline void prefetch_for_write(const void* p) noexcept {
#if defined(__GNUC__)
  __builtin_prefetch(p, 1);
#else
  (void)p;
#endif
}

inline void prefetch_for_read(const void* p) noexcept {
#if defined(__GNUC__)
  __builtin_prefetch(p, 0);
#else
  (void)p;
#endif
}

}  // namespace trailnav
