// A CAN or CAN FD frame as SocketCAN encodes it, and trailnav's UDP tunnel
// for CAN frames on machines without a CAN interface (the replayer sends it,
// the CAN driver receives it). Pure: no I/O, no allocation.
//
// The tunnel datagram: a 24-byte header, then the data bytes.
//    0  "TNCN"            magic
//    4  u8 version (1)    u8 flags: bit 0 CAN FD, bit 1 FD bit-rate switch, bit 2 FD error state
//    6  u16 reserved (0)
//    8  i64 LE            the frame's time, ns since the epoch
//   16  u32 LE            id, SocketCAN encoding (EFF 0x80000000, RTR 0x40000000, ERR 0x20000000)
//   20  u8 length         data bytes that follow (0..8, CAN FD 0..64)
//   21  3 bytes reserved (0)
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

namespace trailnav::can {

inline constexpr std::uint32_t kEffFlag = 0x80000000u;  // 29-bit identifier
inline constexpr std::uint32_t kRtrFlag = 0x40000000u;  // remote transmission request
inline constexpr std::uint32_t kErrFlag = 0x20000000u;  // error frame (Linux error class in the id)
inline constexpr std::uint32_t kSffMask = 0x000007FFu;
inline constexpr std::uint32_t kEffMask = 0x1FFFFFFFu;

struct Frame {
  std::int64_t time_ns = 0;
  std::uint32_t id = 0;  // with the flags above
  std::uint8_t length = 0;
  bool fd = false;
  std::uint8_t fd_flags = 0;  // bit 0 bit-rate switch, bit 1 error state indicator
  std::array<std::uint8_t, 64> data{};

  bool extended() const noexcept { return (id & kEffFlag) != 0; }
  bool error() const noexcept { return (id & kErrFlag) != 0; }
  bool remote() const noexcept { return (id & kRtrFlag) != 0; }
  std::uint32_t identifier() const noexcept { return id & (extended() ? kEffMask : kSffMask); }
  std::span<const std::uint8_t> payload() const noexcept { return {data.data(), length}; }
};

inline constexpr std::uint16_t kDefaultTunnelPort = 29536;
inline constexpr std::size_t kTunnelHeader = 24;

struct TunnelDatagram {
  std::array<std::uint8_t, kTunnelHeader + 64> bytes{};
  std::size_t size = 0;
  std::span<const std::uint8_t> view() const noexcept { return {bytes.data(), size}; }
};
TunnelDatagram encode_tunnel(const Frame& frame) noexcept;
// False when the datagram is not a well-formed tunnel datagram.
bool decode_tunnel(std::span<const std::uint8_t> datagram, Frame& frame) noexcept;

}  // namespace trailnav::can
