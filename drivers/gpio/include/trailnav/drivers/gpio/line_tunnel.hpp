// trailnav's UDP tunnel for GPIO line levels, for machines without a GPIO
// chip: the replayer sends the recorded e-stop levels through it, and the
// GPIO driver can mirror its outputs (heartbeat, status) into it. Pure: no
// I/O, no allocation.
//
// The datagram: a 16-byte header, then the line name.
//    0  "TNGP"           magic
//    4  u8 version (1)
//    5  u8 value         the line's logical level, 0 or 1
//    6  u8 name length   1..kMaxLineName
//    7  u8 reserved (0)
//    8  i64 LE           time of the level, ns since the epoch
//   16  name bytes       the line's name (printable ASCII, no spaces)
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

namespace trailnav::gpio {

inline constexpr std::uint16_t kDefaultTunnelPort = 29537;
inline constexpr std::size_t kTunnelHeader = 16;
inline constexpr std::size_t kMaxLineName = 31;

struct LineLevel {
  std::int64_t time_ns = 0;
  std::array<char, kMaxLineName + 1> name{};  // NUL-terminated
  bool value = false;
  std::string_view line() const noexcept { return {name.data()}; }
};

// A name the tunnel and the recording can carry: 1..31 printable characters, no spaces.
bool valid_line_name(std::string_view name) noexcept;

struct TunnelDatagram {
  std::array<std::uint8_t, kTunnelHeader + kMaxLineName> bytes{};
  std::size_t size = 0;
  std::span<const std::uint8_t> view() const noexcept { return {bytes.data(), size}; }
};
// An empty datagram (size 0) when the name is not valid.
TunnelDatagram encode_tunnel(std::string_view line, bool value, std::int64_t time_ns) noexcept;
// False when the datagram is not a well-formed tunnel datagram.
bool decode_tunnel(std::span<const std::uint8_t> datagram, LineLevel& level) noexcept;

}  // namespace trailnav::gpio
