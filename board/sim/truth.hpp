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
// return from a solid obstacle there (`any`: its top included, from any
// range; `side`: from one of its vertical faces, within kSideSightingRange of
// the sensor, the radius obstacle recall is scored in); 0: never. Empty when
// no lidar was simulated.
inline constexpr double kSideSightingRange = 20.0;  // m
struct Sightings {
  std::vector<std::uint32_t> any;
  std::vector<std::uint32_t> side;
};

Status write_truth(const std::string& directory, const Scenario& scenario, std::uint64_t seed, const World& world,
                   const RoadNetwork& roads, const Trajectory& trajectory, const GeoFrame& geo,
                   const Sightings& sightings);

}  // namespace trailnav::sim
