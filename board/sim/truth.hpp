// Ground truth of a simulated run, written to DIR/truth/ (format in
// docs/simulator.md): trajectory, terrain and obstacle rasters, true trail
// centrelines and junctions, the scenario used, and an overview picture.
#pragma once

#include <cstdint>
#include <string>

#include "motion.hpp"
#include "roads.hpp"
#include "scenario.hpp"
#include "trailnav/runtime/status.hpp"
#include "world.hpp"

namespace trailnav::sim {

Status write_truth(const std::string& directory, const Scenario& scenario, std::uint64_t seed, const World& world,
                   const RoadNetwork& roads, const Trajectory& trajectory, const GeoFrame& geo,
                   const std::vector<std::uint32_t>& sightings);

}  // namespace trailnav::sim
