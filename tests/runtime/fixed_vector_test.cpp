#include "trailnav/runtime/fixed_vector.hpp"

#include <gtest/gtest.h>

#include <numeric>

namespace trailnav {
namespace {

// Counts live objects so the tests can see construction and destruction.
struct Tracked {
  static inline int live = 0;
  int value = 0;
  explicit Tracked(int v = 0) : value(v) { ++live; }
  Tracked(const Tracked& o) : value(o.value) { ++live; }
  Tracked& operator=(const Tracked&) = default;
  ~Tracked() { --live; }
};

int sum(std::span<const int> values) { return std::accumulate(values.begin(), values.end(), 0); }

TEST(InlineVector, RefusesPushBeyondCapacityAndKeepsContents) {
  InlineVector<int, 3> v;
  EXPECT_TRUE(v.try_push_back(1));
  EXPECT_TRUE(v.try_push_back(2));
  EXPECT_TRUE(v.try_push_back(3));
  EXPECT_TRUE(v.full());
  EXPECT_FALSE(v.try_push_back(4));
  EXPECT_EQ(v.try_emplace_back(5), nullptr);
  ASSERT_EQ(v.size(), 3u);
  EXPECT_EQ(sum(v.span()), 6);
}

TEST(InlineVector, ConstructsAndDestroysElementsExactlyOnce) {
  Tracked::live = 0;
  {
    InlineVector<Tracked, 8> v;
    for (int i = 0; i < 5; ++i) ASSERT_NE(v.try_emplace_back(i), nullptr);
    EXPECT_EQ(Tracked::live, 5);
    v.pop_back();
    EXPECT_EQ(Tracked::live, 4);
    InlineVector<Tracked, 8> copy = v;
    EXPECT_EQ(Tracked::live, 8);
    EXPECT_EQ(copy[3].value, 3);
    v.clear();
    EXPECT_EQ(Tracked::live, 4);
  }
  EXPECT_EQ(Tracked::live, 0);
}

TEST(FixedVector, CapacityIsChosenAtRunTimeAndNeverGrows) {
  FixedVector<int> v(100);
  EXPECT_EQ(v.capacity(), 100u);
  for (int i = 0; i < 100; ++i) ASSERT_TRUE(v.try_push_back(i));
  EXPECT_FALSE(v.try_push_back(100));
  EXPECT_EQ(sum(v.span()), 4950);
  const int* storage = v.data();
  v.clear();
  v.resize(50);
  EXPECT_EQ(v.data(), storage);  // same storage after clear and resize
  EXPECT_EQ(v.size(), 50u);
  EXPECT_EQ(v[49], 0);
}

TEST(FixedVector, MoveTransfersStorage) {
  FixedVector<int> a(4);
  ASSERT_TRUE(a.try_push_back(7));
  const int* storage = a.data();
  FixedVector<int> b(std::move(a));
  EXPECT_EQ(b.data(), storage);
  EXPECT_EQ(b.size(), 1u);
  EXPECT_EQ(b[0], 7);
  EXPECT_EQ(a.capacity(), 0u);  // NOLINT(bugprone-use-after-move): checking the moved-from state
}

}  // namespace
}  // namespace trailnav
