#include "map_png.hpp"

#include <algorithm>
#include <cstdint>
#include <vector>

#include "png.hpp"

namespace trailnav::cli {

Status write_occupancy_png(const std::string& path, const nav_msgs_msg_dds__OccupancyGrid_& g) {
  const std::uint32_t w = g.info.width, h = g.info.height;
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(w) * h * 3);
  for (std::uint32_t row = 0; row < h; ++row) {
    const std::uint32_t y = h - 1 - row;
    for (std::uint32_t x = 0; x < w; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * w + x;
      const std::int8_t v = i < g.data._length ? g.data._buffer[i] : std::int8_t{-1};
      std::uint8_t* px = &rgb[(static_cast<std::size_t>(row) * w + x) * 3];
      if (v < 0) {
        px[0] = 60, px[1] = 70, px[2] = 90;
        continue;
      }
      const auto level = static_cast<std::uint8_t>(255 - (std::min<int>(v, 100) * 255) / 100);
      px[0] = px[1] = px[2] = level;
      if (v > 50) px[0] = px[1] = static_cast<std::uint8_t>(level / 2);
    }
  }
  return write_png(path, w, h, PngColor::rgb, rgb);
}

Status write_class_png(const std::string& path, std::uint32_t w, std::uint32_t h, const std::uint8_t* class_id) {
  static const std::uint8_t kColors[5][3] = {{150, 150, 150}, {150, 110, 60}, {120, 200, 90}, {30, 110, 40}, {150, 90, 170}};
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(w) * h * 3);
  for (std::uint32_t row = 0; row < h; ++row) {
    const std::uint32_t y = h - 1 - row;
    for (std::uint32_t x = 0; x < w; ++x) {
      const std::uint8_t c = class_id[static_cast<std::size_t>(y) * w + x];
      std::uint8_t* px = &rgb[(static_cast<std::size_t>(row) * w + x) * 3];
      if (c >= 5) {
        px[0] = 60, px[1] = 70, px[2] = 90;
        continue;
      }
      for (int k = 0; k < 3; ++k) px[k] = kColors[c][k];
    }
  }
  return write_png(path, w, h, PngColor::rgb, rgb);
}

Status write_terrain_png(const std::string& path, const trailnav_msgs_msg_dds__TerrainClassMap_& t) {
  const std::uint32_t w = t.info.width, h = t.info.height;
  std::vector<std::uint8_t> ids(static_cast<std::size_t>(w) * h, 255);
  std::copy(t.class_id._buffer, t.class_id._buffer + std::min<std::size_t>(ids.size(), t.class_id._length), ids.begin());
  return write_class_png(path, w, h, ids.data());
}

}  // namespace trailnav::cli
