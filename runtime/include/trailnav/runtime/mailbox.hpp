// Latest-value mailbox for large snapshots (a triple buffer). The writer fills
// the slot it owns and publishes it by swapping it with the shared middle
// slot; the reader swaps the middle slot for the one it owns when a newer
// snapshot is there. Neither side waits, copies or allocates: a 600 x 600 grid
// moves from a real-time thread to a publisher with two atomic exchanges.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>

#include "trailnav/runtime/spsc_queue.hpp"

namespace trailnav {

template <typename T>
class Mailbox {
 public:
  // All three slots are constructed here, at start-up, from the same
  // arguments (for example a grid's dimensions).
  template <typename... Args>
  explicit Mailbox(const Args&... args) : slots_{Slot{T(args...)}, Slot{T(args...)}, Slot{T(args...)}} {}
  Mailbox(const Mailbox&) = delete;
  Mailbox& operator=(const Mailbox&) = delete;

  // --- writer side (one thread) ---

  // The slot the writer may fill. It holds an older snapshot: overwrite all of it.
  T& write_slot() noexcept { return slots_[back_].value; }

  // Makes the write slot the latest snapshot; the writer then owns another slot.
  void publish() noexcept {
    slots_[back_].sequence = ++published_;
    const std::uint8_t previous =
        middle_.exchange(static_cast<std::uint8_t>(back_ | kFresh), std::memory_order_acq_rel);
    back_ = previous & kIndexMask;
  }

  // --- reader side (one thread) ---

  // The newest snapshot if one arrived since the last call, else nullptr.
  // The pointer stays valid until the next try_read().
  const T* try_read() noexcept {
    if ((middle_.load(std::memory_order_acquire) & kFresh) == 0) return nullptr;
    const std::uint8_t previous = middle_.exchange(front_, std::memory_order_acq_rel);
    front_ = previous & kIndexMask;
    return &slots_[front_].value;
  }

  // The snapshot most recently returned by try_read() (possibly stale).
  const T& last_read() const noexcept { return slots_[front_].value; }
  // Publication number of last_read(): 0 before the first snapshot.
  std::uint64_t last_read_sequence() const noexcept { return slots_[front_].sequence; }

 private:
  static constexpr std::uint8_t kIndexMask = 0x3;
  static constexpr std::uint8_t kFresh = 0x4;
  struct Slot {
    T value;
    std::uint64_t sequence = 0;
  };

  std::array<Slot, 3> slots_;
  alignas(kCacheLine) std::atomic<std::uint8_t> middle_{1};
  alignas(kCacheLine) std::uint8_t back_ = 0;  // writer's slot
  std::uint64_t published_ = 0;               // writer's counter
  alignas(kCacheLine) std::uint8_t front_ = 2;  // reader's slot
};

}  // namespace trailnav
