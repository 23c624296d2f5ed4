// Broadcast: one writer, several readers, each seeing the newest snapshot
// whole, never a torn one, never an older one after a newer.
#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cstdio>
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

// Following the slot being filled: only what the progress word vouches for
// is read; published, the slot comes once through completed(); dropped
// (refill()), it is abandoned() and the writer fills another.
TEST(Broadcast, AFollowerReadsWhatTheProgressVouchesForThenTheCompleteSnapshotOnce) {
  Broadcast<Snapshot> b(1, 0);
  Broadcast<Snapshot>::Reader& r = b.reader(0);
  const Snapshot* f = r.follow();
  ASSERT_NE(f, nullptr);
  EXPECT_EQ(r.progress(), 0u);
  EXPECT_EQ(r.completed(), nullptr);
  EXPECT_FALSE(r.abandoned());
  for (std::size_t i = 0; i < 100; ++i) b.write_slot().v[i] = 1;
  b.progress(100);
  EXPECT_EQ(r.progress(), 100u);
  EXPECT_EQ(f->v[99], 1u);
  for (std::size_t i = 100; i < 256; ++i) b.write_slot().v[i] = 1;
  b.publish();
  const Snapshot* done = r.completed();
  ASSERT_EQ(done, f);
  EXPECT_EQ(r.completed(), nullptr);  // once
  EXPECT_EQ(r.try_read(), nullptr);   // already read
  EXPECT_EQ(r.last_read_sequence(), 1u);
  // The next one: followed, then dropped by the writer.
  const Snapshot* g = r.follow();
  ASSERT_NE(g, nullptr);
  EXPECT_NE(g, f);
  b.write_slot().v[0] = 2;
  b.progress(1);
  b.refill();
  EXPECT_TRUE(r.abandoned());
  EXPECT_EQ(r.completed(), nullptr);
  EXPECT_NE(&b.write_slot(), g);  // the slot followed is not filled again while held
  const Snapshot* h = r.follow();
  EXPECT_NE(h, g);
  EXPECT_EQ(h, &b.write_slot());
  EXPECT_EQ(r.progress(), 0u);
  EXPECT_FALSE(r.abandoned());
  // Nobody follows it: a refill may give the same slot again.
  Broadcast<Snapshot> lone(1, 0);
  Snapshot* before = &lone.write_slot();
  EXPECT_EQ(&lone.refill(), before);
}

// A writer that fills snapshots part by part, publishing most and dropping
// some half-way, and a reader following it on another thread: every value
// the reader reads under a progress word is the one written for that word's
// snapshot, and every completed snapshot is whole.
TEST(Broadcast, AConcurrentFollowerNeverReadsPastTheProgressOrATornSnapshot) {
  Broadcast<Snapshot> b(1, 0);
  std::atomic<bool> started{false}, done{false};
  std::atomic<int> failures{0};
  std::atomic<std::uint64_t> completed{0}, abandoned{0};
  std::uint64_t checked = 0;
  std::thread reader([&] {
    Broadcast<Snapshot>::Reader& r = b.reader(0);
    const Snapshot* f = r.follow();
    started = true;
    for (;;) {
      const bool finished = done.load();
      if (const Snapshot* c = r.completed()) {
        const std::uint64_t id = c->v[0];
        for (std::uint64_t x : c->v) failures += x != id ? 1 : 0;
        ++completed;
        f = r.follow();
      } else if (r.abandoned()) {
        ++abandoned;
        f = r.follow();
      } else if (const std::uint64_t word = r.progress(); word != 0) {
        const std::uint64_t id = word >> 16;
        const std::size_t n = word & 0xffff;
        for (std::size_t i = 0; i < n; ++i) failures += f->v[i] != id ? 1 : 0;
        ++checked;
      }
      if (finished) break;
    }
  });
  while (!started.load()) std::this_thread::yield();
  // Until the reader has seen a few hundred snapshots end (at most a minute).
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  for (std::uint64_t id = 1; completed.load() + abandoned.load() < 300 && std::chrono::steady_clock::now() < give_up; ++id) {
    Snapshot& s = b.write_slot();
    for (std::size_t part = 0; part < 8; ++part) {
      for (std::size_t i = part * 32; i < part * 32 + 32; ++i) s.v[i] = id;
      b.progress((id << 16) | (part * 32 + 32));
      if (id % 7 == 0 && part == 3) break;
      std::this_thread::yield();  // the reader's turn, on a machine of one core too
    }
    if (id % 7 == 0) {
      b.refill();
    } else {
      b.publish();
    }
  }
  done = true;
  reader.join();
  EXPECT_EQ(failures.load(), 0);
  EXPECT_GE(completed.load() + abandoned.load(), 300u);
  EXPECT_GT(completed.load(), 0u);
  std::printf("completed %llu, abandoned %llu, progress checks %llu\n", static_cast<unsigned long long>(completed.load()),
              static_cast<unsigned long long>(abandoned.load()), static_cast<unsigned long long>(checked));
}

}  // namespace
}  // namespace trailnav
