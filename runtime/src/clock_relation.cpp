#include "trailnav/runtime/clock_relation.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>

namespace trailnav {

void ClockRelation::add(std::int64_t sensor_ns, std::int64_t reference_ns) noexcept {
  const std::int64_t d = reference_ns - sensor_ns;
  ++state_.pairs;
  if (state_.valid && (sensor_ns < last_sensor_ns_ - options_.tolerance_ns ||
                       (state_.settled && d < state_.offset_ns - options_.tolerance_ns))) {
    // A step: a new provisional start from this message.
    ++state_.steps;
    state_.settled = false;
    state_.offset_ns = d;
    open_window(sensor_ns, d);
  }
  last_sensor_ns_ = sensor_ns;
  if (window_open_ && (sensor_ns < window_start_ns_ || sensor_ns - window_start_ns_ >= options_.window_ns)) {
    close_window();
  }
  if (!window_open_) open_window(sensor_ns, d);
  window_min_ = std::min(window_min_, d);
  window_max_ = std::max(window_max_, d);
  window_sum_ += static_cast<double>(d - window_first_);
  ++window_count_;
  if (!state_.settled) {
    // Provisional: the running minimum of the first window.
    state_.offset_ns = state_.valid ? std::min(state_.offset_ns, d) : d;
    state_.valid = true;
  }
}

void ClockRelation::open_window(std::int64_t sensor_ns, std::int64_t d) noexcept {
  window_open_ = true;
  window_start_ns_ = sensor_ns;
  window_min_ = window_max_ = window_first_ = d;
  window_sum_ = 0.0;
  window_count_ = 0;
}

void ClockRelation::close_window() noexcept {
  window_open_ = false;
  if (window_count_ == 0) return;
  ++state_.windows;
  const double mean = static_cast<double>(window_first_) + window_sum_ / static_cast<double>(window_count_);
  state_.spread_ns = static_cast<std::int64_t>(std::llround(mean - static_cast<double>(window_min_)));
  state_.max_spread_ns = window_max_ - window_min_;
  if (!state_.settled) {
    state_.settled = true;
    state_.offset_ns = window_min_;
    return;
  }
  if (std::llabs(window_min_ - state_.offset_ns) > options_.tolerance_ns) {
    state_.offset_ns = window_min_;
    ++state_.steps;
  }
}

}  // namespace trailnav
