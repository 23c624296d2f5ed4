// trailnav's UDP tunnel for camera frames, for a bench without a camera:
// `trailnav replay --image-tunnel` sends a recording's image streams through
// it and the camera driver (`camera.input: tunnel`) takes them as it takes a
// V4L2 device's frames. A grey frame is cut into fragments that fit a
// datagram; the receiver puts them together in a buffer sized at start-up.
// Pure: no I/O, no allocation after construction.
//
// The datagram: a 32-byte header, then up to kFragmentBytes of the frame's
// pixels (row-major, one byte each).
//    0  "TNIM"            magic
//    4  u8 version (1)
//    5  u8 format (0: grey)
//    6  u16 LE fragment   0 .. count - 1
//    8  u16 LE count      fragments of this frame
//   10  u16 LE width
//   12  u16 LE height
//   14  u16 LE reserved (0)
//   16  u32 LE sequence   the frame's number (the camera's)
//   20  u32 LE offset     of this fragment's first pixel in the frame
//   24  i64 LE time       the frame's stamp, ns since the epoch
//   32  pixels
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace trailnav::drivers::camera {

inline constexpr std::uint16_t kDefaultImageTunnelPort = 29538;
inline constexpr std::size_t kImageTunnelHeader = 32;
inline constexpr std::size_t kFragmentBytes = 1408;  // header + pixels ≤ 1440: one Ethernet frame

struct TunnelFragment {
  std::array<std::uint8_t, kImageTunnelHeader + kFragmentBytes> bytes{};
  std::size_t size = 0;
  std::span<const std::uint8_t> view() const noexcept { return {bytes.data(), size}; }
};

// How many fragments a frame of width x height takes.
std::size_t fragment_count(int width, int height) noexcept;
// Fragment `index` of a grey frame; size 0 when the index or the frame's
// size is out of range (1..65535 a side, at most 65535 fragments).
TunnelFragment encode_fragment(std::span<const std::uint8_t> grey, int width, int height, std::uint32_t sequence,
                               std::int64_t time_ns, std::size_t index) noexcept;

struct AssemblerCounters {
  std::uint64_t datagrams = 0;
  std::uint64_t malformed = 0;    // not a tunnel datagram, or inconsistent with itself
  std::uint64_t too_large = 0;    // a frame larger than the assembler holds
  std::uint64_t incomplete = 0;   // frames given up with fragments missing (a newer frame began)
  std::uint64_t stale = 0;        // fragments of a frame already completed or older than the one being assembled
  std::uint64_t frames = 0;       // completed
};

class ImageAssembler {
 public:
  // For frames of at most max_width x max_height.
  ImageAssembler(int max_width, int max_height);

  // One datagram; true when it completed a frame (then frame() holds it until
  // the next call).
  bool add(std::span<const std::uint8_t> datagram) noexcept;
  std::span<const std::uint8_t> frame() const noexcept { return {pixels_.data(), static_cast<std::size_t>(width_ * height_)}; }
  int width() const noexcept { return width_; }
  int height() const noexcept { return height_; }
  std::uint32_t sequence() const noexcept { return sequence_; }
  std::int64_t time_ns() const noexcept { return time_ns_; }
  const AssemblerCounters& counters() const noexcept { return counters_; }

 private:
  std::size_t capacity_;
  std::vector<std::uint8_t> pixels_;
  std::vector<std::uint8_t> have_;  // per fragment
  bool assembling_ = false;
  bool have_completed_ = false;
  std::uint32_t completed_ = 0;  // the last completed frame's sequence
  std::uint32_t sequence_ = 0;
  std::int64_t time_ns_ = 0;
  int width_ = 0, height_ = 0;
  std::size_t count_ = 0, received_ = 0;
  AssemblerCounters counters_;
};

}  // namespace trailnav::drivers::camera
