// Allocator hook for plain builds on glibc: the program's own malloc family
// forwards to glibc's internal entry points after telling the guard. Being
// defined in the executable, these definitions take precedence over libc's
// for every caller, operator new included.
#include <cerrno>
#include <cstddef>
#include <cstdlib>

#include "trailnav/runtime/alloc_guard.hpp"

extern "C" {
void* __libc_malloc(std::size_t size);
void __libc_free(void* pointer);
void* __libc_calloc(std::size_t count, std::size_t size);
void* __libc_realloc(void* pointer, std::size_t size);
void* __libc_memalign(std::size_t alignment, std::size_t size);
}

namespace {
volatile bool g_seen_heap_operation = false;

inline void note() noexcept {
  g_seen_heap_operation = true;
  trailnav::alloc_guard::detail::on_heap_operation();
}
}  // namespace

extern "C" {

void* malloc(std::size_t size) noexcept {
  note();
  return __libc_malloc(size);
}

void free(void* pointer) noexcept {
  if (pointer == nullptr) return;
  note();
  __libc_free(pointer);
}

void* calloc(std::size_t count, std::size_t size) noexcept {
  note();
  return __libc_calloc(count, size);
}

void* realloc(void* pointer, std::size_t size) noexcept {
  note();
  return __libc_realloc(pointer, size);
}

void* memalign(std::size_t alignment, std::size_t size) noexcept {
  note();
  return __libc_memalign(alignment, size);
}

void* aligned_alloc(std::size_t alignment, std::size_t size) noexcept {
  note();
  return __libc_memalign(alignment, size);
}

int posix_memalign(void** out, std::size_t alignment, std::size_t size) noexcept {
  if (alignment < sizeof(void*) || (alignment & (alignment - 1)) != 0) return EINVAL;
  note();
  void* pointer = __libc_memalign(alignment, size);
  if (pointer == nullptr) return ENOMEM;
  *out = pointer;
  return 0;
}

}  // extern "C"

namespace trailnav::alloc_guard::detail {
// The interposed functions are active as soon as the program is loaded; a
// heap operation has certainly happened before anyone asks.
bool install_hook() noexcept {
  void* probe = std::malloc(1);
  std::free(probe);
  return g_seen_heap_operation;
}
}  // namespace trailnav::alloc_guard::detail
