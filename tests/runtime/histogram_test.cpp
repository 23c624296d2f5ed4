#include "trailnav/runtime/histogram.hpp"

#include <gtest/gtest.h>

#include <limits>
#include <random>

namespace trailnav {
namespace {

TEST(DurationHistogram, BucketsCoverEveryValueWithBoundedRelativeWidth) {
  std::mt19937_64 rng(7);
  for (int i = 0; i < 100'000; ++i) {
    const std::uint64_t v = rng() >> (rng() % 44 + 20);  // spread over many magnitudes (shift < 64)
    const std::size_t b = DurationHistogram::bucket_of(v);
    ASSERT_LT(b, DurationHistogram::kBuckets);
    if (v < (std::uint64_t{1} << DurationHistogram::kMaxBits)) {
      ASSERT_GE(DurationHistogram::upper_bound_of(b), v);
      if (b > 0) {
        ASSERT_LT(DurationHistogram::upper_bound_of(b - 1), v);
      }
      ASSERT_LE(static_cast<double>(DurationHistogram::upper_bound_of(b) - v), 0.032 * static_cast<double>(v) + 1.0);
    }
  }
}

TEST(DurationHistogram, HugeValuesSaturateInTheLastBucket) {
  EXPECT_EQ(DurationHistogram::bucket_of(~std::uint64_t{0}), DurationHistogram::kBuckets - 1);
  EXPECT_EQ(DurationHistogram::bucket_of(std::uint64_t{1} << DurationHistogram::kMaxBits), DurationHistogram::kBuckets - 1);
  DurationHistogram h;
  h.record(std::numeric_limits<Nanos>::max());
  EXPECT_EQ(h.summary().count, 1u);
}

TEST(DurationHistogram, QuantilesAreWithinThreePercent) {
  DurationHistogram h;
  for (Nanos v = 1; v <= 100'000; ++v) h.record(v);
  const DurationSummary s = h.summary();
  EXPECT_EQ(s.count, 100'000u);
  EXPECT_EQ(s.min, 1);
  EXPECT_EQ(s.max, 100'000);
  EXPECT_NEAR(static_cast<double>(s.p50), 50'000.0, 50'000.0 * 0.032);
  EXPECT_NEAR(static_cast<double>(s.p99), 99'000.0, 99'000.0 * 0.032);
  EXPECT_NEAR(s.mean, 50'000.5, 1e-6);
}

TEST(DurationHistogram, EmptyAndResetGiveZeros) {
  DurationHistogram h;
  EXPECT_EQ(h.summary().count, 0u);
  h.record(5);
  h.record(-3);  // clock went backwards: recorded as 0, never as a huge value
  EXPECT_EQ(h.summary().min, 0);
  h.reset();
  EXPECT_EQ(h.summary().count, 0u);
  EXPECT_EQ(h.summary().max, 0);
}

}  // namespace
}  // namespace trailnav
