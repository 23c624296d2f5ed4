// Absolute time for Velodyne packets.
//
// A packet carries only microseconds past the hour. How that becomes a time
// (ns since the Unix epoch, UTC) depends on what the sensor knows:
//
//  - GPS: the sensor's clock is locked to a GPS receiver's PPS, and its
//    position packets carry the receiver's NMEA RMC sentence. The counter is
//    then UTC's own position in the hour; the hour comes from the sentence's
//    date and time, and later packets continue from it across the top of
//    the hour. The host clock is not used at all.
//  - host: no GPS time (yet). The counter is unwrapped into a continuous
//    sensor time and mapped onto the host clock with the smallest host-minus-
//    sensor offset seen over a window (the transport only ever delays a
//    packet), renewed every window so that drift between the clocks is
//    followed.
//
// The times handed out never decrease, with one exception: the switch from
// host to GPS time, when GPS time first becomes available, may step back
// once (counted in steps()); otherwise a host clock that runs ahead would
// freeze every timestamp until GPS time caught up.
#pragma once

#include <cstdint>
#include <optional>
#include <string_view>

#include "trailnav/drivers/velodyne/packet.hpp"

namespace trailnav::velodyne {

// The UTC time (ns since the epoch) of an NMEA RMC sentence ($GPRMC, $GNRMC,
// ...) with a valid checksum, date and time; nullopt otherwise.
std::optional<std::int64_t> rmc_utc_ns(std::string_view sentence) noexcept;

enum class TimeSource : std::uint8_t { none, host, gps };

const char* time_source_name(TimeSource source) noexcept;

struct SensorClockOptions {
  std::int64_t offset_window_ns = 5'000'000'000;  // host mode: offset renewal period
  bool use_gps = true;                            // take GPS time from position packets when locked
};

class SensorClock {
 public:
  explicit SensorClock(SensorClockOptions options = {}) noexcept : options_(options) {}

  // A position packet. Switches to GPS time
  // when its PPS is locked and its sentence gives a valid time.
  void on_position_packet(const PositionPacket& packet) noexcept;

  // The time of a data packet's first firing, given its microseconds past the
  // hour and the host's receive time (host time, runtime/host_clock.hpp: the kernel timestamp).
  std::int64_t resolve(std::uint32_t us_past_hour, std::int64_t host_receive_ns) noexcept;

  TimeSource source() const noexcept { return source_; }
  // Host mode: the current host-minus-sensor offset.
  std::int64_t host_offset_ns() const noexcept { return offset_ns_; }
  std::uint64_t hour_rollovers() const noexcept { return rollovers_; }
  std::uint64_t clamped() const noexcept { return clamped_; }  // outputs held back to stay monotonic
  std::uint64_t steps() const noexcept { return steps_; }      // switches from host to GPS time
  // The counter went back by more than kStepBackUs: the sensor's clock was
  // set back (a PPS or GPS re-lock), not a late packet. Times follow it down.
  std::uint64_t steps_back() const noexcept { return steps_back_; }
  static constexpr std::int64_t kStepBackUs = 500'000;

 private:
  // The sensor counter unwrapped into continuous microseconds.
  std::int64_t unwrap(std::uint32_t us_past_hour) noexcept;
  std::int64_t monotonic(std::int64_t t) noexcept;

  SensorClockOptions options_;
  TimeSource source_ = TimeSource::none;
  // Unwrapping.
  bool have_counter_ = false;
  std::uint32_t last_counter_ = 0;
  std::int64_t last_continuous_us_ = 0;
  std::uint64_t rollovers_ = 0;
  // GPS mode: continuous sensor microseconds -> UTC ns.
  std::int64_t gps_epoch_ns_ = 0;
  // Host mode.
  std::int64_t offset_ns_ = 0;
  std::int64_t window_min_ns_ = 0;
  std::int64_t window_start_ns_ = 0;
  bool have_offset_ = false;
  bool window_open_ = false;
  // Monotonic output.
  std::int64_t last_out_ns_ = 0;
  std::uint64_t clamped_ = 0;
  std::uint64_t steps_ = 0;
  std::uint64_t steps_back_ = 0;
};

}  // namespace trailnav::velodyne
