#include "trailnav/runtime/clock.hpp"

#include <poll.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <ctime>

namespace trailnav {
namespace {
constexpr Nanos kInterruptCheck = 50 * kNanosPerMilli;

timespec to_timespec(Nanos t) noexcept {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(t / kNanosPerSecond);
  ts.tv_nsec = static_cast<long>(t % kNanosPerSecond);
  return ts;
}
}  // namespace

Nanos MonotonicClock::now() const noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<Nanos>(ts.tv_sec) * kNanosPerSecond + ts.tv_nsec;
}

Nanos MonotonicClock::thread_cpu_time() const noexcept {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<Nanos>(ts.tv_sec) * kNanosPerSecond + ts.tv_nsec;
}

bool MonotonicClock::sleep_until(Nanos deadline) noexcept {
  // Long sleeps are cut into absolute steps so that an interrupt is seen
  // within kInterruptCheck; the final step still ends exactly at the deadline.
  for (;;) {
    if (interrupted_.load(std::memory_order_acquire)) return false;
    const Nanos step_end = std::min(deadline, now() + kInterruptCheck);
    const timespec ts = to_timespec(step_end);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    }
    if (step_end == deadline) return !interrupted_.load(std::memory_order_acquire);
  }
}

Clock::Wake MonotonicClock::sleep_until_readable(Nanos deadline, std::span<const int> fds) noexcept {
  std::array<pollfd, 8> polled{};
  const std::size_t n = std::min(fds.size(), polled.size());
  for (std::size_t i = 0; i < n; ++i) polled[i] = pollfd{fds[i], POLLIN, 0};
  for (;;) {
    if (interrupted_.load(std::memory_order_acquire)) return Wake::interrupted;
    const Nanos t = now();
    if (t >= deadline) return Wake::deadline;
    const timespec timeout = to_timespec(std::min(deadline - t, kInterruptCheck));
    const int ready = ppoll(polled.data(), n, &timeout, nullptr);
    // POLLERR, POLLHUP and POLLNVAL wake too: the task's next run reads the
    // descriptor and reports what happened to it.
    if (ready > 0) return interrupted_.load(std::memory_order_acquire) ? Wake::interrupted : Wake::readable;
  }
}

void MonotonicClock::interrupt_sleepers() noexcept { interrupted_.store(true, std::memory_order_release); }
void MonotonicClock::resume_sleepers() noexcept { interrupted_.store(false, std::memory_order_release); }

bool SimulatedClock::sleep_until(Nanos deadline) noexcept {
  std::unique_lock lock(mutex_);
  sleepers_.fetch_add(1, std::memory_order_acq_rel);
  wake_.notify_all();  // lets waiters on sleepers() re-check
  wake_.wait(lock, [&] { return interrupted_ || now_.load(std::memory_order_acquire) >= deadline; });
  sleepers_.fetch_sub(1, std::memory_order_acq_rel);
  return !interrupted_;
}

void SimulatedClock::advance_to(Nanos t) noexcept {
  {
    std::lock_guard lock(mutex_);
    if (t > now_.load(std::memory_order_relaxed)) now_.store(t, std::memory_order_release);
  }
  wake_.notify_all();
}

void SimulatedClock::interrupt_sleepers() noexcept {
  {
    std::lock_guard lock(mutex_);
    interrupted_ = true;
  }
  wake_.notify_all();
}

void SimulatedClock::resume_sleepers() noexcept {
  std::lock_guard lock(mutex_);
  interrupted_ = false;
}

Nanos wall_clock_ns() noexcept {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<Nanos>(ts.tv_sec) * kNanosPerSecond + ts.tv_nsec;
}

}  // namespace trailnav
