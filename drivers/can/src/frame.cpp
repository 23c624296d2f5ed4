#include "trailnav/drivers/can/frame.hpp"

#include <algorithm>
#include <cstring>

namespace trailnav::can {
namespace {

void put_u32(std::uint8_t* p, std::uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
std::uint32_t get_u32(const std::uint8_t* p) noexcept {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}

}  // namespace

TunnelDatagram encode_tunnel(const Frame& frame) noexcept {
  TunnelDatagram out;
  const std::size_t length = std::min<std::size_t>(frame.length, frame.fd ? 64 : 8);
  out.size = kTunnelHeader + length;
  std::uint8_t* d = out.bytes.data();
  d[0] = 'T';
  d[1] = 'N';
  d[2] = 'C';
  d[3] = 'N';
  d[4] = 1;
  d[5] = static_cast<std::uint8_t>((frame.fd ? 1 : 0) | (frame.fd ? (frame.fd_flags & 0x3) << 1 : 0));
  const auto t = static_cast<std::uint64_t>(frame.time_ns);
  put_u32(d + 8, static_cast<std::uint32_t>(t));
  put_u32(d + 12, static_cast<std::uint32_t>(t >> 32));
  put_u32(d + 16, frame.id);
  d[20] = static_cast<std::uint8_t>(length);
  std::memcpy(d + kTunnelHeader, frame.data.data(), length);
  return out;
}

bool decode_tunnel(std::span<const std::uint8_t> d, Frame& frame) noexcept {
  if (d.size() < kTunnelHeader || d[0] != 'T' || d[1] != 'N' || d[2] != 'C' || d[3] != 'N' || d[4] != 1) return false;
  const std::size_t length = d[20];
  const bool fd = (d[5] & 1) != 0;
  if (length > (fd ? 64u : 8u) || d.size() != kTunnelHeader + length) return false;
  frame = Frame{};
  frame.fd = fd;
  frame.fd_flags = static_cast<std::uint8_t>(fd ? (d[5] >> 1) & 0x3 : 0);
  frame.time_ns = static_cast<std::int64_t>(static_cast<std::uint64_t>(get_u32(d.data() + 8)) |
                                            (static_cast<std::uint64_t>(get_u32(d.data() + 12)) << 32));
  frame.id = get_u32(d.data() + 16);
  frame.length = static_cast<std::uint8_t>(length);
  std::memcpy(frame.data.data(), d.data() + kTunnelHeader, length);
  return true;
}

}  // namespace trailnav::can
