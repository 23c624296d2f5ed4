#include "trailnav/drivers/gpio/line_tunnel.hpp"

#include <cstring>

namespace trailnav::gpio {

bool valid_line_name(std::string_view name) noexcept {
  if (name.empty() || name.size() > kMaxLineName) return false;
  for (char c : name) {
    if (c <= ' ' || c > '~') return false;
  }
  return true;
}

TunnelDatagram encode_tunnel(std::string_view line, bool value, std::int64_t time_ns) noexcept {
  TunnelDatagram d;
  if (!valid_line_name(line)) return d;
  std::memcpy(d.bytes.data(), "TNGP", 4);
  d.bytes[4] = 1;
  d.bytes[5] = value ? 1 : 0;
  d.bytes[6] = static_cast<std::uint8_t>(line.size());
  d.bytes[7] = 0;
  const auto t = static_cast<std::uint64_t>(time_ns);
  for (std::size_t i = 0; i < 8; ++i) d.bytes[8 + i] = static_cast<std::uint8_t>(t >> (8 * i));
  std::memcpy(d.bytes.data() + kTunnelHeader, line.data(), line.size());
  d.size = kTunnelHeader + line.size();
  return d;
}

bool decode_tunnel(std::span<const std::uint8_t> datagram, LineLevel& level) noexcept {
  if (datagram.size() < kTunnelHeader + 1 || std::memcmp(datagram.data(), "TNGP", 4) != 0) return false;
  if (datagram[4] != 1 || datagram[5] > 1 || datagram[7] != 0) return false;
  const std::size_t n = datagram[6];
  if (n == 0 || n > kMaxLineName || datagram.size() != kTunnelHeader + n) return false;
  const std::string_view name(reinterpret_cast<const char*>(datagram.data() + kTunnelHeader), n);
  if (!valid_line_name(name)) return false;
  std::uint64_t t = 0;
  for (std::size_t i = 0; i < 8; ++i) t |= static_cast<std::uint64_t>(datagram[8 + i]) << (8 * i);
  level = LineLevel{};
  level.time_ns = static_cast<std::int64_t>(t);
  level.value = datagram[5] == 1;
  std::memcpy(level.name.data(), name.data(), n);
  return true;
}

}  // namespace trailnav::gpio
