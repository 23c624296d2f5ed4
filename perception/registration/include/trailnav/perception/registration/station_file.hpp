// A taught station on disk (`trailnav station teach --out`): its bodies —
// the surroundings first, then each object with the polygon it was marked
// by — and each body's reference points in the station frame. The
// covariances, normals and trees are worked out again when it is loaded
// (station_from_file, station.hpp), so the file holds only what was measured
// and marked.
//
// Layout, little-endian: "TNSTATN" and a zero byte; u32 version (1); u16
// length and the station's name; u32 bodies (1 to 64); per body: u16 length
// and its name (1 to 64 bytes), u32 polygon corners (0 for the
// surroundings, else 3 to 1024) and as many f64 pairs (x, y, m), u32 points
// (at most 4,194,304) and as many f32 triples (x, y, z, m); then the CRC-32
// (zlib's) of every byte before it. Anything else is refused with what is
// wrong and where.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "trailnav/perception/registration/cloud.hpp"

namespace trailnav::perception::registration {

inline constexpr std::uint32_t kStationFileVersion = 1;
inline constexpr std::size_t kStationMaxBodies = 64;
inline constexpr std::size_t kStationMaxName = 64;
inline constexpr std::size_t kStationMaxCorners = 1024;
inline constexpr std::size_t kStationMaxPoints = 1u << 22;

struct StationBodyFile {
  std::string name;
  std::vector<Eigen::Vector2d> polygon;  // empty for the surroundings (body 0)
  std::vector<Point> points;             // station frame
};

struct StationFile {
  std::string name;
  std::vector<StationBodyFile> bodies;  // bodies[0]: the surroundings
};

std::vector<std::uint8_t> serialize_station(const StationFile& s);

struct LoadedStation {
  std::optional<StationFile> station;
  std::string error;  // with `what` (a path) in it
};
LoadedStation parse_station(std::span<const std::uint8_t> bytes, std::string_view what);
LoadedStation load_station(const std::string& path);
// Written whole or not at all (AtomicFile): "" or what went wrong.
std::string save_station(const StationFile& s, const std::string& path);

}  // namespace trailnav::perception::registration
