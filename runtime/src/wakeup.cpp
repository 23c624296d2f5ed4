#include "trailnav/runtime/wakeup.hpp"

#include <cerrno>
#include <ctime>

namespace trailnav {

Wakeup::Wakeup() noexcept { ::sem_init(&sem_, 0, 0); }

Wakeup::~Wakeup() { ::sem_destroy(&sem_); }

void Wakeup::notify() noexcept {
  // Keep the count small: one pending post is enough to wake the waiter.
  int value = 0;
  if (::sem_getvalue(&sem_, &value) == 0 && value > 0) return;
  ::sem_post(&sem_);
}

bool Wakeup::wait_for(Nanos timeout) noexcept {
  timespec deadline{};
  ::clock_gettime(CLOCK_MONOTONIC, &deadline);
  const Nanos total = static_cast<Nanos>(deadline.tv_nsec) + timeout;
  deadline.tv_sec += static_cast<time_t>(total / kNanosPerSecond);
  deadline.tv_nsec = static_cast<long>(total % kNanosPerSecond);
  int rc = 0;
  while ((rc = ::sem_clockwait(&sem_, CLOCK_MONOTONIC, &deadline)) != 0 && errno == EINTR) {
  }
  if (rc != 0) return false;
  while (::sem_trywait(&sem_) == 0) {
  }
  return true;
}

}  // namespace trailnav
