// Latest-value hand-off from one writer to several readers, for large
// snapshots that more than one thread consumes (a lidar revolution read by the
// obstacle thread and by the terrain thread).
//
// Like Mailbox, nobody waits, copies or allocates after construction; unlike
// Mailbox, each of the R readers holds its own slot. A reader takes the latest
// slot by announcing itself on it and then checking that it is still the
// latest; the writer only ever fills a slot that is neither the latest nor
// announced by a reader. A reader may be announced on two slots at a moment
// (the one it holds and the one it is trying), so 2R + 2 slots always leave
// the writer a free one. Both sides use sequentially consistent
// atomics, which is what makes "announce, then re-check" safe against "publish,
// then look for a free slot".
#pragma once

#include <atomic>
#include <cassert>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace trailnav {

template <typename T>
class Broadcast {
  struct Slot;

 public:
  class Reader {
   public:
    // The newest snapshot if one was published since this reader's last
    // call, else nullptr. The pointer stays valid until the next try_read().
    const T* try_read() noexcept {
      Broadcast& b = *owner_;
      for (;;) {
        const std::size_t latest = b.latest_.load();
        if (latest == kNone) return nullptr;
        Slot& s = *b.slots_[latest];
        if (held_ == latest) {
          if (s.sequence == sequence_) return nullptr;  // nothing newer
        }
        s.readers.fetch_add(1);
        if (b.latest_.load() != latest) {  // the writer moved on meanwhile: try again
          s.readers.fetch_sub(1);
          continue;
        }
        if (s.sequence == sequence_) {  // already seen (we held it before and let go)
          s.readers.fetch_sub(1);
          return nullptr;
        }
        if (held_ != kNone) b.slots_[held_]->readers.fetch_sub(1);
        held_ = latest;
        sequence_ = s.sequence;
        return &s.value;
      }
    }
    // The snapshot most recently returned by try_read(). Before the first
    // one: the first slot's initial value, to be looked at only before the
    // writer starts (its slots' shape, at start-up).
    const T& last_read() const noexcept { return owner_->slots_[held_ == kNone ? 0 : held_]->value; }
    // Publication number of last_read(): 0 before the first snapshot.
    std::uint64_t last_read_sequence() const noexcept { return sequence_; }

   private:
    friend class Broadcast;
    Broadcast* owner_ = nullptr;
    std::size_t held_ = kNone;
    std::uint64_t sequence_ = 0;
  };

  // `readers` readers; every slot is constructed from `args` (a grid's shape).
  template <typename... Args>
  explicit Broadcast(std::size_t readers, const Args&... args) : readers_(readers) {
    assert(readers >= 1);
    slots_.reserve(2 * readers + 2);
    for (std::size_t i = 0; i < 2 * readers + 2; ++i) slots_.push_back(std::make_unique<Slot>(args...));
    for (Reader& r : readers_) r.owner_ = this;
  }
  Broadcast(const Broadcast&) = delete;
  Broadcast& operator=(const Broadcast&) = delete;

  std::size_t reader_count() const noexcept { return readers_.size(); }
  // Reader i (0 <= i < reader_count()); each used by one thread.
  Reader& reader(std::size_t i) noexcept { return readers_[i]; }

  // --- writer side (one thread) ---

  // The slot the writer may fill; it holds an older snapshot: overwrite all of it.
  T& write_slot() noexcept { return slots_[back_]->value; }

  // Makes the write slot the latest snapshot and picks a free one to fill next.
  void publish() noexcept {
    slots_[back_]->sequence = ++published_;
    latest_.store(back_);
    const std::size_t just_published = back_;
    for (std::size_t i = 0; i < slots_.size(); ++i) {
      if (i != just_published && slots_[i]->readers.load() == 0) {
        back_ = i;
        return;
      }
    }
    // Unreachable: R readers are announced on at most 2R slots, the latest is one more.
    assert(false);
  }

  std::uint64_t published() const noexcept { return published_; }

 private:
  static constexpr std::size_t kNone = static_cast<std::size_t>(-1);
  struct Slot {
    template <typename... Args>
    explicit Slot(const Args&... args) : value(args...) {}
    T value;
    std::uint64_t sequence = 0;
    std::atomic<std::uint32_t> readers{0};
  };

  std::vector<std::unique_ptr<Slot>> slots_;  // behind pointers: Slot holds an atomic
  std::vector<Reader> readers_;
  std::atomic<std::size_t> latest_{kNone};
  std::size_t back_ = 0;
  std::uint64_t published_ = 0;
};

}  // namespace trailnav
