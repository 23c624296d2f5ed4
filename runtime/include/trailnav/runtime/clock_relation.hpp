// How one sensor's clock relates to trailnavd's reference clock.
//
// trailnavd stamps everything on one time base: host time, the host's
// CLOCK_REALTIME (UTC since the epoch) minus the steps the system clock took
// since start (runtime/host_clock.hpp), the clock every driver takes its
// receive times on; its stamps go out on the CLOCK_REALTIME a ROS 2 node's
// `now()` reads.
// A sensor that keeps its own clock (a Velodyne locked to GPS PPS, a replayed
// recording's GPS time, an IMU's sample counter) hands over times on that
// clock; this class relates them to the reference from pairs of
// (sensor time, host receive time) of the same message:
//
//   d_i = t_receive,i - t_sensor,i = offset + delay_i,   delay_i >= 0
//
// The transport only ever delays a message, so the smallest d over a window
// is the offset plus the shortest delay (on loopback or a direct Ethernet
// link, tens to hundreds of microseconds). The offset in use is *held*: it is
// re-anchored to a window's minimum only when that minimum moved more than
// `tolerance` away (the clocks drifted apart), so that ordinary jitter never
// moves a stamp and replays of a recording stay deterministic. Until the
// first window closes the running minimum is used (provisional). Two kinds of
// step are taken at once, as a new provisional start: a message received
// more than `tolerance` before the held offset allows (impossible unless a
// clock was stepped), and a sensor time that goes back by more than
// `tolerance` (GPS time arrived, a recording looped).
//
// Uncertainty: the spread of d above its minimum over the last window (its
// mean and its largest value), i.e. how late a typical message is. The
// shortest delay itself stays in the offset as a bias no receiver can
// measure; docs/dds.md ("One clock") gives its size per link.
//
// Pure: no clock reads, no allocation; the caller gives both times.
#pragma once

#include <cstdint>

namespace trailnav {

struct ClockRelationOptions {
  std::int64_t window_ns = 2'000'000'000;  // a window's length (sensor time)
  std::int64_t tolerance_ns = 2'000'000;   // re-anchor when a window's minimum moved further than this
};

struct ClockRelationState {
  bool valid = false;           // at least one pair seen
  bool settled = false;         // a whole window seen: the offset is held
  std::int64_t offset_ns = 0;   // reference = sensor + offset
  std::int64_t spread_ns = 0;   // mean of d - min(d) over the last closed window
  std::int64_t max_spread_ns = 0;  // largest d - min(d) over the last closed window
  std::uint64_t pairs = 0;
  std::uint64_t steps = 0;      // re-anchorings after the first window (clock steps)
  std::uint64_t windows = 0;
};

class ClockRelation {
 public:
  explicit ClockRelation(ClockRelationOptions options = {}) noexcept : options_(options) {}

  // One message: its time on the sensor's clock and its host receive time.
  void add(std::int64_t sensor_ns, std::int64_t reference_ns) noexcept;
  // The reference time of a sensor time (the sensor time itself before any pair).
  std::int64_t to_reference(std::int64_t sensor_ns) const noexcept { return sensor_ns + state_.offset_ns; }
  std::int64_t offset_ns() const noexcept { return state_.offset_ns; }
  const ClockRelationState& state() const noexcept { return state_; }

 private:
  void open_window(std::int64_t sensor_ns, std::int64_t d) noexcept;
  void close_window() noexcept;

  ClockRelationOptions options_;
  ClockRelationState state_;
  // The open window.
  bool window_open_ = false;
  std::int64_t window_start_ns_ = 0;
  std::int64_t window_min_ = 0;
  // d relative to the window's first d, summed in double (only its mean
  // is reported), and the largest d.
  std::int64_t window_first_ = 0;
  std::int64_t window_max_ = 0;
  double window_sum_ = 0.0;
  std::int64_t window_count_ = 0;
  std::int64_t last_sensor_ns_ = 0;
};

}  // namespace trailnav
