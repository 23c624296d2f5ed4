// The emergency-stop input, debounced. Pure: no I/O, no allocation.
//
// An e-stop must stop the robot at once and must not let it go on a bounce:
// the first sign of an active line engages the stop immediately, and the
// stop is released only after the line has stayed inactive for
// `release_debounce` seconds without interruption. Until the first level is
// known, or after the line is lost, the state is `unknown`, which counts as
// engaged (fail-safe).
#pragma once

#include <cstdint>

#include "trailnav/runtime/clock.hpp"

namespace trailnav::gpio {

enum class EstopState : std::uint8_t { unknown, engaged, released };
const char* estop_state_name(EstopState s) noexcept;

struct EstopCounters {
  std::uint64_t inputs = 0;       // levels or edges fed in
  std::uint64_t engagements = 0;  // transitions into engaged
  std::uint64_t releases = 0;     // transitions into released
  std::uint64_t bounces = 0;      // inactive spells cut short by a new activation
  std::uint64_t losses = 0;       // times the line was lost
};

class EstopDebouncer {
 public:
  explicit EstopDebouncer(double release_debounce_s = 0.2) noexcept
      : release_debounce_(seconds_to_nanos(release_debounce_s)) {}

  // The line's logical level (true: e-stop pressed) observed at time t.
  void input(bool active, Nanos t) noexcept;
  // The line can no longer be read: engaged until a level is seen again.
  void lost() noexcept;
  // Applies the release timer; returns the state at `now`.
  EstopState update(Nanos now) noexcept;

  EstopState state() const noexcept { return state_; }
  bool engaged() const noexcept { return state_ != EstopState::released; }
  // When the current state began (-1 while unknown).
  Nanos since() const noexcept { return since_; }
  // When update() releases the stop if the line stays inactive (-1: no
  // release is coming: released already, or the line active or unread).
  Nanos release_due() const noexcept {
    return state_ == EstopState::engaged && !raw_active_ && inactive_since_ >= 0 ? inactive_since_ + release_debounce_
                                                                                 : -1;
  }
  const EstopCounters& counters() const noexcept { return counters_; }

 private:
  void enter(EstopState s, Nanos t) noexcept;

  Nanos release_debounce_;
  EstopState state_ = EstopState::unknown;
  Nanos since_ = -1;
  bool raw_active_ = true;
  Nanos inactive_since_ = -1;  // start of the current inactive spell; -1 while active
  EstopCounters counters_;
};

}  // namespace trailnav::gpio
