// ClockRelation: a sensor clock related to the host's by the smallest
// receive-minus-sensor difference, held against jitter, re-anchored on steps.
#include <gtest/gtest.h>

#include <cstdint>
#include <random>

#include "trailnav/runtime/clock_relation.hpp"

using trailnav::ClockRelation;

namespace {

constexpr std::int64_t kMs = 1'000'000;
constexpr std::int64_t kSec = 1'000'000'000;

}  // namespace

TEST(ClockRelation, BeforeAnyPairTheSensorTimeIsTaken) {
  ClockRelation r;
  EXPECT_FALSE(r.state().valid);
  EXPECT_EQ(r.to_reference(123), 123);
}

// A recording's GPS time months before the host's: packets every 1.3 ms,
// delayed 0.05-3 ms by the transport. The offset is the true one plus the
// shortest delay, and it never moves once held.
TEST(ClockRelation, FindsTheOffsetPlusTheShortestDelayAndHoldsIt) {
  const std::int64_t true_offset = 163LL * 86400 * kSec + 12345678;  // 163 days and a bit
  std::mt19937 rng(7);
  std::uniform_int_distribution<std::int64_t> delay(50'000, 3 * kMs);
  ClockRelation r;
  std::int64_t held = 0;
  for (int i = 0; i < 20000; ++i) {  // 26 s
    const std::int64_t sensor = 1'782'000'000LL * kSec + i * 1'300'000LL;
    r.add(sensor, sensor + true_offset + delay(rng));
    if (i == 3000) {  // past the first 2 s window
      ASSERT_TRUE(r.state().settled);
      held = r.offset_ns();
    }
  }
  EXPECT_EQ(r.offset_ns(), held);
  EXPECT_GE(r.offset_ns(), true_offset + 50'000);
  EXPECT_LE(r.offset_ns(), true_offset + 60'000);  // 1,500 draws per window from 2.95 ms: the smallest is within 10 us
  EXPECT_EQ(r.state().steps, 0u);
  EXPECT_GE(r.state().windows, 12u);
  // Mean delay 1.525 ms above a minimum near 0.05 ms.
  EXPECT_NEAR(static_cast<double>(r.state().spread_ns), 1.475e6, 0.1e6);
  EXPECT_GT(r.state().max_spread_ns, 2 * kMs);
}

TEST(ClockRelation, ProvisionalOffsetIsTheRunningMinimum) {
  ClockRelation r;
  r.add(1000 * kMs, 1000 * kMs + 5 * kMs);
  EXPECT_TRUE(r.state().valid);
  EXPECT_FALSE(r.state().settled);
  EXPECT_EQ(r.offset_ns(), 5 * kMs);
  r.add(1001 * kMs, 1001 * kMs + 7 * kMs);
  EXPECT_EQ(r.offset_ns(), 5 * kMs);
  r.add(1002 * kMs, 1002 * kMs + 1 * kMs);
  EXPECT_EQ(r.offset_ns(), 1 * kMs);
}

// The host clock is stepped by 250 ms (or the sensor switches to GPS time):
// the next window's minimum is far from the held offset, so it re-anchors
// once and counts it; the window after it holds again.
TEST(ClockRelation, ReanchorsOnAClockStepAndCountsIt) {
  ClockRelation r;
  std::int64_t offset = 40 * kMs;
  for (int i = 0; i < 10000; ++i) {  // 10 s at 1 kHz
    if (i == 5000) offset += 250 * kMs;
    const std::int64_t sensor = 5 * kSec + i * kMs;
    r.add(sensor, sensor + offset + (i % 7) * 100'000);
  }
  EXPECT_EQ(r.state().steps, 1u);
  EXPECT_EQ(r.offset_ns(), 290 * kMs);
}

// The host clock is stepped back: a message would have arrived before it was
// sent, so the relation restarts at once.
TEST(ClockRelation, AMessageFromTheFutureRestartsAtOnce) {
  ClockRelation r;
  for (int i = 0; i < 3000; ++i) r.add(i * kMs, i * kMs + 10 * kMs);
  ASSERT_TRUE(r.state().settled);
  r.add(3000 * kMs, 3000 * kMs - 490 * kMs);
  EXPECT_EQ(r.state().steps, 1u);
  EXPECT_FALSE(r.state().settled);
  EXPECT_EQ(r.offset_ns(), -490 * kMs);
}

TEST(ClockRelation, JitterWithinToleranceNeverMovesTheOffset) {
  ClockRelation r;
  std::int64_t held = 0;
  for (int w = 0; w < 10; ++w) {
    // Each window's shortest delay differs by up to 1.5 ms (under the 2 ms tolerance).
    const std::int64_t shortest = (w % 2 == 0) ? 100'000 : 1'600'000;
    for (int i = 0; i < 2001; ++i) {
      const std::int64_t sensor = 100 * kSec + w * 2 * kSec + i * kMs;
      r.add(sensor, sensor + 3 * kSec + shortest + (i % 10) * 10'000);
    }
    if (w == 1) held = r.offset_ns();
  }
  EXPECT_EQ(r.offset_ns(), held);
  EXPECT_EQ(r.offset_ns(), 3 * kSec + 100'000);
  EXPECT_EQ(r.state().steps, 0u);
}

// A recording that loops: the sensor time jumps back by the drive's length
// while the host time goes on; the relation follows at once.
TEST(ClockRelation, SensorTimeGoingBackClosesTheWindowAndReanchors) {
  ClockRelation r;
  const std::int64_t host0 = 1'790'000'000LL * kSec;
  for (int i = 0; i < 6000; ++i) {  // 6 s of a 3 s recording played twice
    const std::int64_t sensor = 1'780'000'000LL * kSec + (i % 3000) * kMs;
    r.add(sensor, host0 + i * kMs + 200'000);
    if (i == 3000) {
      EXPECT_EQ(r.to_reference(sensor), host0 + i * kMs + 200'000);
    }
  }
  EXPECT_EQ(r.state().steps, 1u);
  EXPECT_EQ(r.to_reference(1'780'000'000LL * kSec + 2999 * kMs), host0 + 5999 * kMs + 200'000);
}
