// Little-endian bytes for trailnav's own file formats (the terrain and
// traversability models, the station): values appended to a byte vector and read back from
// a span with bounds checks, byte by byte, so a file means the same on any
// host. Not for real-time threads (the writer grows a vector).
#pragma once

#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <vector>

namespace trailnav::le {

inline void put_u16(std::vector<std::uint8_t>& out, std::uint16_t v) {
  for (int i = 0; i < 2; ++i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
inline void put_u32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
inline void put_u64(std::vector<std::uint8_t>& out, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
inline void put_f32(std::vector<std::uint8_t>& out, float f) {
  std::uint32_t v;
  std::memcpy(&v, &f, 4);
  put_u32(out, v);
}
inline void put_f64(std::vector<std::uint8_t>& out, double f) {
  std::uint64_t v;
  std::memcpy(&v, &f, 8);
  put_u64(out, v);
}

// Each read returns false, and reads nothing, when the bytes left are too few.
class Reader {
 public:
  explicit Reader(std::span<const std::uint8_t> d) : d_(d) {}
  bool u16(std::uint16_t& v) { return unsigned_of(v); }
  bool u32(std::uint32_t& v) { return unsigned_of(v); }
  bool u64(std::uint64_t& v) { return unsigned_of(v); }
  bool f32(float& f) {
    std::uint32_t v = 0;
    if (!u32(v)) return false;
    std::memcpy(&f, &v, 4);
    return true;
  }
  bool f64(double& f) {
    std::uint64_t v = 0;
    if (!u64(v)) return false;
    std::memcpy(&f, &v, 8);
    return true;
  }
  bool bytes(std::size_t n, std::string& s) {
    if (left() < n) return false;
    s.assign(reinterpret_cast<const char*>(d_.data() + pos_), n);
    pos_ += n;
    return true;
  }
  bool bytes(std::size_t n, std::vector<std::uint8_t>& v) {
    if (left() < n) return false;
    v.assign(d_.data() + pos_, d_.data() + pos_ + n);
    pos_ += n;
    return true;
  }
  std::size_t left() const noexcept { return d_.size() - pos_; }
  std::size_t pos() const noexcept { return pos_; }  // bytes read so far

 private:
  template <typename T>
  bool unsigned_of(T& v) {
    if (left() < sizeof(T)) return false;
    v = 0;
    for (std::size_t i = 0; i < sizeof(T); ++i) v = static_cast<T>(v | static_cast<T>(static_cast<T>(d_[pos_ + i]) << (8 * i)));
    pos_ += sizeof(T);
    return true;
  }
  std::span<const std::uint8_t> d_;
  std::size_t pos_ = 0;
};

}  // namespace trailnav::le
