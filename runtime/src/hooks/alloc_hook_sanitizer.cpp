// Allocator hook for AddressSanitizer and ThreadSanitizer builds: the
// sanitizers own malloc, so the guard registers their allocation hooks
// instead of interposing the allocator.
#include <cstddef>

#include "trailnav/runtime/alloc_guard.hpp"

extern "C" int __sanitizer_install_malloc_and_free_hooks(
    void (*malloc_hook)(const volatile void*, std::size_t), void (*free_hook)(const volatile void*));

namespace {
void on_malloc(const volatile void*, std::size_t) { trailnav::alloc_guard::detail::on_heap_operation(); }
void on_free(const volatile void* pointer) {
  if (pointer != nullptr) trailnav::alloc_guard::detail::on_heap_operation();
}
}  // namespace

namespace trailnav::alloc_guard::detail {
bool install_hook() noexcept {
  static const bool installed = __sanitizer_install_malloc_and_free_hooks(&on_malloc, &on_free) != 0;
  return installed;
}
}  // namespace trailnav::alloc_guard::detail
