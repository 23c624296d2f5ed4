// The terrain classes and the terrain-class map as the obstacle fusion reads
// it (thesis §7.2.3, §7.3).
//
// The map is a robot-centred rolling grid (default 300 x 300 cells of 0.2 m)
// whose cells hold a distribution over the five classes. A cell nobody has
// classified yet holds no distribution (`known` false); the fusion then uses
// its configured class for unknown terrain. The terrain thread owns and
// updates one map and hands copies to readers through a Mailbox; readers
// never see a map being written.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>

#include "trailnav/runtime/rolling_grid.hpp"

namespace trailnav::perception {

inline constexpr int kTerrainClasses = 5;

enum class TerrainClass : std::uint8_t { street = 0, dirt = 1, grass = 2, vegetation = 3, other = 4 };

std::string_view terrain_class_name(TerrainClass c) noexcept;
std::optional<TerrainClass> parse_terrain_class(std::string_view name) noexcept;

struct TerrainCell {
  std::array<float, kTerrainClasses> p{};  // P(t | f_1..f_n); sums to 1 when known
  TerrainClass best = TerrainClass::other;  // argmax of p
  bool known = false;
  // The learnt traversability layer's P(trav | f_1..n) for this robot
  // (thesis ch. 6, perception/traversability), written by the terrain step
  // when trailnavd runs one; negative: no evidence (or no layer).
  float traversable = -1.0f;

  // Sets the distribution (normalised here) and its argmax.
  void set(const std::array<float, kTerrainClasses>& distribution) noexcept;
};

// The cost layer of §8.1.2 for one cell: the class costs (indexed by
// TerrainClass) weighted by the cell's distribution; `unknown_cost` for a
// cell not classified yet.
inline float terrain_cost(const TerrainCell& c, const std::array<float, kTerrainClasses>& cost, float unknown_cost) noexcept {
  if (!c.known) return unknown_cost;
  float sum = 0.0f;
  for (std::size_t t = 0; t < cost.size(); ++t) sum += c.p[t] * cost[t];
  return sum;
}

// The learnt layer's cost of a cell for the subgoal aligner: 1 − P(trav),
// `unknown_cost` where the layer has no evidence.
inline float traversability_cost(const TerrainCell& c, float unknown_cost) noexcept {
  return c.traversable < 0.0f ? unknown_cost : 1.0f - c.traversable;
}

struct TerrainMapShape {
  std::int32_t size_x = 300;
  std::int32_t size_y = 300;
  double resolution = 0.2;
};

class TerrainClassMap {
 public:
  explicit TerrainClassMap(TerrainMapShape shape = {});

  const TerrainMapShape& shape() const noexcept { return shape_; }
  RollingGrid<TerrainCell>& grid() noexcept { return grid_; }
  const RollingGrid<TerrainCell>& grid() const noexcept { return grid_; }

  // The cell under a world point, or nullptr outside the map or not known.
  const TerrainCell* known_cell(double x, double y) const noexcept {
    const TerrainCell* c = grid_.find(x, y);
    return c != nullptr && c->known ? c : nullptr;
  }

  // Copies another map of the same shape (no allocation).
  void copy_from(const TerrainClassMap& other) noexcept;

  // Row-major from the origin (row 0 = lowest y), size_x * size_y entries:
  // the best class (kUnknownClass where not known) and its probability
  // scaled to 0..255. No allocation.
  static constexpr std::uint8_t kUnknownClass = 255;
  void export_classes(std::span<std::uint8_t> class_id, std::span<std::uint8_t> confidence) const noexcept;

  std::uint64_t sequence = 0;   // snapshot number
  std::int64_t time_ns = 0;     // when the snapshot was taken (the revolution's end, lidar clock)
  std::int64_t clock_offset_ns = 0;  // reference clock minus the lidar's at that revolution

 private:
  TerrainMapShape shape_;
  RollingGrid<TerrainCell> grid_;
};

}  // namespace trailnav::perception
