// trailnav's simple IMU line format, for bench rigs, microcontroller IMUs
// and hand-written tests (docs/imu.md):
//
//   $TNIMU,<time s>,<gx>,<gy>,<gz>,<ax>,<ay>,<az>[,<qw>,<qx>,<qy>,<qz>][*hh]
//
// Rate of turn in rad/s and specific force in m/s^2, both in the sensor
// frame; the optional quaternion rotates sensor vectors into ENU. The
// NMEA-style checksum (XOR of the bytes between '$' and '*') is checked when
// present. Lines are at most 160 characters (gps::LineFramer frames them).
// Pure: no allocation.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string_view>

#include "trailnav/drivers/imu/imu_sample.hpp"

namespace trailnav::imu {

enum class LineError : std::uint8_t {
  none,
  not_imu,          // not a $TNIMU line
  bad_checksum,
  field_count,      // neither 7 nor 11 numbers
  bad_number,       // a field that is not a finite decimal number, or a time beyond kMaxSampleTime
  bad_quaternion,   // norm far from 1
};
inline constexpr std::size_t kLineErrors = 6;
// The largest device clock a line may carry, s (about 31,700 years).
inline constexpr double kMaxSampleTime = 1e12;
const char* line_error_name(LineError e) noexcept;

// Fills time, rate of turn, acceleration and, when given, orientation;
// `sample.time_ns` is left as it was.
LineError parse_imu_line(std::string_view line, ImuSample& sample) noexcept;

// Writes one line with checksum and CR LF into `out`; returns its length (0
// when `out` is too small). Nine significant digits per number.
std::size_t format_imu_line(const ImuSample& sample, char* out, std::size_t capacity) noexcept;

}  // namespace trailnav::imu
