// Allocator hook for plain builds on glibc: the program's own malloc family
// forwards to glibc's internal entry points after telling the guard. Being
// defined in the executable, these definitions take precedence over libc's
// for every caller, operator new included.
#include <cerrno>
#include <cstddef>
#include <cstdlib>
#include <cstring>

#include "trailnav/runtime/alloc_guard.hpp"
#include "trailnav/runtime/heap_redirect.hpp"

extern "C" {
void* __libc_malloc(std::size_t size);
void __libc_free(void* pointer);
void* __libc_calloc(std::size_t count, std::size_t size);
void* __libc_realloc(void* pointer, std::size_t size);
void* __libc_memalign(std::size_t alignment, std::size_t size);
std::size_t malloc_usable_size(void* pointer) noexcept;
}

namespace {
volatile bool g_seen_heap_operation = false;

inline void note() noexcept {
  g_seen_heap_operation = true;
  trailnav::alloc_guard::detail::on_heap_operation();
}

// The calling thread's heap redirect (heap_redirect.hpp); initial-exec TLS,
// so reading it never allocates.
__attribute__((tls_model("initial-exec"))) thread_local trailnav::heap_redirect::Redirect* t_redirect = nullptr;
}  // namespace

namespace trailnav::heap_redirect::detail {
bool exchange(Redirect* redirect, Redirect** previous) noexcept {
  *previous = t_redirect;
  t_redirect = redirect;
  return true;
}
}  // namespace trailnav::heap_redirect::detail

extern "C" {

void* malloc(std::size_t size) noexcept {
  if (auto* r = t_redirect) return r->allocate(size);
  note();
  return __libc_malloc(size);
}

void free(void* pointer) noexcept {
  if (pointer == nullptr) return;
  if (auto* r = t_redirect; r != nullptr && r->owns(pointer)) {
    r->release(pointer);
    return;
  }
  note();
  __libc_free(pointer);
}

void* calloc(std::size_t count, std::size_t size) noexcept {
  if (auto* r = t_redirect) {
    if (size != 0 && count > static_cast<std::size_t>(-1) / size) return nullptr;
    void* p = r->allocate(count * size);
    if (p != nullptr) std::memset(p, 0, count * size);
    return p;
  }
  note();
  return __libc_calloc(count, size);
}

void* realloc(void* pointer, std::size_t size) noexcept {
  if (auto* r = t_redirect) {
    if (pointer == nullptr) return r->allocate(size);
    if (r->owns(pointer)) return r->reallocate(pointer, size);
    // A heap block from before the scope moves into the redirect.
    void* p = r->allocate(size);
    if (p == nullptr) return nullptr;
    const std::size_t old = malloc_usable_size(pointer);
    std::memcpy(p, pointer, old < size ? old : size);
    note();
    __libc_free(pointer);
    return p;
  }
  note();
  return __libc_realloc(pointer, size);
}

void* memalign(std::size_t alignment, std::size_t size) noexcept {
  if (auto* r = t_redirect; r != nullptr && alignment <= 16) return r->allocate(size);
  note();
  return __libc_memalign(alignment, size);
}

void* aligned_alloc(std::size_t alignment, std::size_t size) noexcept {
  if (auto* r = t_redirect; r != nullptr && alignment <= 16) return r->allocate(size);
  note();
  return __libc_memalign(alignment, size);
}

int posix_memalign(void** out, std::size_t alignment, std::size_t size) noexcept {
  if (alignment < sizeof(void*) || (alignment & (alignment - 1)) != 0) return EINVAL;
  void* pointer = nullptr;
  if (auto* r = t_redirect; r != nullptr && alignment <= 16) {
    pointer = r->allocate(size);
  } else {
    note();
    pointer = __libc_memalign(alignment, size);
  }
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
