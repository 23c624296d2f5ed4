// The terrain analysis of thesis §7.2: lidar points registered with the local
// odometry pose into a rolling grid of running sums, a feature per cell every
// d metres driven (terrain_features.hpp), the random forest's P(t | f) and the
// Bayes update of the terrain-class map (Eq. 7.15) with classified cells
// frozen and re-opened (§7.2.3). Everything is allocated by create().
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>

#include "trailnav/perception/cloud.hpp"
#include "trailnav/perception/random_forest.hpp"
#include "trailnav/perception/terrain_class_map.hpp"
#include "trailnav/perception/terrain_config.hpp"
#include "trailnav/perception/terrain_features.hpp"

namespace trailnav::perception {

struct TerrainCounters {
  std::uint64_t revolutions = 0;
  std::uint64_t points = 0;           // registered in a cell
  std::uint64_t outside = 0;          // aligned, but outside the grid
  std::uint64_t out_of_range = 0;     // aligned, but outside [min_range, max_range] of the terrain config
  std::uint64_t steps = 0;            // classification steps (every d metres)
  std::uint64_t features = 0;         // computed and classified
  std::uint64_t frozen_skipped = 0;   // cells with enough points that were already classified
  std::uint64_t frozen = 0;           // cells that became classified
  std::uint64_t reopened = 0;         // classified cells opened again after reopen_after
  std::uint64_t classified_cells = 0; // at the last step
  std::uint64_t known_cells = 0;      // at the last step
  AlignCounters align;
};

// What an offline tool sees of each cell at a step (training data, scores).
struct TerrainObservation {
  CellIndex cell;
  double x = 0.0, y = 0.0;            // the cell's centre, odometry frame
  std::uint32_t points = 0;
  FeatureVector feature{};
  ClassDistribution likelihood{};     // the forest's P(t | f) (uniform without a forest)
  const TerrainCell* estimate = nullptr;  // the map's cell after the update
  bool updated = false;               // false: the cell was classified (frozen) and kept its state
  std::int64_t time_ns = 0;
};

class TerrainObserver {
 public:
  virtual ~TerrainObserver() = default;
  virtual void observe(const TerrainObservation& o) = 0;
};

// Told, at each classification step, about every cell whose running sums the
// step takes (at least min_points points since the cell's last feature):
// those that get a terrain feature and the frozen ones whose sums are
// dropped. The traversability layer builds its own features from them
// (perception/traversability). Called on the terrain thread: no allocation.
class CellSumsSink {
 public:
  virtual ~CellSumsSink() = default;
  // (x, y): the cell's centre in the odometry frame; `feature` the terrain
  // feature the step computed from these sums (null for a frozen cell, whose
  // sums get none), so that a sink need not find the eigenvalues again.
  virtual void cell_sums(CellIndex cell, const CellStats& sums, const FeatureVector* feature, double x,
                         double y) noexcept = 0;
  // Each registered revolution: the robot's pose at its end (odometry frame,
  // the revolution's lidar clock) — a demonstration's footprint.
  virtual void robot_pose(double /*x*/, double /*y*/, double /*yaw*/, std::int64_t /*time_ns*/) noexcept {}
  // Before a step hands over its cells: the robot's position then and the
  // class map the step updates; a sink may write the `traversable` of the
  // map's cells (its own layer) while it is handed their sums.
  virtual void step_begins(double /*robot_x*/, double /*robot_y*/, std::int64_t /*now_ns*/,
                           TerrainClassMap& /*map*/) noexcept {}
};

// Per cell of the registration grid.
struct TerrainWorkCell {
  CellStats stats;
  std::uint16_t observations = 0;  // features folded into the class map since (re)opening
  bool frozen = false;
  std::int64_t frozen_ns = 0;
};

// Empty when the terrain's [min_range, max_range] lies within the range the
// points are aligned for (TerrainMapper::create()), else what is wrong.
std::string check_terrain_alignment(const TerrainConfig& config, const FeatureParams& alignment);

class TerrainMapper {
 public:
  struct Created;
  // `forest` may be null (features only, for training); it must outlive the mapper.
  //
  // The points are aligned as the obstacle pipeline aligns them, with
  // `alignment` (the obstacle config's features: its range limits and
  // self_box), and then only those within the terrain config's own
  // [min_range, max_range] are registered: trailnavd's terrain thread takes
  // the obstacle thread's aligned revolutions (process_aligned()) instead of
  // aligning each one a second time, and an offline run that aligns itself
  // (process()) gets the same cells bit for bit. The terrain's range must lie
  // within the alignment's (an error otherwise).
  static Created create(const TerrainConfig& config, const MountParams& mount, const velodyne::RangeImageShape& shape,
                        const RandomForest* forest, const FeatureParams& alignment = FeatureParams{});

  // Aligns and registers one revolution, then runs a classification step if
  // the robot moved d metres (or max_step_interval passed) since the last.
  // True when a step ran (the class map changed). `poses` may be null.
  bool process(const velodyne::RangeImage& image, const PoseTrack* poses) noexcept;
  // The same for a revolution aligned elsewhere with the same alignment (the
  // points of RevolutionCloud::hand_over_aligned()).
  bool process_aligned(const RevolutionCloud& aligned) noexcept;

  // The stages on their own, for benchmarks and tests.
  void align(const velodyne::RangeImage& image, const PoseTrack* poses) noexcept;
  void register_cloud() noexcept { register_cloud(cloud_); }
  void register_cloud(const RevolutionCloud& aligned) noexcept;
  bool step_due() const noexcept;
  void step(std::int64_t now_ns) noexcept;

  // Takes over another mapper's grids and step state (same config; no
  // allocation): benchmarks repeat one step from the same state.
  void copy_state_from(const TerrainMapper& other) noexcept;

  // Offline only: told about every cell at every step.
  void set_observer(TerrainObserver* observer) noexcept { observer_ = observer; }
  // The traversability layer (may be null); it must outlive the mapper.
  void set_sums_sink(CellSumsSink* sink) noexcept { sums_sink_ = sink; }

  const TerrainConfig& config() const noexcept { return config_; }
  const TerrainClassMap& map() const noexcept { return map_; }
  const RollingGrid<TerrainWorkCell>& work() const noexcept { return work_; }
  RollingGrid<TerrainWorkCell>& work() noexcept { return work_; }
  const RevolutionCloud& cloud() const noexcept { return cloud_; }
  TerrainCounters counters() const noexcept;

 private:
  TerrainMapper(const TerrainConfig& config, const MountParams& mount, const velodyne::RangeImageShape& shape,
                const RandomForest* forest, const FeatureParams& alignment);
  // Re-opens a frozen cell when its time has come; whether the cell gets a
  // feature at this step.
  bool due_for_feature(TerrainWorkCell& w, TerrainCell& c, CellIndex i, std::int64_t now_ns) noexcept;
  // Features, then forest and Bayes update, for the first `count` batched cells.
  void finish_batch(std::size_t count, std::int64_t now_ns, std::uint64_t& classified, std::uint64_t& known) noexcept;
  void update_cell(TerrainWorkCell& w, TerrainCell& c, CellIndex i, const FeatureVector& feature,
                   std::int64_t now_ns) noexcept;

  struct Pending {
    TerrainWorkCell* work = nullptr;
    TerrainCell* cell = nullptr;
    CellIndex index{};
    FeatureVector feature{};
    float area_std = 0.0f;
  };
  // Remission sums of cells: points, sum, sum of squares (double: the
  // pooled variance is a difference of large sums).
  struct AreaSums {
    double n = 0.0, s = 0.0, q = 0.0;
  };
  // TerrainFeature::area_std_remission by box sums over the
  // (2 kAreaRadius + 1)^2 cells around: along x per row (add_area_row), then
  // along y over a ring of such rows (area_cols_, which a row enters and
  // leaves, drop_area_row), so a cell costs the same whatever the radius.
  void add_area_row(std::int32_t y) noexcept;   // window row y
  void drop_area_row(std::int32_t y) noexcept;
  float area_std(std::int32_t x) const noexcept;  // window column x of the row whose area is complete

  TerrainConfig config_;
  CloudAligner aligner_;
  RevolutionCloud cloud_;
  const RandomForest* forest_;
  RollingGrid<TerrainWorkCell> work_;
  TerrainClassMap map_;
  TerrainObserver* observer_ = nullptr;
  CellSumsSink* sums_sink_ = nullptr;
  std::array<Pending, 32> batch_{};
  std::unique_ptr<AreaSums[]> area_cells_;  // one row of cells' own sums
  std::unique_ptr<AreaSums[]> area_rows_;   // 2 kAreaRadius + 1 rows of sums along x
  std::unique_ptr<AreaSums[]> area_cols_;   // their sums along y, per column
  TerrainCounters counters_;
  bool have_step_ = false;
  double step_x_ = 0.0, step_y_ = 0.0;
  std::int64_t step_ns_ = 0;
  // The revolution registered last.
  double robot_x_ = 0.0, robot_y_ = 0.0;
  std::int64_t time_ns_ = 0;
  std::int64_t clock_offset_ns_ = 0;
};

struct TerrainMapper::Created {
  std::unique_ptr<TerrainMapper> mapper;
  std::string error;
};

}  // namespace trailnav::perception
