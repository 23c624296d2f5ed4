// One inertial measurement as every IMU driver delivers it, in SI units:
// whatever the device sent (a field bit says what is present), with the
// host's receive time.
#pragma once

#include <array>
#include <cstdint>
#include <limits>

namespace trailnav::imu {

inline constexpr double kStandardGravity = 9.80665;  // m/s^2

enum ImuField : std::uint32_t {
  kPacketCounter = 1u << 0,
  kSampleTimeFine = 1u << 1,  // device clock, 10 kHz ticks
  kSampleTime = 1u << 2,      // device clock in seconds (line format)
  kOrientation = 1u << 3,     // quaternion, sensor to ENU
  kAcceleration = 1u << 4,    // specific force, sensor frame
  kRateOfTurn = 1u << 5,      // sensor frame
  kMagneticField = 1u << 6,
  kTemperature = 1u << 7,
  kStatusWord = 1u << 8,
  kFreeAcceleration = 1u << 9,  // ENU, gravity removed
};

struct ImuSample {
  std::int64_t time_ns = 0;  // host receive time (runtime/host_clock.hpp) or recording time
  std::uint32_t fields = 0;  // ImuField bits
  std::uint16_t packet_counter = 0;
  std::uint32_t sample_time_fine = 0;
  double sample_time = 0.0;                       // s
  std::array<double, 4> orientation{1, 0, 0, 0};  // w, x, y, z: rotates sensor vectors into ENU
  std::array<double, 3> acceleration{0, 0, 0};    // m/s^2
  std::array<double, 3> rate_of_turn{0, 0, 0};    // rad/s
  std::array<double, 3> magnetic_field{0, 0, 0};  // device units (Xsens: normalised to the calibration field)
  std::array<double, 3> free_acceleration{0, 0, 0};
  double temperature = std::numeric_limits<double>::quiet_NaN();  // degrees C
  std::uint32_t status_word = 0;

  bool has(ImuField f) const noexcept { return (fields & f) != 0; }
};

}  // namespace trailnav::imu
