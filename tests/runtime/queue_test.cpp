#include <gtest/gtest.h>

#include <array>
#include <thread>
#include <vector>

#include "trailnav/runtime/mpsc_queue.hpp"
#include "trailnav/runtime/spsc_queue.hpp"

namespace trailnav {
namespace {

TEST(SpscQueue, FullAndEmptyAreReportedWithoutBlocking) {
  SpscQueue<int, 4> q;
  int out = -1;
  EXPECT_FALSE(q.try_pop(out));
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(q.try_push(i));
  EXPECT_FALSE(q.try_push(99));
  EXPECT_EQ(q.size_approx(), 4u);
  for (int i = 0; i < 4; ++i) {
    ASSERT_TRUE(q.try_pop(out));
    EXPECT_EQ(out, i);
  }
  EXPECT_FALSE(q.try_pop(out));
}

TEST(SpscQueue, TwoThreadsTransferEveryItemInOrder) {
  constexpr std::uint64_t kItems = 1'000'000;
  auto q = std::make_unique<SpscQueue<std::uint64_t, 1024>>();
  std::thread producer([&] {
    for (std::uint64_t i = 0; i < kItems;) {
      if (q->try_push(i)) ++i;
    }
  });
  std::uint64_t expected = 0;
  std::uint64_t value = 0;
  while (expected < kItems) {
    if (q->try_pop(value)) {
      ASSERT_EQ(value, expected);
      ++expected;
    }
  }
  producer.join();
  EXPECT_FALSE(q->try_pop(value));
}

TEST(MpscQueue, ManyProducersDeliverEveryItemOncePerProducerInOrder) {
  constexpr int kProducers = 4;
  constexpr std::uint32_t kPerProducer = 100'000;
  struct Item {
    std::uint32_t producer = 0;
    std::uint32_t sequence = 0;
  };
  auto q = std::make_unique<MpscQueue<Item, 256>>();
  std::vector<std::thread> producers;
  for (int p = 0; p < kProducers; ++p) {
    producers.emplace_back([&, p] {
      for (std::uint32_t i = 0; i < kPerProducer;) {
        if (q->try_push(Item{static_cast<std::uint32_t>(p), i})) ++i;
      }
    });
  }
  std::array<std::uint32_t, kProducers> next{};
  std::uint64_t received = 0;
  Item item;
  while (received < std::uint64_t{kProducers} * kPerProducer) {
    if (q->try_pop(item)) {
      ASSERT_LT(item.producer, static_cast<std::uint32_t>(kProducers));
      ASSERT_EQ(item.sequence, next[item.producer]);
      ++next[item.producer];
      ++received;
    }
  }
  for (auto& t : producers) t.join();
  EXPECT_FALSE(q->try_pop(item));
}

TEST(MpscQueue, RefusesPushWhenFull) {
  MpscQueue<int, 2> q;
  EXPECT_TRUE(q.try_push(1));
  EXPECT_TRUE(q.try_push(2));
  EXPECT_FALSE(q.try_push(3));
  int out = 0;
  ASSERT_TRUE(q.try_pop(out));
  EXPECT_EQ(out, 1);
  EXPECT_TRUE(q.try_push(3));
}

}  // namespace
}  // namespace trailnav
