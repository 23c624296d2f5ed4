// Map samples received over DDS as PNG pictures a person can look at. Not
// for real-time threads.
#pragma once

#include <string>

#include "nav_msgs.h"
#include "trailnav/runtime/status.hpp"
#include "trailnav_msgs.h"

namespace trailnav::cli {

// Unknown blue-grey, free white to occupied black by percentage, obstacles
// (above 50 %) tinted; north (+y) up.
Status write_occupancy_png(const std::string& path, const nav_msgs_msg_dds__OccupancyGrid_& grid);
// Street grey, dirt brown, grass green, vegetation dark green, other purple, unknown blue-grey.
Status write_terrain_png(const std::string& path, const trailnav_msgs_msg_dds__TerrainClassMap_& map);
// The same from class ids, row-major with row 0 the lowest y (>= 5: unknown).
Status write_class_png(const std::string& path, std::uint32_t width, std::uint32_t height, const std::uint8_t* class_id);

}  // namespace trailnav::cli
