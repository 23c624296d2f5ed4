#include "trailnav/perception/terrain_class_map.hpp"

#include <algorithm>
#include <cmath>

namespace trailnav::perception {

namespace {
constexpr std::array<std::string_view, kTerrainClasses> kNames = {"street", "dirt", "grass", "vegetation", "other"};
}

std::string_view terrain_class_name(TerrainClass c) noexcept { return kNames[static_cast<std::size_t>(c)]; }

std::optional<TerrainClass> parse_terrain_class(std::string_view name) noexcept {
  for (std::size_t i = 0; i < kNames.size(); ++i) {
    if (kNames[i] == name) return static_cast<TerrainClass>(i);
  }
  return std::nullopt;
}

void TerrainCell::set(const std::array<float, kTerrainClasses>& distribution) noexcept {
  float sum = 0.0f;
  for (float v : distribution) sum += v;
  std::size_t best_index = 0;
  for (std::size_t t = 0; t < p.size(); ++t) {
    p[t] = sum > 0.0f ? distribution[t] / sum : 1.0f / static_cast<float>(kTerrainClasses);
    if (p[t] > p[best_index]) best_index = t;
  }
  best = static_cast<TerrainClass>(best_index);
  known = true;
}

TerrainClassMap::TerrainClassMap(TerrainMapShape shape)
    : shape_(shape), grid_(shape.size_x, shape.size_y, shape.resolution) {}

void TerrainClassMap::copy_from(const TerrainClassMap& other) noexcept {
  grid_.assign_from(other.grid_);
  sequence = other.sequence;
  time_ns = other.time_ns;
  clock_offset_ns = other.clock_offset_ns;
}

void TerrainClassMap::export_classes(std::span<std::uint8_t> class_id, std::span<std::uint8_t> confidence) const noexcept {
  const CellIndex o = grid_.origin();
  std::size_t k = 0;
  for (std::int32_t y = 0; y < grid_.size_y(); ++y) {
    for (std::int32_t x = 0; x < grid_.size_x(); ++x, ++k) {
      if (k >= class_id.size() || k >= confidence.size()) return;
      const TerrainCell& c = grid_.at({o.x + x, o.y + y});
      if (!c.known) {
        class_id[k] = kUnknownClass;
        confidence[k] = 0;
        continue;
      }
      class_id[k] = static_cast<std::uint8_t>(c.best);
      const float p = c.p[static_cast<std::size_t>(c.best)];
      confidence[k] = static_cast<std::uint8_t>(std::lround(255.0f * std::clamp(p, 0.0f, 1.0f)));
    }
  }
}

}  // namespace trailnav::perception
