#include "trailnav/runtime/mailbox.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <thread>
#include <vector>

namespace trailnav {
namespace {

// A large snapshot whose every element must equal its stamp when read: any
// torn read (writer and reader on one slot) shows as a mismatch.
struct Snapshot {
  explicit Snapshot(std::size_t n) : cells(n, 0) {}
  std::uint64_t stamp = 0;
  std::vector<std::uint64_t> cells;
};

TEST(Mailbox, ReaderSeesOnlyNewSnapshots) {
  Mailbox<Snapshot> box(std::size_t{4});
  EXPECT_EQ(box.try_read(), nullptr);
  EXPECT_EQ(box.last_read_sequence(), 0u);

  box.write_slot().stamp = 1;
  box.publish();
  const Snapshot* s = box.try_read();
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(s->stamp, 1u);
  EXPECT_EQ(box.last_read_sequence(), 1u);
  EXPECT_EQ(box.try_read(), nullptr);  // nothing new
  EXPECT_EQ(box.last_read().stamp, 1u);

  // Two publications before a read: the reader gets only the newest.
  box.write_slot().stamp = 2;
  box.publish();
  box.write_slot().stamp = 3;
  box.publish();
  s = box.try_read();
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(s->stamp, 3u);
  EXPECT_EQ(box.last_read_sequence(), 3u);
}

TEST(Mailbox, WriterNeverWritesTheSlotTheReaderHolds) {
  constexpr std::size_t kCells = 600 * 600 / 8;
  Mailbox<Snapshot> box(kCells);
  std::atomic<bool> done{false};
  std::thread writer([&] {
    for (std::uint64_t stamp = 1; stamp <= 3000; ++stamp) {
      Snapshot& slot = box.write_slot();
      slot.stamp = stamp;
      for (auto& c : slot.cells) c = stamp;
      box.publish();
    }
    done.store(true);
  });
  std::uint64_t last = 0;
  std::uint64_t reads = 0;
  for (;;) {
    const bool finished = done.load();
    const Snapshot* s = box.try_read();
    if (s == nullptr) {
      if (finished) break;
      continue;
    }
    ++reads;
    ASSERT_GT(s->stamp, last) << "snapshots must arrive newest-last";
    last = s->stamp;
    for (std::uint64_t c : s->cells) ASSERT_EQ(c, s->stamp) << "torn snapshot";
  }
  writer.join();
  EXPECT_GT(reads, 0u);
  EXPECT_EQ(last, 3000u) << "the final snapshot is always delivered";
}

}  // namespace
}  // namespace trailnav
