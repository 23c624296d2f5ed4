// Bounded lock-free queue for many producers and one consumer, after Dmitry
// Vyukov's bounded MPMC design: each slot carries a sequence number that
// tells producers and the consumer whose turn it is. Used where several
// real-time threads feed one service thread (the logger).
#pragma once

#include <array>
#include <atomic>
#include <bit>
#include <cstddef>
#include <cstdint>

#include "trailnav/runtime/spsc_queue.hpp"

namespace trailnav {

template <typename T, std::size_t Capacity>
class MpscQueue {
  static_assert(std::has_single_bit(Capacity), "capacity must be a power of two");

 public:
  MpscQueue() noexcept {
    for (std::size_t i = 0; i < Capacity; ++i) slots_[i].sequence.store(i, std::memory_order_relaxed);
  }
  MpscQueue(const MpscQueue&) = delete;
  MpscQueue& operator=(const MpscQueue&) = delete;

  // Any thread. Returns false without waiting when the queue is full.
  bool try_push(const T& value) noexcept {
    std::size_t pos = tail_.load(std::memory_order_relaxed);
    for (;;) {
      Slot& slot = slots_[pos & kMask];
      const std::size_t seq = slot.sequence.load(std::memory_order_acquire);
      const auto diff = static_cast<std::intptr_t>(seq) - static_cast<std::intptr_t>(pos);
      if (diff == 0) {
        if (tail_.compare_exchange_weak(pos, pos + 1, std::memory_order_relaxed)) {
          slot.value = value;
          slot.sequence.store(pos + 1, std::memory_order_release);
          return true;
        }
      } else if (diff < 0) {
        return false;
      } else {
        pos = tail_.load(std::memory_order_relaxed);
      }
    }
  }

  // The single consumer. Returns false when nothing is ready.
  bool try_pop(T& out) noexcept {
    Slot& slot = slots_[head_ & kMask];
    const std::size_t seq = slot.sequence.load(std::memory_order_acquire);
    if (seq != head_ + 1) return false;
    out = slot.value;
    slot.sequence.store(head_ + Capacity, std::memory_order_release);
    ++head_;
    return true;
  }

 private:
  static constexpr std::size_t kMask = Capacity - 1;
  struct Slot {
    std::atomic<std::size_t> sequence{0};
    T value{};
  };

  alignas(kCacheLine) std::atomic<std::size_t> tail_{0};
  alignas(kCacheLine) std::size_t head_ = 0;
  alignas(kCacheLine) std::array<Slot, Capacity> slots_{};
};

}  // namespace trailnav
