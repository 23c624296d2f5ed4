// A fixed block of memory handed out first fit, with neighbouring free
// blocks merged on release: the storage of one solver, sized from the
// configuration at start-up. When it is full an allocation fails (nullptr)
// and the caller reports it; it never grows. Counts what is in use and its
// high-water mark, so the memory a solve took is measured, not estimated.
// Not thread-safe: one arena per user (a solver, a decoder), used by one
// thread at a time. The pose-graph solver's (navigation/slam) and the
// camera's MJPEG decoder's (drivers/camera/frame.hpp) memory.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <memory_resource>
#include <new>

namespace trailnav {

class Arena {
 public:
  explicit Arena(std::size_t bytes);
  Arena(const Arena&) = delete;
  Arena& operator=(const Arena&) = delete;

  void* allocate(std::size_t bytes) noexcept;  // 16-byte aligned; nullptr when no free block is large enough
  void* reallocate(void* p, std::size_t bytes) noexcept;  // as realloc; p kept when it fails
  void release(void* p) noexcept;
  bool owns(const void* p) const noexcept;
  std::size_t usable_size(const void* p) const noexcept;  // bytes p may hold (p owned)

  std::size_t capacity() const noexcept { return capacity_; }
  std::size_t in_use() const noexcept { return in_use_; }        // bytes of blocks handed out (headers included)
  std::size_t high_water() const noexcept { return high_water_; }
  std::uint64_t failures() const noexcept { return failures_; }  // allocations refused
  void reset_high_water() noexcept { high_water_ = in_use_; }

 private:
  struct Header;
  Header* first() const noexcept;
  Header* next(Header* h) const noexcept;
  Header* previous(Header* h) const noexcept;
  void split(Header* h, std::size_t size) noexcept;

  std::unique_ptr<std::byte[]> storage_;
  std::byte* base_ = nullptr;
  std::size_t capacity_ = 0;
  std::size_t in_use_ = 0;
  std::size_t high_water_ = 0;
  std::uint64_t failures_ = 0;
};

// The arena as a standard memory resource, for std::pmr containers: an
// allocation it cannot serve throws std::bad_alloc (the solver turns it into
// an error naming the arena); alignment up to 16 bytes.
class ArenaResource final : public std::pmr::memory_resource {
 public:
  explicit ArenaResource(Arena& arena) noexcept : arena_(arena) {}

 private:
  void* do_allocate(std::size_t bytes, std::size_t alignment) override {
    void* p = alignment <= 16 ? arena_.allocate(bytes) : nullptr;
    if (p == nullptr) throw std::bad_alloc();
    return p;
  }
  void do_deallocate(void* p, std::size_t, std::size_t) override { arena_.release(p); }
  bool do_is_equal(const std::pmr::memory_resource& other) const noexcept override { return this == &other; }
  Arena& arena_;
};

}  // namespace trailnav
