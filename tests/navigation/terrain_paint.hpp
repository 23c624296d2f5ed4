// Terrain-class maps whose trail the test knows: every cell of the map, moved
// to be centred on (cx, cy), is street where on_street(x, y) of its centre
// (map frame) holds, else grass; 0.9 of the class, the rest spread evenly.
#pragma once

#include <cstdint>
#include <functional>

#include "trailnav/perception/terrain_class_map.hpp"

namespace trailnav::test {

inline void paint_terrain(perception::TerrainClassMap& map, double cx, double cy,
                          const std::function<bool(double, double)>& on_street) {
  auto& grid = map.grid();
  grid.move_to(cx, cy);
  const CellIndex o = grid.origin();
  for (std::int32_t y = o.y; y < o.y + grid.size_y(); ++y) {
    for (std::int32_t x = o.x; x < o.x + grid.size_x(); ++x) {
      const auto c = grid.cell_center({x, y});
      std::array<float, perception::kTerrainClasses> p{};
      const bool street = on_street(c.x, c.y);
      p[static_cast<std::size_t>(street ? perception::TerrainClass::street : perception::TerrainClass::grass)] = 0.9f;
      for (auto& v : p) v += 0.025f;
      grid.at({x, y}).set(p);
    }
  }
}

}  // namespace trailnav::test
