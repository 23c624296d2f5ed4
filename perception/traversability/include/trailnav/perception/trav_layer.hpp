// The traversability layer on the robot: each cell's evidence from the words
// its features produced, classified by a learnt model as the terrain step
// hands the cells over (CellSumsSink), on a rolling grid of the terrain
// grid's geometry. A cell keeps the evidence of the local map it was last
// observed in (thesis §6.1: local maps of d_M are withdrawn; a cell seen
// again in a new local map starts afresh). Set as the terrain mapper's sink
// it also writes each cell's P(trav) into the class map the step updates
// (TerrainCell::traversable), so that every reader of the class map (the
// DDS publisher, the subgoal aligner) gets the layer with it. Everything is
// allocated at construction; the terrain thread calls it without touching
// the heap.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "trailnav/perception/terrain_mapper.hpp"
#include "trailnav/perception/trav_ground.hpp"
#include "trailnav/perception/trav_learner.hpp"
#include "trailnav/runtime/rolling_grid.hpp"

namespace trailnav::perception::trav {

// Terrain models a layer can hold per cell (the learner's max_models may be
// larger for offline work).
inline constexpr std::uint32_t kLayerModels = 8;

struct TravCell {
  std::array<float, kLayerModels> pnb{};  // Σ log P(f|trav) − log P(f|¬trav) per terrain model
  float pos = 0.0f;                       // Σ logit P(trav|f) − logit P(trav)
  std::uint16_t words = 0;                // 0: never observed
  std::uint16_t local_map = 0;            // the local map the evidence belongs to
  std::uint16_t models = 0;               // the models it was weighed with (TravLayer::set_models())
};

struct LayerCounters {
  std::uint64_t words = 0;       // classified
  std::uint64_t restarted = 0;   // cells whose evidence a new local map (or newer models) replaced
  std::uint64_t too_far = 0;     // beyond max_range
  std::uint64_t outside = 0;     // cells outside the layer's grid
};

class TravLayer final : public CellSumsSink {
 public:
  struct Created;
  // `models` must outlive the layer (or be replaced by set_models()) and
  // hold at most kLayerModels terrain models; with none (a demonstration
  // that has not finished its first local map) every cell is unknown.
  static Created create(const TravModels& models, Method method, double local_map_distance, double max_range,
                        std::int32_t size_x, std::int32_t size_y, double resolution);

  // The robot's position (odometry frame): the grid follows it, the local
  // map counts its travel.
  void move_to(double x, double y) noexcept;
  void cell_sums(CellIndex cell, const CellStats& sums, const FeatureVector* feature, double x, double y) noexcept override {
    std::uint32_t word = 0;
    classify(cell, sums, feature, x, y, word);
  }
  // The same, and the cell's word in `word` when it made one (true): a
  // demonstration's recorder over the same vocabulary takes it as it is
  // (TravOnline), instead of working out the ground and the word again.
  bool classify(CellIndex cell, const CellStats& sums, const FeatureVector* feature, double x, double y,
                std::uint32_t& word) noexcept;
  // The step's robot position (move_to) and the class map whose cells'
  // `traversable` the following cell_sums() write.
  void step_begins(double robot_x, double robot_y, std::int64_t now_ns, TerrainClassMap& map) noexcept override;

  // Newer models (a demonstration's, trained further): at most kLayerModels,
  // over the same vocabulary. A cell's evidence is a sum of the older
  // models' log ratios, which cannot be re-weighed without its words: the
  // cell keeps it (and the class map its answer) until it is observed again,
  // and then starts afresh with the newer models. No allocation.
  void set_models(const TravModels& models) noexcept {
    models_ = &models;
    models_epoch_ = static_cast<std::uint16_t>(models_epoch_ + 1);
  }
  const TravModels& models() const noexcept { return *models_; }

  // P(trav | f_1..n) of a cell's words in its local map; negative when the
  // cell has none (unknown).
  float probability(const TravCell& cell) const noexcept;
  // The grid as ROS costs, row-major from the grid's origin: 0 (surely
  // traversable) .. 100 (surely not), −1 unknown; `out` has size_x · size_y.
  void export_costs(std::span<std::int8_t> out) const noexcept;

  const RollingGrid<TravCell>& grid() const noexcept { return grid_; }
  Method method() const noexcept { return method_; }
  std::uint16_t local_map() const noexcept { return local_map_; }
  const LayerCounters& counters() const noexcept { return counters_; }

 private:
  TravLayer(const TravModels& models, Method method, double local_map_distance, double max_range, std::int32_t size_x,
            std::int32_t size_y, double resolution);

  const TravModels* models_;
  Method method_;
  TerrainClassMap* map_ = nullptr;  // the class map of the step under way
  double local_map_distance_;
  double max_range_;
  RollingGrid<TravCell> grid_;
  GroundReference ground_;
  std::uint16_t local_map_ = 1;
  std::uint16_t models_epoch_ = 0;
  double travelled_ = 0.0;
  bool have_pose_ = false;
  double x_ = 0.0, y_ = 0.0;
  LayerCounters counters_;
};

struct TravLayer::Created {
  std::unique_ptr<TravLayer> layer;
  std::string error;
};

}  // namespace trailnav::perception::trav
