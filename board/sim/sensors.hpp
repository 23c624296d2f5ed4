// Sensor byte formats the simulator writes: NMEA 0183 sentences, Velodyne
// position packets and Xsens MT binary (MTData2) messages.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>

#include "trailnav/drivers/velodyne/packet.hpp"

namespace trailnav::sim {

// One GNSS epoch as the receiver reports it.
struct GnssFix {
  std::int64_t utc_ns = 0;
  double lat = 0.0;        // degrees
  double lon = 0.0;
  double altitude = 0.0;   // m above mean sea level
  double separation = 47.0;  // m, geoid above ellipsoid
  double speed = 0.0;      // m/s over ground
  double course = 0.0;     // degrees true
  int quality = 1;         // GGA fix quality
  int satellites = 12;
  double hdop = 0.8;
  double sigma_lat = 0.0;  // m, GST error estimates
  double sigma_lon = 0.0;
  double sigma_alt = 0.0;
  double rms = 0.0;
};

// Complete sentences "$GPGGA,...*hh\r\n".
std::string nmea_gga(const GnssFix& fix, const char* talker = "GP");
std::string nmea_rmc(const GnssFix& fix, const char* talker = "GP");
std::string nmea_gst(const GnssFix& fix, const char* talker = "GP");
std::string nmea_vtg(const GnssFix& fix, const char* talker = "GP");

// A 512-byte Velodyne position packet: timestamp (us past the hour), PPS
// status and the RMC sentence, NUL-padded.
std::array<std::uint8_t, velodyne::kPositionPacketSize> position_packet(std::uint32_t us_past_hour, std::uint8_t pps,
                                                                         const std::string& rmc);

// One Xsens MTData2 sample: packet counter, sample time fine (10 kHz ticks),
// orientation quaternion (w, x, y, z; sensor to ENU), acceleration (m/s^2),
// rate of turn (rad/s) and status word, floats big-endian as the MT sends.
struct XsensSample {
  std::uint16_t counter = 0;
  std::uint32_t sample_time_fine = 0;
  std::array<float, 4> quaternion{1, 0, 0, 0};
  std::array<float, 3> acceleration{0, 0, 0};
  std::array<float, 3> rate_of_turn{0, 0, 0};
  std::uint32_t status = 0;
};

inline constexpr std::size_t kXsensMtData2Size = 73;  // preamble .. checksum
std::array<std::uint8_t, kXsensMtData2Size> xsens_mtdata2(const XsensSample& s);

}  // namespace trailnav::sim
