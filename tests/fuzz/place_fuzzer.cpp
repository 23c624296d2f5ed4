// Fuzzes the place database (parse_place_database) and the image tunnel's
// assembler: any bytes give a database or a message, never a crash, and a
// database that loads writes back the same bytes (tried also with its
// checksum mended, to get past the CRC); the same bytes cut into datagrams
// never make the assembler publish a frame larger than it holds.
#include <zlib.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

#include "check.hpp"

#include "trailnav/drivers/camera/image_tunnel.hpp"
#include "trailnav/perception/place/database.hpp"

using namespace trailnav::perception::place;

namespace {

void parse_one(std::span<const std::uint8_t> bytes) {
  const LoadedPlaceDatabase loaded = parse_place_database(bytes, "fuzz.tnplace");
  check(loaded.database.has_value() != !loaded.error.empty());
  if (!loaded.database) return;
  const PlaceDatabase& db = *loaded.database;
  check(!db.entries.empty());
  for (const PlaceEntry& e : db.entries) check(e.code.size() == static_cast<std::size_t>(db.length));
  const std::vector<std::uint8_t> back = serialize_place_database(db);
  if (bytes[8] == 1) {
    // Version 1 is read and written as the current version: that one round-trips.
    const LoadedPlaceDatabase again = parse_place_database(back, "fuzz.tnplace");
    check(again.database.has_value());
    const std::vector<std::uint8_t> twice = serialize_place_database(*again.database);
    check(twice == back);
  } else {
    check(back.size() == bytes.size() && std::equal(back.begin(), back.end(), bytes.begin()));
  }
  check(db.whitening.rank == 0 || (db.whitening.mean.size() == db.entries.size() &&
                                   db.whitening.directions.size() == db.entries.size() * static_cast<std::size_t>(db.whitening.rank)));
}

void assemble(std::span<const std::uint8_t> bytes) {
  trailnav::drivers::camera::ImageAssembler a(64, 32);
  // Datagrams: each a length byte's worth of the input (up to 255 + 32).
  std::size_t at = 0;
  while (at < bytes.size()) {
    const std::size_t n = std::min<std::size_t>(bytes.size() - at - 1 + 1, 32u + bytes[at]);
    const std::span<const std::uint8_t> d = bytes.subspan(at, n);
    if (a.add(d)) check(a.frame().size() <= 64u * 32u && a.width() * a.height() <= 64 * 32);
    at += n;
  }
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
  assemble(std::span<const std::uint8_t>(data, size));
  return 0;
}
