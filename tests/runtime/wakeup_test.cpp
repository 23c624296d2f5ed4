#include "trailnav/runtime/wakeup.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>

using namespace trailnav;

TEST(Wakeup, TimesOutWithoutNotification) {
  Wakeup w;
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_FALSE(w.wait_for(20 * kNanosPerMilli));
  EXPECT_GE(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(19));
}

TEST(Wakeup, NotificationsBeforeTheWaitCoalesceIntoOneWakeUp) {
  Wakeup w;
  for (int i = 0; i < 10; ++i) w.notify();
  EXPECT_TRUE(w.wait_for(kNanosPerSecond));
  EXPECT_FALSE(w.wait_for(5 * kNanosPerMilli));  // all consumed
}

TEST(Wakeup, AnotherThreadWakesTheWaiter) {
  Wakeup w;
  std::atomic<int> woken{0};
  std::thread waiter([&] {
    while (woken.load() < 100) {
      if (!w.wait_for(2 * kNanosPerSecond)) break;
      woken.fetch_add(1);
    }
  });
  for (int i = 0; i < 100; ++i) {
    const int before = woken.load();
    w.notify();
    while (woken.load() == before) std::this_thread::yield();
  }
  waiter.join();
  EXPECT_EQ(woken.load(), 100);
}
