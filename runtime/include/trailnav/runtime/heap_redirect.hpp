// Heap redirect: the malloc family of one thread served, for a while, from a
// block of memory its owner sized at start-up.
//
// Our own code takes its memory from arenas and fixed containers; a library
// that calls malloc itself (METIS' partitioner, for one) cannot be given an
// allocator. While a ScopedHeapRedirect is alive on a thread, every malloc,
// calloc, realloc and aligned allocation of 16 bytes or less alignment on
// that thread is served by the redirect instead of the heap, and freeing a
// block the redirect owns hands it back; nothing else is touched, and the
// allocation guard does not see these operations (they are not heap
// operations). An allocation the redirect cannot serve returns nullptr, as
// malloc does when memory is exhausted: the library reports it.
//
// The code inside the scope must free what it allocated before the scope
// ends (METIS does, on success and on error), on the same thread, and must
// not start threads (a new thread's state, allocated here, would be freed
// there, on the heap).
//
// Plain builds on glibc support it (the project's own malloc); sanitizer
// builds own malloc themselves, so there the scope does nothing and
// heap_redirect_supported() is false.
#pragma once

#include <cstddef>

#include "trailnav/runtime/arena.hpp"

namespace trailnav::heap_redirect {

class Redirect {
 public:
  virtual void* allocate(std::size_t bytes) noexcept = 0;  // 16-byte aligned, or nullptr
  virtual void* reallocate(void* p, std::size_t bytes) noexcept = 0;  // p owned; nullptr keeps p
  virtual void release(void* p) noexcept = 0;                // p owned
  virtual bool owns(const void* p) const noexcept = 0;
  virtual std::size_t usable_size(const void* p) const noexcept = 0;  // p owned

 protected:
  ~Redirect() = default;
};

// A redirect served from an Arena (runtime/arena.hpp: first fit, freed
// blocks merged, its high-water mark the most a scope took).
class ArenaRedirect final : public Redirect {
 public:
  explicit ArenaRedirect(Arena& arena) noexcept : arena_(arena) {}
  void* allocate(std::size_t bytes) noexcept override { return arena_.allocate(bytes); }
  void* reallocate(void* p, std::size_t bytes) noexcept override { return arena_.reallocate(p, bytes); }
  void release(void* p) noexcept override { arena_.release(p); }
  bool owns(const void* p) const noexcept override { return arena_.owns(p); }
  std::size_t usable_size(const void* p) const noexcept override { return arena_.usable_size(p); }

 private:
  Arena& arena_;
};

bool supported() noexcept;

// Installs `redirect` for the calling thread; the destructor puts back what
// was installed before (scopes nest).
class Scope {
 public:
  explicit Scope(Redirect& redirect) noexcept;
  ~Scope();
  Scope(const Scope&) = delete;
  Scope& operator=(const Scope&) = delete;
  bool active() const noexcept { return active_; }

 private:
  Redirect* previous_ = nullptr;
  bool active_ = false;
};

namespace detail {
// Implemented by the allocator hook CMake selects: sets the calling thread's
// redirect, returns the one it replaces; false when unsupported.
bool exchange(Redirect* redirect, Redirect** previous) noexcept;
}  // namespace detail

}  // namespace trailnav::heap_redirect
