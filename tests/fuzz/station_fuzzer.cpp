// Fuzzes the station file (parse_station): any bytes give a station or a
// message, never a crash; a station that loads writes back the same bytes,
// and every body but the surroundings has its polygon. Each input is also
// tried with its checksum mended, so that the fuzzer gets past the CRC to
// the structure behind it.
#include <zlib.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

#include "check.hpp"

#include "trailnav/perception/registration/station_file.hpp"

using namespace trailnav::perception::registration;

namespace {

void parse_one(std::span<const std::uint8_t> bytes) {
  const LoadedStation loaded = parse_station(bytes, "fuzz.tnst");
  check(loaded.station.has_value() != !loaded.error.empty());
  if (!loaded.station) return;
  const StationFile& s = *loaded.station;
  check(!s.bodies.empty() && s.bodies.front().polygon.empty());
  for (std::size_t k = 1; k < s.bodies.size(); ++k) check(s.bodies[k].polygon.size() >= 3);
  const std::vector<std::uint8_t> back = serialize_station(s);
  check(back.size() == bytes.size() && std::equal(back.begin(), back.end(), bytes.begin()));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  parse_one(std::span<const std::uint8_t>(data, size));
  if (size >= 4) {
    std::vector<std::uint8_t> mended(data, data + size);
    const auto crc = static_cast<std::uint32_t>(crc32(0L, mended.data(), static_cast<uInt>(size - 4)));
    std::memcpy(mended.data() + size - 4, &crc, 4);
    parse_one(mended);
  }
  return 0;
}
