// Ground truth of a simulated run, written to DIR/truth/ (format in
// docs/simulator.md): trajectory, terrain and obstacle rasters, true trail
// centrelines and junctions, the scenario used, and an overview picture.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "motion.hpp"
#include "roads.hpp"
#include "scenario.hpp"
#include "trailnav/runtime/status.hpp"
#include "world.hpp"

namespace trailnav::sim {

// Per pixel of the obstacle raster: ms after the start + 1 of the first lidar
// return from a solid obstacle there; 0: never. Empty when no lidar was
// simulated.
//  - `any`: from any part of it (its top included), from any range;
//  - `side_hit`: from one of its vertical faces, within kSideSightingRange of
//    the sensor (the radius obstacle recall is scored in);
//  - `side`: of those, the returns that show the face (side_shown below).
inline constexpr double kSideSightingRange = 20.0;  // m
// A side return shows its face when it lies at least kSideSightingDepth below
// the obstacle's top, so that the face above it is itself an obstacle the
// recall scores (over tall grass, a ray may clip the top edge and show a few
// centimetres of face), and meets the face at kSideSightingAngle or more
// rather than running along it (a ray that grazes a face passes within
// millimetres of its corner, and the ring above and below it land metres
// away: no geometric detector sees a step there).
inline constexpr double kSideSightingDepth = 0.10;  // m
inline constexpr double kSideSightingAngle = 10.0;  // degrees between the ray and the face
bool side_shown(const Hit& hit) noexcept;

struct Sightings {
  std::vector<std::uint32_t> any;
  std::vector<std::uint32_t> side_hit;
  std::vector<std::uint32_t> side;
  // The first lidar return of any kind (ground, obstacle, vegetation) in each
  // pixel: what the lidar has seen, so what a map may call free.
  std::vector<std::uint32_t> returns;
};

Status write_truth(const std::string& directory, const Scenario& scenario, std::uint64_t seed, const World& world,
                   const RoadNetwork& roads, const Trajectory& trajectory, const GeoFrame& geo,
                   const Sightings& sightings);

}  // namespace trailnav::sim
