// The heap redirect serves one thread's malloc family from the caller's
// block while a scope lives, and nothing else.
#include "trailnav/runtime/heap_redirect.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <thread>

#include "trailnav/runtime/alloc_guard.hpp"

namespace trailnav {
namespace {

// A bump allocator over a static block: enough to see which calls it served.
class Bump final : public heap_redirect::Redirect {
 public:
  void* allocate(std::size_t bytes) noexcept override {
    const std::size_t need = (bytes + 15u + 16u) & ~std::size_t{15};  // 16 bytes of size in front
    if (used_ + need > sizeof(block_)) return nullptr;
    unsigned char* p = block_ + used_;
    used_ += need;
    std::memcpy(p, &bytes, sizeof bytes);
    ++allocations;
    return p + 16;
  }
  void* reallocate(void* p, std::size_t bytes) noexcept override {
    void* q = allocate(bytes);
    if (q == nullptr) return nullptr;
    const std::size_t old = usable_size(p);
    std::memcpy(q, p, old < bytes ? old : bytes);
    release(p);
    return q;
  }
  void release(void*) noexcept override { ++releases; }
  bool owns(const void* p) const noexcept override {
    const auto* b = static_cast<const unsigned char*>(p);
    return b >= block_ && b < block_ + sizeof(block_);
  }
  std::size_t usable_size(const void* p) const noexcept override {
    std::size_t n = 0;
    std::memcpy(&n, static_cast<const unsigned char*>(p) - 16, sizeof n);
    return n;
  }
  int allocations = 0, releases = 0;

 private:
  alignas(16) unsigned char block_[1 << 16] = {};
  std::size_t used_ = 0;
};

void* volatile g_sink = nullptr;

TEST(HeapRedirect, ServesTheScopedThreadOnlyAndOnlyWhileTheScopeLives) {
  if (!heap_redirect::supported()) GTEST_SKIP() << "this build's malloc is the sanitizer's: no redirect";
  static Bump bump;
  void* before = std::malloc(32);  // from the heap, freed inside the scope
  ASSERT_FALSE(bump.owns(before));
  // Another thread, started before the scope (creating a thread allocates
  // its state, which the new thread frees: blocks must not cross threads),
  // allocates while the scope lives.
  std::atomic<int> stage{0};
  void* other = nullptr;
  std::thread t([&] {
    while (stage.load() == 0) std::this_thread::yield();
    other = std::malloc(16);
    stage.store(2);
  });
  // Inside the scope nothing but the calls under test may allocate (a
  // gtest assertion would, and free it later on the heap): results are
  // noted and checked after.
  bool active = false, a_owned = false, c_owned = false, c_zero = true, aligned = false, b_owned = false,
       b_kept = false, moved_owned = false, moved_kept = false, other_owned = true;
  int allocations = 0, releases = 0;
  {
    heap_redirect::Scope scope(bump);
    active = scope.active();
    void* a = std::malloc(100);
    auto* c = static_cast<unsigned char*>(std::calloc(10, 8));
    a_owned = bump.owns(a);
    c_owned = bump.owns(c);
    for (int i = 0; i < 80; ++i) c_zero = c_zero && c[i] == 0;
    aligned = reinterpret_cast<std::uintptr_t>(a) % 16 == 0;
    std::memset(a, 7, 100);
    void* b = std::realloc(a, 300);  // owned: moved within the block, contents kept
    b_owned = bump.owns(b);
    b_kept = static_cast<unsigned char*>(b)[99] == 7;
    std::memset(before, 9, 32);
    void* moved = std::realloc(before, 64);  // a heap block moves into the redirect
    moved_owned = bump.owns(moved);
    moved_kept = static_cast<unsigned char*>(moved)[31] == 9;
    stage.store(1);
    while (stage.load() != 2) std::this_thread::yield();
    other_owned = bump.owns(other);  // the other thread is not redirected
    std::free(other);                // a heap block freed inside the scope goes to the heap
    std::free(b);
    std::free(c);
    std::free(moved);
    allocations = bump.allocations;  // malloc, calloc, two reallocs
    releases = bump.releases;        // a (by realloc), b, c, moved
  }
  EXPECT_TRUE(active);
  EXPECT_TRUE(a_owned);
  EXPECT_TRUE(c_owned);
  EXPECT_TRUE(c_zero);
  EXPECT_TRUE(aligned);
  EXPECT_TRUE(b_owned);
  EXPECT_TRUE(b_kept);
  EXPECT_TRUE(moved_owned);
  EXPECT_TRUE(moved_kept);
  EXPECT_FALSE(other_owned);
  EXPECT_EQ(allocations, 4);
  EXPECT_EQ(releases, 4);
  t.join();
  void* after = std::malloc(16);
  EXPECT_FALSE(bump.owns(after));
  g_sink = after;
  std::free(after);
}

// Redirected operations are not heap operations: the allocation guard, armed
// on a real-time thread, counts none of them.
TEST(HeapRedirect, RedirectedAllocationsAreNotCountedByTheGuard) {
  if (!heap_redirect::supported()) GTEST_SKIP() << "this build's malloc is the sanitizer's: no redirect";
  static Bump bump;
  alloc_guard::reset_counters();
  std::thread rt([] {  // the scope lives and ends on this thread
    alloc_guard::mark_realtime_thread("redirected");
    alloc_guard::arm();
    {
      heap_redirect::Scope scope(bump);
      void* p = std::malloc(64);
      g_sink = p;
      std::free(p);
    }
    alloc_guard::disarm();
    alloc_guard::unmark_current_thread();
  });
  rt.join();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
  EXPECT_EQ(bump.allocations, 1);
}

}  // namespace
}  // namespace trailnav
