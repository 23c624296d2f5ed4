#include "trailnav/drivers/camera/image_tunnel.hpp"

#include <algorithm>
#include <cstring>

namespace trailnav::drivers::camera {
namespace {

void put16(std::uint8_t* p, std::uint16_t v) noexcept {
  p[0] = static_cast<std::uint8_t>(v);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}
void put32(std::uint8_t* p, std::uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
void put64(std::uint8_t* p, std::uint64_t v) noexcept {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
std::uint16_t get16(const std::uint8_t* p) noexcept { return static_cast<std::uint16_t>(p[0] | (p[1] << 8)); }
std::uint32_t get32(const std::uint8_t* p) noexcept {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}
std::uint64_t get64(const std::uint8_t* p) noexcept {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}

}  // namespace

std::size_t fragment_count(int width, int height) noexcept {
  if (width < 1 || height < 1) return 0;
  const std::size_t pixels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  return (pixels + kFragmentBytes - 1) / kFragmentBytes;
}

TunnelFragment encode_fragment(std::span<const std::uint8_t> grey, int width, int height, std::uint32_t sequence,
                               std::int64_t time_ns, std::size_t index) noexcept {
  TunnelFragment f;
  const std::size_t count = fragment_count(width, height);
  const std::size_t pixels = static_cast<std::size_t>(std::max(width, 0)) * static_cast<std::size_t>(std::max(height, 0));
  if (width > 65535 || height > 65535 || count == 0 || count > 65535 || index >= count || grey.size() < pixels) return f;
  std::uint8_t* p = f.bytes.data();
  std::memcpy(p, "TNIM", 4);
  p[4] = 1;
  p[5] = 0;
  put16(p + 6, static_cast<std::uint16_t>(index));
  put16(p + 8, static_cast<std::uint16_t>(count));
  put16(p + 10, static_cast<std::uint16_t>(width));
  put16(p + 12, static_cast<std::uint16_t>(height));
  put16(p + 14, 0);
  put32(p + 16, sequence);
  const std::size_t offset = index * kFragmentBytes;
  put32(p + 20, static_cast<std::uint32_t>(offset));
  put64(p + 24, static_cast<std::uint64_t>(time_ns));
  const std::size_t n = std::min(kFragmentBytes, pixels - offset);
  std::memcpy(p + kImageTunnelHeader, grey.data() + offset, n);
  f.size = kImageTunnelHeader + n;
  return f;
}

ImageAssembler::ImageAssembler(int max_width, int max_height)
    : capacity_(static_cast<std::size_t>(std::max(max_width, 1)) * static_cast<std::size_t>(std::max(max_height, 1))),
      pixels_(capacity_),
      have_((capacity_ + kFragmentBytes - 1) / kFragmentBytes) {}

bool ImageAssembler::add(std::span<const std::uint8_t> d) noexcept {
  ++counters_.datagrams;
  if (d.size() <= kImageTunnelHeader || std::memcmp(d.data(), "TNIM", 4) != 0 || d[4] != 1 || d[5] != 0) {
    ++counters_.malformed;
    return false;
  }
  const std::size_t index = get16(d.data() + 6);
  const std::size_t count = get16(d.data() + 8);
  const int width = get16(d.data() + 10);
  const int height = get16(d.data() + 12);
  const std::uint32_t sequence = get32(d.data() + 16);
  const std::size_t offset = get32(d.data() + 20);
  const auto time_ns = static_cast<std::int64_t>(get64(d.data() + 24));
  const std::size_t n = d.size() - kImageTunnelHeader;
  const std::size_t pixels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  // The fragment must be exactly the one its index names.
  if (width == 0 || height == 0 || count != fragment_count(width, height) || index >= count ||
      offset != index * kFragmentBytes || n != std::min(kFragmentBytes, pixels - offset)) {
    ++counters_.malformed;
    return false;
  }
  if (pixels > capacity_) {
    ++counters_.too_large;
    return false;
  }
  if (have_completed_ && static_cast<std::int32_t>(sequence - completed_) <= 0) {
    ++counters_.stale;  // a duplicate of a finished frame, or older
    return false;
  }
  if (assembling_ && sequence != sequence_) {
    // Sequence numbers wrap: a frame up to 2^31 ahead is newer.
    if (static_cast<std::int32_t>(sequence - sequence_) < 0) {
      ++counters_.stale;
      return false;
    }
    ++counters_.incomplete;
    assembling_ = false;
  }
  if (assembling_ && (width != width_ || height != height_ || time_ns != time_ns_)) {
    ++counters_.malformed;  // one frame number, two frames
    return false;
  }
  if (!assembling_) {
    assembling_ = true;
    sequence_ = sequence;
    time_ns_ = time_ns;
    width_ = width;
    height_ = height;
    count_ = count;
    received_ = 0;
    std::fill(have_.begin(), have_.begin() + static_cast<long>(count), 0);
  }
  if (have_[index] == 0) {
    have_[index] = 1;
    ++received_;
    std::memcpy(pixels_.data() + offset, d.data() + kImageTunnelHeader, n);
  }
  if (received_ < count_) return false;
  assembling_ = false;
  have_completed_ = true;
  completed_ = sequence_;
  ++counters_.frames;
  return true;
}

}  // namespace trailnav::drivers::camera
