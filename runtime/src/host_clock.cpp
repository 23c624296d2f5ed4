#include "trailnav/runtime/host_clock.hpp"

#include <ctime>

namespace trailnav {
namespace {

Nanos read(clockid_t id) noexcept {
  timespec ts{};
  ::clock_gettime(id, &ts);
  return static_cast<Nanos>(ts.tv_sec) * kNanosPerSecond + ts.tv_nsec;
}

// Readings further apart than this (the reader lost its core between them)
// say nothing about the difference: the step is left as it is.
constexpr Nanos kBracket = 200 * kNanosPerMicro;

struct Process {
  std::atomic<Nanos> anchor{0};  // 0 until anchored (REALTIME - MONOTONIC is never 0 on a running system)
  std::atomic<Nanos> step{0};
  std::atomic<std::uint64_t> steps{0};
};

Process& process() noexcept {
  static Process p;  // constant-initialised: no guard, no allocation
  return p;
}

// REALTIME read between two MONOTONIC readings; false when they are too far apart.
bool pair(Nanos& realtime, Nanos& monotonic) noexcept {
  const Nanos m0 = read(CLOCK_MONOTONIC);
  realtime = read(CLOCK_REALTIME);
  const Nanos m1 = read(CLOCK_MONOTONIC);
  monotonic = m0 + (m1 - m0) / 2;
  return m1 - m0 <= kBracket;
}

// The anchor, taken by the first caller (the one whose exchange succeeds).
Nanos anchor() noexcept {
  Process& p = process();
  Nanos a = p.anchor.load(std::memory_order_acquire);
  if (a != 0) return a;
  Nanos rt = 0, mono = 0;
  for (int i = 0; i < 8 && !pair(rt, mono); ++i) {
  }
  Nanos expected = 0;
  return p.anchor.compare_exchange_strong(expected, rt - mono, std::memory_order_acq_rel) ? rt - mono : expected;
}

// The step now: from a fresh pair of readings when they are close enough.
Nanos current_step(Nanos& realtime) noexcept {
  const Nanos a = anchor();
  Process& p = process();
  Nanos mono = 0;
  const bool good = pair(realtime, mono);
  Nanos step = p.step.load(std::memory_order_acquire);
  if (!good) return step;
  const Nanos next = HostClockRelation::next_step(a, realtime, mono, step);
  if (next != step && p.step.compare_exchange_strong(step, next, std::memory_order_acq_rel)) {
    p.steps.fetch_add(1, std::memory_order_relaxed);
    step = next;
  }  // a failed exchange: another thread saw the step first, and `step` holds its value
  return step;
}

}  // namespace

void host_clock_start() noexcept { anchor(); }

Nanos host_now_ns() noexcept {
  Nanos realtime = 0;
  const Nanos step = current_step(realtime);
  return realtime - step;
}

Nanos host_from_realtime(Nanos realtime_ns) noexcept {
  Nanos now = 0;
  return realtime_ns - current_step(now);
}

Nanos host_to_realtime(Nanos host_ns) noexcept {
  Nanos now = 0;
  return host_ns + current_step(now);
}

Nanos host_clock_step_ns() noexcept {
  Nanos now = 0;
  return current_step(now);
}

std::uint64_t host_clock_steps() noexcept { return process().steps.load(std::memory_order_relaxed); }

}  // namespace trailnav
