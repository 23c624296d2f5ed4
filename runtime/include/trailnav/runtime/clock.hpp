// Injectable time. Tasks and drivers ask a Clock for the time and sleep on
// it, so the same code runs on the monotonic clock of the robot PC or on a
// simulated clock driven by a recording's timestamps.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <span>

namespace trailnav {

// Nanoseconds on a clock's own timeline (CLOCK_MONOTONIC for the real clock).
using Nanos = std::int64_t;

inline constexpr Nanos kNanosPerSecond = 1'000'000'000;
inline constexpr Nanos kNanosPerMilli = 1'000'000;
inline constexpr Nanos kNanosPerMicro = 1'000;

constexpr Nanos seconds_to_nanos(double s) noexcept { return static_cast<Nanos>(s * 1e9); }
constexpr double nanos_to_seconds(Nanos n) noexcept { return static_cast<double>(n) * 1e-9; }

// UTC now (CLOCK_REALTIME, ns since the epoch), as the system clock reads
// it: for tools and tests. trailnavd stamps on host time, which carries on
// across steps of this clock (runtime/host_clock.hpp).
Nanos wall_clock_ns() noexcept;
constexpr double nanos_to_millis(Nanos n) noexcept { return static_cast<double>(n) * 1e-6; }
constexpr double nanos_to_micros(Nanos n) noexcept { return static_cast<double>(n) * 1e-3; }

class Clock {
 public:
  virtual ~Clock() = default;
  virtual Nanos now() const noexcept = 0;
  // CPU time the calling thread has used, on this clock's scale: what a
  // task's budget is measured in. Only differences between two readings on
  // one thread mean anything.
  virtual Nanos thread_cpu_time() const noexcept = 0;
  // Sleeps until the clock reads at least `deadline`. Returns early (false)
  // once interrupt_sleepers() was called; true when the deadline was reached.
  virtual bool sleep_until(Nanos deadline) noexcept = 0;
  // Sleeps until `deadline` or until one of `fds` is readable (or reports an
  // error or hang-up), whichever comes first. A clock that cannot wait on
  // descriptors (wakes_on_descriptors() false) sleeps to the deadline.
  enum class Wake : std::uint8_t { deadline, readable, interrupted };
  virtual Wake sleep_until_readable(Nanos deadline, std::span<const int> fds) noexcept {
    (void)fds;
    return sleep_until(deadline) ? Wake::deadline : Wake::interrupted;
  }
  virtual bool wakes_on_descriptors() const noexcept { return false; }
  // Wakes every sleeper now and makes later sleeps return at once, until
  // resume_sleepers(); used to stop threads promptly.
  virtual void interrupt_sleepers() noexcept = 0;
  virtual void resume_sleepers() noexcept = 0;
};

// CLOCK_MONOTONIC with absolute-deadline sleeps (clock_nanosleep with
// TIMER_ABSTIME), so periodic deadlines never drift.
class MonotonicClock final : public Clock {
 public:
  Nanos now() const noexcept override;
  // CLOCK_THREAD_CPUTIME_ID.
  Nanos thread_cpu_time() const noexcept override;
  bool sleep_until(Nanos deadline) noexcept override;
  // ppoll(2) on the descriptors, in steps as sleep_until's (at most 8 descriptors).
  Wake sleep_until_readable(Nanos deadline, std::span<const int> fds) noexcept override;
  bool wakes_on_descriptors() const noexcept override { return true; }
  void interrupt_sleepers() noexcept override;
  void resume_sleepers() noexcept override;

 private:
  std::atomic<bool> interrupted_{false};
};

// Time advanced explicitly, for example by a replay to each recorded
// timestamp. Sleepers wake when the time reaches their deadline.
class SimulatedClock final : public Clock {
 public:
  explicit SimulatedClock(Nanos start = 0) noexcept : now_(start) {}
  Nanos now() const noexcept override { return now_.load(std::memory_order_acquire); }
  // Simulated work is time advanced while a task runs: all of it counts as CPU time.
  Nanos thread_cpu_time() const noexcept override { return now(); }
  bool sleep_until(Nanos deadline) noexcept override;
  void interrupt_sleepers() noexcept override;
  void resume_sleepers() noexcept override;

  // Moves time forward to `t` (never backwards) and wakes due sleepers.
  void advance_to(Nanos t) noexcept;
  void advance_by(Nanos dt) noexcept { advance_to(now() + dt); }
  // Number of threads currently blocked in sleep_until(); lets a test step
  // time only once its threads are waiting.
  int sleepers() const noexcept { return sleepers_.load(std::memory_order_acquire); }

 private:
  std::atomic<Nanos> now_;
  std::atomic<int> sleepers_{0};
  bool interrupted_ = false;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
};

}  // namespace trailnav
