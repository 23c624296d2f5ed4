#include "trailnav/runtime/alloc_guard.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace trailnav {
namespace {

class AllocGuardTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(alloc_guard::hook_installed()) << "the allocator hook must be active in every build";
    alloc_guard::set_fatal(false);
    alloc_guard::reset_counters();
  }
  void TearDown() override {
    alloc_guard::disarm();
    alloc_guard::reset_counters();
  }

  static std::uint64_t count_for(const char* name) {
    std::array<alloc_guard::ThreadAllocations, alloc_guard::kMaxThreadNames> rows{};
    const std::size_t n = alloc_guard::report(rows);
    for (std::size_t i = 0; i < n; ++i) {
      if (std::strcmp(rows[i].name, name) == 0) return rows[i].allocations;
    }
    return 0;
  }
};

// Keeps the compiler from eliding a new/delete pair.
void* volatile g_sink = nullptr;

TEST_F(AllocGuardTest, CatchesDeliberateAllocationsOnAnArmedRealtimeThread) {
  std::thread rt([] {
    alloc_guard::mark_realtime_thread("deliberate");
    alloc_guard::arm();
    auto* p = new int(42);  // new + delete: two heap operations
    g_sink = p;
    delete p;
    void* m = std::malloc(64);  // malloc + realloc + free: three more
    g_sink = m;
    m = std::realloc(m, 4096);
    g_sink = m;
    std::free(m);
    alloc_guard::disarm();
    alloc_guard::unmark_current_thread();
  });
  rt.join();
  EXPECT_GE(count_for("deliberate"), 5u);
  EXPECT_GE(alloc_guard::total_allocations(), 5u);
}

TEST_F(AllocGuardTest, CatchesContainerGrowth) {
  std::thread rt([] {
    std::vector<int> v;
    alloc_guard::mark_realtime_thread("growing");
    alloc_guard::arm();
    for (int i = 0; i < 100; ++i) v.push_back(i);
    alloc_guard::disarm();
    alloc_guard::unmark_current_thread();
  });
  rt.join();
  EXPECT_GT(count_for("growing"), 0u);
}

TEST_F(AllocGuardTest, IgnoresUnmarkedThreadsAndDisarmedTimes) {
  alloc_guard::arm();
  std::thread other([] {
    auto s = std::make_unique<std::string>(1000, 'x');  // unmarked thread
    g_sink = s.get();
  });
  other.join();
  alloc_guard::disarm();
  std::thread rt([] {
    alloc_guard::mark_realtime_thread("disarmed");
    auto s = std::make_unique<std::string>(1000, 'x');  // marked, but not armed
    g_sink = s.get();
    alloc_guard::unmark_current_thread();
  });
  rt.join();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
  EXPECT_EQ(count_for("disarmed"), 0u);
}

TEST_F(AllocGuardTest, ThreadsOfOneNameShareACounter) {
  for (int i = 0; i < 3; ++i) {
    std::thread rt([] {
      alloc_guard::mark_realtime_thread("shared-name");
      alloc_guard::arm();
      void* m = std::malloc(8);
      g_sink = m;
      alloc_guard::disarm();
      alloc_guard::unmark_current_thread();
      std::free(m);
    });
    rt.join();
  }
  EXPECT_EQ(count_for("shared-name"), 3u);
}

using AllocGuardDeathTest = AllocGuardTest;

TEST_F(AllocGuardDeathTest, FatalModeAbortsNamingTheThread) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_DEATH(
      {
        alloc_guard::set_fatal(true);
        alloc_guard::mark_realtime_thread("fatal-thread");
        alloc_guard::arm();
        g_sink = std::malloc(16);
      },
      "heap allocation on armed real-time thread 'fatal-thread'");
}

}  // namespace
}  // namespace trailnav
