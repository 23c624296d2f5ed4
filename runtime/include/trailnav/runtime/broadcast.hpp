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
//
// A reader may also follow the slot the writer is filling (follow()), to work
// on a snapshot while it is made (trailnavd's obstacle thread on a lidar
// revolution): the writer tells how far it is with a progress word, stored
// after the contents it vouches for, and a reader reads only those. Following
// is holding: the slot stays the reader's until it follows or reads another,
// so it is never refilled under it; a writer that drops what it filled
// (refill()) takes a fresh slot instead.
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
          if (s.sequence.load() == sequence_) return nullptr;  // nothing newer
        }
        s.readers.fetch_add(1);
        if (b.latest_.load() != latest) {  // the writer moved on meanwhile: try again
          s.readers.fetch_sub(1);
          continue;
        }
        if (s.sequence.load() == sequence_) {  // already seen (we held it before and let go)
          s.readers.fetch_sub(1);
          return nullptr;
        }
        if (held_ != kNone) b.slots_[held_]->readers.fetch_sub(1);
        held_ = latest;
        sequence_ = s.sequence.load();
        return &s.value;
      }
    }

    // The slot the writer is filling (or has just published), held from
    // now on in place of the one held before. Its contents are the writer's
    // to change, except what its progress() vouches for; published, it
    // becomes completed()'s. Valid until the next follow() or try_read().
    const T* follow() noexcept {
      Broadcast& b = *owner_;
      for (;;) {
        const std::size_t filling = b.filling_.load();
        if (held_ == filling) return &b.slots_[filling]->value;
        Slot& s = *b.slots_[filling];
        s.readers.fetch_add(1);
        if (b.filling_.load() != filling) {  // published or dropped meanwhile: try again
          s.readers.fetch_sub(1);
          continue;
        }
        if (held_ != kNone) b.slots_[held_]->readers.fetch_sub(1);
        held_ = filling;
        sequence_ = s.sequence.load();  // its last publication: the next one is news
        // Unless it was published as the reader came (the latest is never
        // filled): then completed() gives it.
        if (b.latest_.load() == filling) sequence_ = 0;
        return &s.value;
      }
    }
    // The writer's progress word on the slot held (0 before it said any),
    // with everything it wrote before it.
    std::uint64_t progress() const noexcept {
      return held_ == kNone ? 0 : owner_->slots_[held_]->progress.load();
    }
    // The slot held, when the writer has published it since the reader took
    // it (then no more: it counts as read), else nullptr.
    const T* completed() noexcept {
      if (held_ == kNone) return nullptr;
      Slot& s = *owner_->slots_[held_];
      const std::uint64_t published = s.sequence.load();
      if (published == sequence_) return nullptr;
      sequence_ = published;
      return &s.value;
    }
    // The slot followed was dropped by the writer (refill()): neither
    // filled nor published any more.
    bool abandoned() const noexcept {
      if (held_ == kNone) return false;
      const Broadcast& b = *owner_;
      if (b.filling_.load() == held_) return false;
      return b.slots_[held_]->sequence.load() == sequence_;
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
    slots_[back_]->sequence.store(++published_);
    latest_.store(back_);
    next_slot(back_);
  }

  // How far the write slot is, for readers following it (Reader::follow()):
  // a word both sides agree on, 0 for "nothing yet"; it vouches for what the
  // writer wrote before it. (All of it sequentially consistent: a reader
  // that comes to a slot just picked anew must not see its old word.)
  void progress(std::uint64_t word) noexcept { slots_[back_]->progress.store(word); }

  // Drops what the write slot holds and gives a fresh one (the same one when
  // no reader follows it): when the writer starts its snapshot anew.
  T& refill() noexcept {
    slots_[back_]->progress.store(0);  // before looking for readers: a newcomer sees 0, not the old word
    next_slot(kNone);
    return write_slot();
  }

  std::uint64_t published() const noexcept { return published_; }

 private:
  static constexpr std::size_t kNone = static_cast<std::size_t>(-1);
  struct Slot {
    template <typename... Args>
    explicit Slot(const Args&... args) : value(args...) {}
    T value;
    std::atomic<std::uint64_t> sequence{0};  // of its last publication
    std::atomic<std::uint64_t> progress{0};  // while filled
    std::atomic<std::uint32_t> readers{0};
  };

  // Picks a slot no reader holds, other than `not_this` and the latest, to fill next.
  void next_slot(std::size_t not_this) noexcept {
    const std::size_t latest = latest_.load();
    for (std::size_t i = 0; i < slots_.size(); ++i) {
      if (i != not_this && i != latest && slots_[i]->readers.load() == 0) {
        back_ = i;
        slots_[i]->progress.store(0);
        filling_.store(i);
        return;
      }
    }
    // Unreachable: R readers are announced on at most 2R slots, the latest is one more.
    assert(false);
  }

  std::vector<std::unique_ptr<Slot>> slots_;  // behind pointers: Slot holds an atomic
  std::vector<Reader> readers_;
  std::atomic<std::size_t> latest_{kNone};
  std::atomic<std::size_t> filling_{0};  // back_, for followers
  std::size_t back_ = 0;
  std::uint64_t published_ = 0;
};

}  // namespace trailnav
