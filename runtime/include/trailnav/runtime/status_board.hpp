// A driver's counters and health, written by its real-time task and read by
// anyone (diagnostics, the daemon's publisher). The task only try_locks, so a
// reader can never block it: an update that meets a reader is skipped and the
// next run's update carries it. Readers take a consistent copy.
#pragma once

#include <mutex>

namespace trailnav {

template <typename T>
class StatusBoard {
 public:
  // Real-time side: never waits.
  void post(const T& value) noexcept {
    if (mutex_.try_lock()) {
      value_ = value;
      mutex_.unlock();
    }
  }
  // Reader side.
  T read() const noexcept {
    std::lock_guard lock(mutex_);
    return value_;
  }

 private:
  mutable std::mutex mutex_;
  T value_{};
};

}  // namespace trailnav
