// Fuzzes the station file (parse_station): any bytes give a station or a
// message, never a crash; a station that loads writes back the same bytes,
// and every body but the surroundings has its polygon.
#include <algorithm>
#include <cstdint>
#include <span>
#include <vector>

#include "check.hpp"

#include "trailnav/perception/registration/station_file.hpp"

using namespace trailnav::perception::registration;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::uint8_t> bytes(data, size);
  const LoadedStation loaded = parse_station(bytes, "fuzz.tnst");
  check(loaded.station.has_value() != !loaded.error.empty());
  if (!loaded.station) return 0;
  const StationFile& s = *loaded.station;
  check(!s.bodies.empty() && s.bodies.front().polygon.empty());
  for (std::size_t k = 1; k < s.bodies.size(); ++k) check(s.bodies[k].polygon.size() >= 3);
  const std::vector<std::uint8_t> back = serialize_station(s);
  check(back.size() == size && std::equal(back.begin(), back.end(), bytes.begin()));
  return 0;
}
