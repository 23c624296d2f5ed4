// Messages of a real Xsens MTi-300 (firmware 1.8.2), recorded with Xsens' MT
// Manager and published as test vectors by a public robotics project, and
// helpers to write them as Xbus bytes.
#pragma once

#include <cstdint>
#include <sstream>
#include <string>
#include <vector>

#include "trailnav/drivers/imu/xsens.hpp"

namespace trailnav::test {

// "FA FF 30" -> bytes.
inline std::vector<std::uint8_t> hex(const std::string& text) {
  std::vector<std::uint8_t> out;
  std::istringstream in(text);
  std::string byte;
  while (in >> byte) out.push_back(static_cast<std::uint8_t>(std::stoul(byte, nullptr, 16)));
  return out;
}

// A complete message with header and checksum.
inline std::vector<std::uint8_t> xbus(std::uint8_t mid, const std::vector<std::uint8_t>& payload) {
  std::vector<std::uint8_t> out(payload.size() + 8);
  out.resize(imu::encode_xbus(mid, payload, out));
  return out;
}

// MTData2 payloads: counter, sample time fine, quaternion and status word ...
inline const char* kMti300QuaternionOnly =
    "10 20 02 46 82 10 60 04 01 C4 FC 3E 20 10 10 3F 71 CE 6C BE A5 6B CF 3C 61 3B D8 BD 69 1D 25 E0 20 04 00 40 00 03";
// ... and eleven items: quaternion, acceleration, delta v, free acceleration,
// rate of turn, delta q, magnetic field, pressure, status word.
inline const char* kMti300AllFields =
    "10 20 02 A6 55 10 60 04 00 57 47 2E 20 10 10 3F 7F 7D C4 BC 10 10 7D 3B A1 57 70 BD 7E C6 56 40 20 0C BD A2 1A "
    "F8 BE 2A 8E 96 41 1D 27 A2 40 10 0C B9 4F C8 00 B9 DA 24 00 3C C9 28 80 40 30 0C 3C 02 C8 9C 3C 35 F6 C8 3C DB "
    "0C 00 80 20 0C BB B1 7D 81 BB 96 32 00 3C 01 E8 41 80 30 10 3F 80 00 00 B6 E3 30 01 B6 C0 40 00 37 26 48 00 C0 "
    "20 0C BE 99 9C 24 3F B6 1B 56 3F 16 6A EB 30 10 04 00 01 86 DE E0 20 04 00 40 00 03";

}  // namespace trailnav::test
