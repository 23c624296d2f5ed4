#include "trailnav/runtime/clock.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <thread>

namespace trailnav {
namespace {

TEST(MonotonicClock, SleepsToAnAbsoluteDeadline) {
  MonotonicClock clock;
  const Nanos deadline = clock.now() + 20 * kNanosPerMilli;
  EXPECT_TRUE(clock.sleep_until(deadline));
  EXPECT_GE(clock.now(), deadline);
  // A deadline in the past returns at once.
  const Nanos before = clock.now();
  EXPECT_TRUE(clock.sleep_until(before - kNanosPerSecond));
  EXPECT_LT(clock.now() - before, 10 * kNanosPerMilli);
}

TEST(MonotonicClock, InterruptEndsALongSleep) {
  MonotonicClock clock;
  std::atomic<bool> result{true};
  std::thread sleeper([&] { result = clock.sleep_until(clock.now() + 60 * kNanosPerSecond); });
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  clock.interrupt_sleepers();
  sleeper.join();
  EXPECT_FALSE(result.load());
}

TEST(SimulatedClock, SleepersWakeWhenTimeReachesTheirDeadline) {
  SimulatedClock clock(1000);
  std::atomic<bool> woke{false};
  std::thread sleeper([&] {
    EXPECT_TRUE(clock.sleep_until(5000));
    woke = true;
  });
  while (clock.sleepers() == 0) std::this_thread::yield();
  clock.advance_to(4999);
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_FALSE(woke.load());
  clock.advance_to(5000);
  sleeper.join();
  EXPECT_TRUE(woke.load());
  clock.advance_to(10);  // never backwards
  EXPECT_EQ(clock.now(), 5000);
}

TEST(SimulatedClock, InterruptReleasesSleepers) {
  SimulatedClock clock(0);
  std::thread sleeper([&] { EXPECT_FALSE(clock.sleep_until(1'000'000)); });
  while (clock.sleepers() == 0) std::this_thread::yield();
  clock.interrupt_sleepers();
  sleeper.join();
  clock.resume_sleepers();
  EXPECT_TRUE(clock.sleep_until(0));
}

}  // namespace
}  // namespace trailnav
