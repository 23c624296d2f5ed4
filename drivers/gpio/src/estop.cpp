#include "trailnav/drivers/gpio/estop.hpp"

namespace trailnav::gpio {

const char* estop_state_name(EstopState s) noexcept {
  switch (s) {
    case EstopState::unknown: return "unknown";
    case EstopState::engaged: return "engaged";
    case EstopState::released: return "released";
  }
  return "?";
}

void EstopDebouncer::enter(EstopState s, Nanos t) noexcept {
  if (s == state_) return;
  if (s == EstopState::engaged) ++counters_.engagements;
  if (s == EstopState::released) ++counters_.releases;
  state_ = s;
  since_ = s == EstopState::unknown ? -1 : t;
}

void EstopDebouncer::input(bool active, Nanos t) noexcept {
  ++counters_.inputs;
  if (active) {
    // A new activation during an inactive spell that had not yet released
    // the stop is a bounce.
    if (!raw_active_ && state_ != EstopState::released && inactive_since_ >= 0) ++counters_.bounces;
    raw_active_ = true;
    inactive_since_ = -1;
    enter(EstopState::engaged, t);
    return;
  }
  if (state_ == EstopState::unknown) {
    // The first level seen is inactive: still engaged until it has been
    // inactive for the debounce time (a line read once is not yet trusted).
    enter(EstopState::engaged, t);
  }
  if (raw_active_ || inactive_since_ < 0) inactive_since_ = t;
  raw_active_ = false;
  update(t);
}

void EstopDebouncer::lost() noexcept {
  if (state_ != EstopState::unknown) ++counters_.losses;
  raw_active_ = true;
  inactive_since_ = -1;
  enter(EstopState::unknown, 0);
}

EstopState EstopDebouncer::update(Nanos now) noexcept {
  if (state_ == EstopState::engaged && !raw_active_ && inactive_since_ >= 0 &&
      now - inactive_since_ >= release_debounce_) {
    enter(EstopState::released, inactive_since_ + release_debounce_);
  }
  return state_;
}

}  // namespace trailnav::gpio
