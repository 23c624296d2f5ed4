// Wakes a non-real-time thread from a real-time one. notify() posts a POSIX
// semaphore: no lock, no allocation, never blocks (async-signal-safe too), so
// a real-time task may call it after publishing a snapshot. The waiting side
// sleeps until a notification or a timeout; notifications that pile up while
// it works coalesce into one wake-up.
#pragma once

#include <semaphore.h>

#include "trailnav/runtime/clock.hpp"

namespace trailnav {

class Wakeup {
 public:
  Wakeup() noexcept;
  ~Wakeup();
  Wakeup(const Wakeup&) = delete;
  Wakeup& operator=(const Wakeup&) = delete;

  // Any thread; wait-free.
  void notify() noexcept;
  // One thread: true when notified within `timeout` (all pending notifications
  // are consumed), false on timeout.
  bool wait_for(Nanos timeout) noexcept;

 private:
  sem_t sem_;
};

}  // namespace trailnav
