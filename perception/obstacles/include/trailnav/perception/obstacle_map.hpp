// The robot-centred obstacle map (thesis §7.1.3, §7.3): a rolling grid
// perpendicular to gravity, moved with the odometry, updated each
// revolution point by point with the recursive log-odds rule (Eq. 7.10).
//
// Every cell is unknown until a point with features lands in it; unknown is
// never reported as free. PW maps (Dirac model) keep a cell occupied for
// `dirac_hold` seconds after its last obstacle point, whatever else is seen
// there in that time (the thesis' workaround for 0/1 probabilities). After
// that a free point clears it, at once when it lies below the obstacle
// (`dirac_clear_depth`), at the obstacle's height only after
// `dirac_top_hold` (MapParams).
#pragma once

#include <algorithm>

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>

#include "trailnav/perception/cloud.hpp"
#include "trailnav/perception/obstacle_models.hpp"
#include "trailnav/perception/terrain_class_map.hpp"
#include "trailnav/runtime/rolling_grid.hpp"

namespace trailnav::perception {

// One cell: the log-odds of an obstacle, NaN while no point has landed in
// it. Four bytes, so that the cells a revolution touches (one cache miss per
// point where the points spread out) take half the cache lines they took
// with a separate `seen` field.
struct ObstacleCell {
  float logit = std::numeric_limits<float>::quiet_NaN();
  bool known() const noexcept { return !std::isnan(logit); }
};

enum class CellState : std::uint8_t { unknown, free, occupied };

// Where the terrain class of a point comes from.
struct TerrainSource {
  const TerrainClassMap* map = nullptr;  // adaptive: this map (may be null: all cells unknown)
  bool fixed = false;                    // true: every cell is `fixed_class`
  TerrainClass fixed_class = TerrainClass::street;
  TerrainClass unknown_class = TerrainClass::other;  // cells `map` does not know

  // The class of a point whose cell the map does not give: the fixed class,
  // or the class for unknown terrain.
  TerrainClass fallback() const noexcept { return fixed ? fixed_class : unknown_class; }
  // The map to read classes from: none with a fixed class.
  const TerrainClassMap* adaptive_map() const noexcept { return fixed ? nullptr : map; }
  // The terrain map's cell under (x, y) when it knows it, else null (the
  // point then takes fallback()).
  const TerrainCell* known_cell(double x, double y) const noexcept {
    const TerrainClassMap* m = adaptive_map();
    if (m == nullptr) return nullptr;
    const TerrainCell* c = m->grid().find(x, y);
    return c != nullptr && c->known ? c : nullptr;
  }
};

struct MapCounters {
  std::uint64_t updates = 0;        // points integrated
  std::uint64_t outside_map = 0;    // points beyond the map's edge
  std::uint64_t unknown_terrain = 0;  // points on cells without a terrain class
  std::uint64_t cells_cleared = 0;  // by moving the map
};

class ObstacleMap {
 public:
  ObstacleMap(const MapParams& params, FusionModel model);

  FusionModel model() const noexcept { return model_; }
  const MapParams& params() const noexcept { return params_; }
  const RollingGrid<ObstacleCell>& grid() const noexcept { return grid_; }

  // Re-centres on the robot and integrates one revolution's points:
  // begin_revolution(), then integrate_columns() over every column.
  void integrate(const RevolutionCloud& cloud, const ObstacleModels& models, const TerrainSource& terrain) noexcept;
  // In parts: begin_revolution() once the cloud's revolution has begun
  // (re-centres on the robot at its first firing), then the points of
  // columns [first, end), ring by ring, in the order the parts come.
  void begin_revolution(const RevolutionCloud& cloud, const ObstacleModels& models) noexcept;
  void integrate_columns(const RevolutionCloud& cloud, const ObstacleModels& models, const TerrainSource& terrain,
                         int first, int end) noexcept;

  // P(o) of a cell; NaN when unknown.
  float probability(const ObstacleCell& c) const noexcept {
    return c.known() ? logistic(c.logit) : std::numeric_limits<float>::quiet_NaN();
  }
  CellState state(const ObstacleCell& c) const noexcept {
    if (!c.known()) return CellState::unknown;
    return c.logit > occupied_logit_ ? CellState::occupied : CellState::free;
  }
  std::uint32_t revolutions() const noexcept { return revolution_; }
  // Every cell unknown again (the odometry lost track of the robot: what was
  // mapped no longer fits where it is). Keeps the origin.
  void forget() noexcept {
    grid_.fill(ObstacleCell{});
    occupancy_.fill(std::int8_t{-1});
    hits_.fill(DiracHit{});
  }
  const MapCounters& counters() const noexcept { return counters_; }

  // Row-major copy from the map's origin (row 0 = lowest y): 0..100 percent
  // occupancy, -1 unknown (the ROS OccupancyGrid convention). The percentages
  // come from a table over the clamped log-odds (within 1 of the exact value)
  // and are kept up to date, cell by cell, as points arrive, so a snapshot
  // is a copy (the obstacle task takes one every revolution).
  void export_occupancy(std::span<std::int8_t> out) const noexcept;

 private:
  template <FusionModel M>
  void integrate_points(const RevolutionCloud& cloud, const ObstacleModels& models, const TerrainSource& terrain, int first,
                        int end) noexcept;

  static constexpr int kPercentSteps = 1024;
  std::int8_t percent(float logit) const noexcept {
    const int step = std::clamp(static_cast<int>((logit - params_.logit_min) * percent_scale_ + 0.5f), 0, kPercentSteps);
    return percent_[static_cast<std::size_t>(step)];
  }

  MapParams params_;
  FusionModel model_;
  std::array<std::int8_t, kPercentSteps + 1> percent_{};
  float percent_scale_;
  RollingGrid<ObstacleCell> grid_;
  RollingGrid<std::int8_t> occupancy_;  // percent() of every cell, -1 unknown; moves with grid_
  // PW: per cell, the revolution of its last obstacle point (0: none) and
  // the highest obstacle point since the cell turned occupied (odometry-frame
  // z); moves with grid_. Apart from the cells so that the cells stay 4 bytes
  // for every model (one cell per point is a cache miss: the smaller, the
  // fewer).
  struct DiracHit {
    std::uint32_t revolution = 0;
    float top = 0.0f;
  };
  RollingGrid<DiracHit> hits_;
  float occupied_logit_;
  float prior_logit_;
  std::uint32_t revolution_ = 0;
  std::uint32_t hold_revolutions_ = 0;
  std::array<std::uint32_t, kTerrainClasses> top_hold_revolutions_{};  // per terrain class
  std::int64_t first_ns_ = 0;
  std::int64_t last_ns_ = 0;
  MapCounters counters_;
};

}  // namespace trailnav::perception
