// trailnavd's one time base, steady across steps of the host's clock.
//
// Everything the daemon stamps (packets, serial bytes, CAN frames, readings,
// poses, maps) is on the host's UTC, CLOCK_REALTIME, minus how far that clock
// has been stepped since the daemon started:
//
//     host time = CLOCK_REALTIME - step,   step = (REALTIME - MONOTONIC) - anchor,
//
// where anchor is REALTIME - MONOTONIC when the process started. Both clocks
// are slewed alike by NTP, so their difference changes only when the system
// clock is *set*: chrony's or ntpd's `makestep`, a clock set from GPS at boot,
// an operator's `date -s`, a leap second. Without a step, host time is
// CLOCK_REALTIME to the nanosecond; after one, it carries on from where it was,
// so readings taken on either side stay in order and the right distance apart
// (the odometry does not see a gap of the step's size, and a revolution is not
// placed with poses from seconds away).
//
// What the kernel stamps on CLOCK_REALTIME (socket timestamps) comes in through
// from_realtime(); what leaves the daemon (message stamps, DDS source
// timestamps) goes out through to_realtime(), on the system clock of that
// moment, so that other nodes see stamps on the clock they read themselves.
//
// A change of the difference under `tolerance` (1 ms) is not a step: the two
// clocks cannot be read at one instant, and a reader preempted between them
// would otherwise see one.
#pragma once

#include <atomic>
#include <cstdint>

#include "trailnav/runtime/clock.hpp"

namespace trailnav {

// The arithmetic, on given readings (pure: the tests drive it).
class HostClockRelation {
 public:
  static constexpr Nanos kTolerance = kNanosPerMilli;

  // `realtime` and `monotonic` read at (about) one instant.
  HostClockRelation(Nanos realtime, Nanos monotonic) noexcept : anchor_(realtime - monotonic) {}

  // The step a pair of readings shows, given the one taken so far: the new
  // difference when it moved more than the tolerance, else the old one. What
  // update() and the process's clock (host_now_ns() and the rest) both use.
  static constexpr Nanos next_step(Nanos anchor, Nanos realtime, Nanos monotonic, Nanos step) noexcept {
    const Nanos raw = realtime - monotonic - anchor;
    return raw - step > kTolerance || step - raw > kTolerance ? raw : step;
  }

  // Takes a new pair of readings; returns the step since the anchor.
  Nanos update(Nanos realtime, Nanos monotonic) noexcept {
    const Nanos next = next_step(anchor_, realtime, monotonic, step_);
    if (next != step_) ++steps_;
    step_ = next;
    return step_;
  }
  Nanos step() const noexcept { return step_; }
  std::uint64_t steps() const noexcept { return steps_; }

  Nanos from_realtime(Nanos realtime) const noexcept { return realtime - step_; }
  Nanos to_realtime(Nanos host) const noexcept { return host + step_; }

 private:
  Nanos anchor_;
  Nanos step_ = 0;
  std::uint64_t steps_ = 0;
};

// The process's host clock: the relation anchored at the first call (the
// daemon calls host_clock_start() in main, before any thread). Lock-free and
// allocation-free; safe on real-time threads.
void host_clock_start() noexcept;
// Host time now (see above).
Nanos host_now_ns() noexcept;
// A CLOCK_REALTIME time (a kernel timestamp, a GPS receiver's UTC) in host time.
Nanos host_from_realtime(Nanos realtime_ns) noexcept;
// A host time on the system clock as it reads now (for stamps that leave).
Nanos host_to_realtime(Nanos host_ns) noexcept;
// How far the system clock has been stepped since start, and how many times.
Nanos host_clock_step_ns() noexcept;
std::uint64_t host_clock_steps() noexcept;

}  // namespace trailnav
