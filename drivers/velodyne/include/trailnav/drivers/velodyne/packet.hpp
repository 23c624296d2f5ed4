// The Velodyne data and position packet formats (UDP payloads).
//
// Data packet, 1206 bytes: 12 blocks of 100 bytes — flag (0xFF 0xEE; 0xFF 0xDD
// for the HDL-64E's lower laser block), azimuth (uint16 LE, hundredths of a
// degree), 32 returns of distance (uint16 LE, counts) and intensity (uint8) —
// then the timestamp (uint32 LE, microseconds past the hour) and two factory
// bytes: return mode (0x37 strongest, 0x38 last, 0x39 dual) and product id.
//
// Position packet, 512 bytes: timestamp at byte 198 (uint32 LE, microseconds
// past the hour), PPS status at 202, and the GPS receiver's NMEA sentence
// (ASCII, NUL-padded) from byte 206.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>

#include "trailnav/drivers/velodyne/model.hpp"

namespace trailnav::velodyne {

inline constexpr std::size_t kDataPacketSize = 1206;
inline constexpr std::size_t kPositionPacketSize = 512;
inline constexpr int kBlocksPerPacket = 12;
inline constexpr int kReturnsPerBlock = 32;
inline constexpr std::size_t kBlockSize = 100;
inline constexpr std::size_t kTimestampOffset = 1200;
inline constexpr std::size_t kReturnModeOffset = 1204;
inline constexpr std::size_t kProductIdOffset = 1205;
inline constexpr std::uint16_t kUpperBlockFlag = 0xEEFF;  // as read little-endian
inline constexpr std::uint16_t kLowerBlockFlag = 0xDDFF;
inline constexpr int kMaxPointsPerPacket = kBlocksPerPacket * kReturnsPerBlock;
inline constexpr std::uint32_t kMicrosPerHour = 3'600'000'000u;

inline std::uint16_t read_u16(const std::uint8_t* p) noexcept {
  return static_cast<std::uint16_t>(p[0] | (p[1] << 8));
}
inline std::uint32_t read_u32(const std::uint8_t* p) noexcept {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}

// Microseconds from `previous` to `current` on the sensors' hour clock (the
// microseconds past the hour that every packet carries), taken as the
// nearest reading: in (-30 min, +30 min].
inline std::int64_t hour_clock_delta_us(std::uint32_t current, std::uint32_t previous) noexcept {
  constexpr std::int64_t kHour = kMicrosPerHour;
  std::int64_t d = static_cast<std::int64_t>(current) - static_cast<std::int64_t>(previous);
  if (d <= -kHour / 2) d += kHour;
  if (d > kHour / 2) d -= kHour;
  return d;
}

// The model a data packet comes from: its product id, or the HDL-64E when
// the packet has lower-block flags (the HDL-64E sends no product id).
// nullopt when the packet tells neither.
std::optional<Model> detect_model(std::span<const std::uint8_t> payload) noexcept;

enum class PpsStatus : std::uint8_t { absent = 0, synchronizing = 1, locked = 2, error = 3 };

struct PositionPacket {
  std::uint32_t timestamp_us = 0;  // microseconds past the hour
  PpsStatus pps = PpsStatus::absent;
  std::string_view nmea;  // the sentence, without padding or line end; views the packet
};

enum class PositionError : std::uint8_t { none, wrong_size, bad_timestamp, bad_pps };

// Decodes a position packet; the NMEA view points into `payload`.
PositionError decode_position_packet(std::span<const std::uint8_t> payload, PositionPacket& out) noexcept;

}  // namespace trailnav::velodyne
