// A place database on disk (`trailnav place-map RECORDING --out DB`): the
// images of an earlier drive as compact descriptors (similarity.hpp), each
// with the pose the robot had when it was taken, and the descriptor's
// settings, so that the robot describes its frames the same way
// (trailnavd's place task refuses a camera whose frames would be described
// otherwise).
//
// Layout, little-endian: "TNPLACE" and a zero byte; u32 version (1); the
// descriptor: u16 frame width, u16 frame height (what the descriptor was
// computed on, after the camera's reduction), u16 patch, u16 cells, u16 bins,
// f32 clip, u32 descriptor length (must equal patches x cells² x bins); u16
// length and the source's name (the recording, at most 256 bytes); u32 images
// (1 to 1,000,000); per image: i64 time (ns since the epoch), f64 x, y, yaw
// (m, m, rad: the map frame the poses came in), f64 latitude, longitude
// (degrees, NaN when unknown), then the code's bytes (its length is worked
// out again when loaded);
// then the CRC-32 (zlib's) of every byte before it. Anything else is refused
// with what is wrong and where.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "trailnav/perception/place/hog.hpp"
#include "trailnav/perception/place/online.hpp"

namespace trailnav::perception::place {

inline constexpr std::uint32_t kPlaceFileVersion = 2;  // 1 is still read (no whitening)
inline constexpr int kPlaceMaxRank = 1024;
inline constexpr std::size_t kPlaceMaxImages = 1'000'000;
inline constexpr std::size_t kPlaceMaxSource = 256;

struct PlaceEntry {
  std::int64_t time_ns = 0;
  double x = 0.0, y = 0.0, yaw = 0.0;
  double lat = 0.0, lon = 0.0;  // NaN when unknown
  float norm = 0.0f;            // the code's length (computed, not stored)
  std::vector<std::uint8_t> code;
};

struct PlaceDatabase {
  int width = 0, height = 0;  // the frames the descriptors were computed on
  HogConfig hog;              // patch resolved (never 0)
  int length = 0;             // descriptor values
  std::string source;
  std::vector<PlaceEntry> entries;
  Whitening whitening;  // rank 0: none (Eq. 5.3 online)
};

std::vector<std::uint8_t> serialize_place_database(const PlaceDatabase& db);

struct LoadedPlaceDatabase {
  std::optional<PlaceDatabase> database;
  std::string error;  // with `what` (a path) in it
};
LoadedPlaceDatabase parse_place_database(std::span<const std::uint8_t> bytes, std::string_view what);
LoadedPlaceDatabase load_place_database(const std::string& path);
// Written whole or not at all (AtomicFile): "" or what went wrong.
std::string save_place_database(const PlaceDatabase& db, const std::string& path);

}  // namespace trailnav::perception::place
