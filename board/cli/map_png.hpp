// Map samples received over DDS as PNG pictures a person can look at, each
// with a panel giving its title, frame, size, a legend of its colours, a
// scale bar and north (figure.hpp). Not for real-time threads.
#pragma once

#include <array>
#include <string>
#include <string_view>
#include <vector>

#include "figure.hpp"
#include "nav_msgs.h"
#include "trailnav/runtime/status.hpp"
#include "trailnav_msgs.h"

namespace trailnav::cli {

// The colour of an occupancy value: unknown (< 0) blue-grey, free white to
// occupied black by percentage, above 50 % tinted blue.
Rgb occupancy_color(int percent) noexcept;
std::vector<LegendEntry> occupancy_legend();
// The terrain classes' colours (street grey, dirt brown, grass green,
// vegetation dark green, other purple; unknown blue-grey) and names.
Rgb terrain_color(std::uint8_t class_id) noexcept;  // >= 5: unknown
std::vector<LegendEntry> terrain_legend();

// A cost layer's colour (0 green, 50 yellow, 100 red; unknown blue-grey)
// and its legend, `what` naming the ends (e.g. "traversable", "not").
Rgb cost_color(int percent) noexcept;
std::vector<LegendEntry> cost_legend(std::string_view low, std::string_view high);

// North (+y) up.
Status write_occupancy_png(const std::string& path, const nav_msgs_msg_dds__OccupancyGrid_& grid,
                           std::string_view title = "obstacle map");
// A cost layer (trailnav/terrain_cost, trailnav/traversability): 0..100 on
// the green-to-red ramp, `note` saying what the cost is.
Status write_cost_png(const std::string& path, const nav_msgs_msg_dds__OccupancyGrid_& grid, std::string_view title,
                      std::string_view note, std::string_view low = "0: cheapest", std::string_view high = "100: dearest");
Status write_terrain_png(const std::string& path, const trailnav_msgs_msg_dds__TerrainClassMap_& map,
                         std::string_view title = "terrain classes");
// The same from class ids, row-major with row 0 the lowest y (>= 5: unknown).
Status write_class_png(const std::string& path, std::uint32_t width, std::uint32_t height, const std::uint8_t* class_id,
                       const MapFigure& figure);

}  // namespace trailnav::cli
