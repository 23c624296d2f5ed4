// Broadcast: one writer, several readers, each seeing the newest snapshot
// whole, never a torn one, never an older one after a newer.
#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <thread>
#include <vector>

#include "trailnav/runtime/broadcast.hpp"

namespace trailnav {
namespace {

struct Snapshot {
  explicit Snapshot(int fill) { v.fill(static_cast<std::uint64_t>(fill)); }
  std::array<std::uint64_t, 256> v;
};

TEST(Broadcast, EachReaderGetsEachNewSnapshotOnce) {
  Broadcast<Snapshot> b(2, 0);
  EXPECT_EQ(b.reader(0).try_read(), nullptr);
  EXPECT_EQ(b.reader(0).last_read_sequence(), 0u);
  b.write_slot().v.fill(7);
  b.publish();
  const Snapshot* a = b.reader(0).try_read();
  ASSERT_NE(a, nullptr);
  EXPECT_EQ(a->v[100], 7u);
  EXPECT_EQ(b.reader(0).try_read(), nullptr);  // nothing newer
  EXPECT_EQ(b.reader(0).last_read().v[0], 7u);
  // The second reader has its own view.
  const Snapshot* c = b.reader(1).try_read();
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(c->v[0], 7u);
  // Both hold their slots while the writer publishes again and again.
  for (int i = 8; i < 20; ++i) {
    b.write_slot().v.fill(static_cast<std::uint64_t>(i));
    b.publish();
    EXPECT_EQ(a->v[5], 7u);  // still intact: no slot a reader holds is written
  }
  EXPECT_EQ(b.reader(0).try_read()->v[9], 19u);
  EXPECT_EQ(b.reader(0).last_read_sequence(), 13u);
  EXPECT_EQ(b.reader(1).try_read()->v[9], 19u);
}

TEST(Broadcast, ConcurrentReadersNeverSeeATornOrOlderSnapshot) {
  Broadcast<Snapshot> b(3, 0);
  constexpr std::uint64_t kSnapshots = 20000;
  std::atomic<bool> done{false};
  std::atomic<int> failures{0};
  std::vector<std::thread> readers;
  std::array<std::uint64_t, 3> seen{};
  for (std::size_t r = 0; r < 3; ++r) {
    readers.emplace_back([&, r] {
      std::uint64_t last = 0;
      for (;;) {
        const bool finished = done.load();
        if (const Snapshot* s = b.reader(r).try_read()) {
          const std::uint64_t value = s->v[0];
          for (std::uint64_t x : s->v) failures += x != value ? 1 : 0;
          failures += value <= last ? 1 : 0;
          failures += b.reader(r).last_read_sequence() != value ? 1 : 0;
          last = value;
          ++seen[r];
        }
        if (finished) break;
      }
    });
  }
  for (std::uint64_t i = 1; i <= kSnapshots; ++i) {
    b.write_slot().v.fill(i);
    b.publish();
  }
  done = true;
  for (auto& t : readers) t.join();
  EXPECT_EQ(failures.load(), 0);
  for (std::size_t r = 0; r < 3; ++r) {
    EXPECT_GT(seen[r], 0u);
    EXPECT_EQ(b.reader(r).last_read_sequence(), kSnapshots) << r;  // every reader ends on the newest
  }
}

}  // namespace
}  // namespace trailnav
