// Synthetic VLP-16 data packets for tests: a sensor turning at a given rate,
// every laser returning a fixed distance, timestamps from the firing timing.
#pragma once

#include <cstdint>
#include <vector>

#include "trailnav/drivers/velodyne/packet.hpp"

namespace trailnav::test {

class Vlp16Stream {
 public:
  explicit Vlp16Stream(double rpm, double start_azimuth_deg = 0.0, std::uint32_t start_us = 0)
      : rpm_(rpm), azimuth_(start_azimuth_deg * 100.0), time_us_(start_us) {}

  void set_rpm(double rpm) { rpm_ = rpm; }
  double time_us() const { return time_us_; }

  // The next packet: 12 blocks of two firing sequences, 110.592 us a block.
  std::vector<std::uint8_t> next(std::uint16_t raw_distance = 5000, std::uint8_t intensity = 40) {
    std::vector<std::uint8_t> p(velodyne::kDataPacketSize, 0);
    const double per_block = rpm_ / 60.0 * 36000.0 * 110.592e-6;  // hundredths of a degree
    for (int b = 0; b < 12; ++b) {
      const std::size_t base = static_cast<std::size_t>(b) * 100;
      put16(p, base, velodyne::kUpperBlockFlag);
      auto az = static_cast<int>(azimuth_ + per_block * b) % 36000;
      put16(p, base + 2, static_cast<std::uint16_t>(az));
      for (int k = 0; k < 32; ++k) {
        put16(p, base + 4 + static_cast<std::size_t>(k) * 3, raw_distance);
        p[base + 6 + static_cast<std::size_t>(k) * 3] = intensity;
      }
    }
    const auto ts = static_cast<std::uint32_t>(static_cast<std::uint64_t>(time_us_) % velodyne::kMicrosPerHour);
    p[1200] = static_cast<std::uint8_t>(ts);
    p[1201] = static_cast<std::uint8_t>(ts >> 8);
    p[1202] = static_cast<std::uint8_t>(ts >> 16);
    p[1203] = static_cast<std::uint8_t>(ts >> 24);
    p[1204] = 0x37;
    p[1205] = 0x22;
    azimuth_ += per_block * 12;
    while (azimuth_ >= 36000.0) azimuth_ -= 36000.0;
    time_us_ += 12 * 110.592;
    return p;
  }

 private:
  static void put16(std::vector<std::uint8_t>& p, std::size_t at, std::uint16_t v) {
    p[at] = static_cast<std::uint8_t>(v & 0xFF);
    p[at + 1] = static_cast<std::uint8_t>(v >> 8);
  }

  double rpm_;
  double azimuth_;  // hundredths of a degree
  double time_us_;
};

}  // namespace trailnav::test
