#include "map_png.hpp"

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <vector>

namespace trailnav::cli {
namespace {

constexpr Rgb kUnknown{60, 70, 90};
constexpr Rgb kClassColors[5] = {{150, 150, 150}, {150, 110, 60}, {120, 200, 90}, {30, 110, 40}, {150, 90, 170}};
constexpr const char* kClassNames[5] = {"street", "dirt", "grass", "vegetation", "other"};

std::string grid_note(std::uint32_t w, std::uint32_t h, float resolution) {
  char text[96];
  std::snprintf(text, sizeof text, "%u x %u cells of %.2f m", w, h, static_cast<double>(resolution));
  return text;
}

std::string stamp_note(const char* frame, std::int32_t sec, std::uint32_t nanosec) {
  char text[128];
  std::snprintf(text, sizeof text, "frame %s, stamp %d.%03u s", frame != nullptr && frame[0] != '\0' ? frame : "(none)", sec,
                nanosec / 1000000u);
  return text;
}

}  // namespace

Rgb occupancy_color(int v) noexcept {
  if (v < 0) return kUnknown;
  const auto level = static_cast<std::uint8_t>(255 - (std::min(v, 100) * 255) / 100);
  if (v > 50) return {static_cast<std::uint8_t>(level / 2), static_cast<std::uint8_t>(level / 2), level};
  return {level, level, level};
}

std::vector<LegendEntry> occupancy_legend() {
  return {{occupancy_color(-1), "unknown (not seen)"},
          {occupancy_color(0), "free, 0 %"},
          {occupancy_color(25), "25 %"},
          {occupancy_color(50), "50 %"},
          {occupancy_color(75), "obstacle, 75 %"},
          {occupancy_color(100), "obstacle, 100 %"}};
}

Rgb terrain_color(std::uint8_t c) noexcept { return c < 5 ? kClassColors[c] : kUnknown; }

std::vector<LegendEntry> terrain_legend() {
  std::vector<LegendEntry> legend;
  for (std::uint8_t c = 0; c < 5; ++c) legend.push_back({kClassColors[c], kClassNames[c]});
  legend.push_back({kUnknown, "unknown"});
  return legend;
}

namespace {
// An occupancy grid's cells as colours (north up: row 0 of the picture is
// the grid's last row) with its panel: stamp, size, `note`, `legend`.
template <typename Color>
Status write_grid_png(const std::string& path, const nav_msgs_msg_dds__OccupancyGrid_& g, std::string_view title,
                      const std::string& note, std::vector<LegendEntry> legend, const Color& color) {
  const std::uint32_t w = g.info.width, h = g.info.height;
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(w) * h * 3);
  for (std::uint32_t row = 0; row < h; ++row) {
    const std::uint32_t y = h - 1 - row;
    for (std::uint32_t x = 0; x < w; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * w + x;
      const Rgb c = color(i < g.data._length ? g.data._buffer[i] : -1);
      std::uint8_t* px = &rgb[(static_cast<std::size_t>(row) * w + x) * 3];
      px[0] = c.r, px[1] = c.g, px[2] = c.b;
    }
  }
  MapFigure figure;
  figure.title = std::string(title);
  figure.notes = {stamp_note(g.header.frame_id, g.header.stamp.sec, g.header.stamp.nanosec),
                  grid_note(w, h, g.info.resolution), note};
  figure.legend = std::move(legend);
  figure.metres_per_pixel = g.info.resolution;
  return write_map_figure(path, rgb, static_cast<int>(w), static_cast<int>(h), figure);
}
}  // namespace

Status write_occupancy_png(const std::string& path, const nav_msgs_msg_dds__OccupancyGrid_& g, std::string_view title) {
  return write_grid_png(path, g, title, "occupancy in percent, north up", occupancy_legend(), occupancy_color);
}

Rgb cost_color(int v) noexcept {
  if (v < 0) return kUnknown;
  // Green (0) through yellow (50) to red (100).
  const int c = std::min(v, 100);
  if (c <= 50) return {static_cast<std::uint8_t>(40 + (c * 200) / 50), 190, 60};
  return {240, static_cast<std::uint8_t>(190 - ((c - 50) * 170) / 50), 60};
}

std::vector<LegendEntry> cost_legend(std::string_view low, std::string_view high) {
  return {{cost_color(0), std::string(low)},
          {cost_color(25), "25"},
          {cost_color(50), "50"},
          {cost_color(75), "75"},
          {cost_color(100), std::string(high)},
          {kUnknown, "unknown (no evidence)"}};
}

Status write_cost_png(const std::string& path, const nav_msgs_msg_dds__OccupancyGrid_& g, std::string_view title,
                      std::string_view note, std::string_view low, std::string_view high) {
  return write_grid_png(path, g, title, std::string(note) + ", north up", cost_legend(low, high), cost_color);
}

Status write_class_png(const std::string& path, std::uint32_t w, std::uint32_t h, const std::uint8_t* class_id,
                       const MapFigure& figure) {
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(w) * h * 3);
  for (std::uint32_t row = 0; row < h; ++row) {
    const std::uint32_t y = h - 1 - row;
    for (std::uint32_t x = 0; x < w; ++x) {
      const Rgb c = terrain_color(class_id[static_cast<std::size_t>(y) * w + x]);
      std::uint8_t* px = &rgb[(static_cast<std::size_t>(row) * w + x) * 3];
      px[0] = c.r, px[1] = c.g, px[2] = c.b;
    }
  }
  return write_map_figure(path, rgb, static_cast<int>(w), static_cast<int>(h), figure);
}

Status write_terrain_png(const std::string& path, const trailnav_msgs_msg_dds__TerrainClassMap_& t, std::string_view title) {
  const std::uint32_t w = t.info.width, h = t.info.height;
  std::vector<std::uint8_t> ids(static_cast<std::size_t>(w) * h, 255);
  std::copy(t.class_id._buffer, t.class_id._buffer + std::min<std::size_t>(ids.size(), t.class_id._length), ids.begin());
  MapFigure figure;
  figure.title = std::string(title);
  figure.notes = {stamp_note(t.header.frame_id, t.header.stamp.sec, t.header.stamp.nanosec),
                  grid_note(w, h, t.info.resolution), "the random forest's class per cell, north up"};
  figure.legend = terrain_legend();
  // The names the message carries, when it names the five classes.
  if (t.class_names._length == 5 && t.class_names._buffer != nullptr) {
    for (std::size_t c = 0; c < 5; ++c) {
      const char* name = t.class_names._buffer[c];
      if (name != nullptr && name[0] != '\0') figure.legend[c].label = name;
    }
  }
  figure.metres_per_pixel = t.info.resolution;
  return write_class_png(path, w, h, ids.data(), figure);
}

}  // namespace trailnav::cli
