// One lidar revolution in, the obstacle map(s) updated: alignment, smoothing,
// features and the map update, with everything allocated by create().
//
// The work goes in blocks of kBlockColumns columns, each stage of a block as
// soon as what it reads is final: a block's firings once the assembler has
// passed them; its smoothing once the points of the columns within reach
// are all aligned (a point lands up to CloudAligner::spread_columns() from
// its firing's column); its features once the smoothed columns within
// ring_neighbours are there; its map update in a fixed order, the blocks
// after the cut first and the first blocks, which need the revolution's
// last columns, at the end. So trailnavd can take a revolution while it
// arrives (begin / advance / finish) and be left with the last block's work
// when its last packet comes, and the maps are the same bits however the
// revolution was cut into steps, offline or live (tests).
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "trailnav/perception/cloud.hpp"
#include "trailnav/perception/ground_height.hpp"
#include "trailnav/perception/obstacle_config.hpp"
#include "trailnav/perception/obstacle_map.hpp"
#include "trailnav/perception/obstacle_models.hpp"

namespace trailnav::perception {

struct PipelineCounters {
  std::uint64_t revolutions = 0;
  AlignCounters align;
  FeatureCounters features;
  MapCounters map;  // of the primary map
  GroundCounters ground;  // config().ground enabled
};

class ObstaclePipeline {
 public:
  struct Created;
  // `shape`: the range images this pipeline will be given.
  static Created create(const ObstacleConfig& config, const velodyne::RangeImageShape& shape);

  static constexpr int kBlockColumns = 64;

  // Aligns, smooths, computes features and updates every map kept. `poses`
  // and `terrain` may be null (fixed orientation; no terrain map).
  void process(const velodyne::RangeImage& image, const PoseTrack* poses, const TerrainClassMap* terrain) noexcept;

  // The same, while the revolution arrives: begin() once the assembler has
  // started it in `image` (its start time, columns and cut are set); then
  // advance() whenever it has passed more columns (`final_columns`: columns
  // [0, final_columns) and their times no longer change); finish() when it is
  // complete. Same image, poses (samples may be added in between) and
  // terrain map (it must stay valid) throughout. Returns the blocks worked on.
  void begin(const velodyne::RangeImage& image, const PoseTrack* poses, const TerrainClassMap* terrain) noexcept;
  int advance(const velodyne::RangeImage& image, const PoseTrack* poses, int final_columns) noexcept;
  void finish(const velodyne::RangeImage& image, const PoseTrack* poses) noexcept;
  // Of the revolution begun: columns aligned so far, and whether every block is mapped.
  int aligned_columns() const noexcept { return std::min(aligned_blocks_ * kBlockColumns, columns_); }
  bool mapped() const noexcept { return mapped_ == blocks_; }

  // The stages on their own (process() runs them in order, block by block),
  // for benchmarks and the offline timings; the same bits as process().
  void align(const velodyne::RangeImage& image, const PoseTrack* poses) noexcept;
  // A point-cloud file's scan straight from its cells, without a range
  // image (CloudAligner::align_scan): the same as align(image, nullptr) over
  // the image CloudImager::fill() makes of that cloud.
  void align_scan(const cloud::ScanCells& scan) noexcept;
  void features() noexcept;
  void update_maps(const TerrainClassMap* terrain) noexcept;
  // Where update_maps(terrain) takes each point's terrain class from.
  TerrainSource terrain_source(const TerrainClassMap* terrain) const noexcept;
  // What the last revolution's point k (cloud().index()) was fused as: the
  // class of its cell (or the fallback) and its class's two models' answers.
  struct PointAnswer {
    TerrainClass terrain = TerrainClass::other;
    bool terrain_known = false;
    bool dirac = false;   // Dirac model: an obstacle
    float smooth = 0.0f;  // smooth model: P(obstacle)
  };
  PointAnswer answer(const TerrainSource& terrain, std::size_t k) const noexcept;
  // The same for a step and incline at (x, y) of the last revolution's
  // frame (the cloud's: metres from its reference point).
  PointAnswer answer_at(const TerrainSource& terrain, float x, float y, float step, float sin_incline) const noexcept;

  // Keep what alignment made of every range-image point (AlignFate, or its
  // index in cloud()), for the offline tools' per-point answers: allocates
  // here, once; every revolution after fills it.
  void keep_point_fates() {
    fates_.assign(static_cast<std::size_t>(cloud_.rings()) * static_cast<std::size_t>(cloud_.stride()), kFateNoReturn);
    aligner_.keep_fates(fates_.data(), cloud_.stride(), fates_.size());
  }
  // The last revolution's, by range-image cell (ring * cloud().stride() + column); empty unless kept.
  const std::vector<std::int32_t>& point_fates() const noexcept { return fates_; }
  // With config().ground enabled: each point's height above the ground
  // (cloud().index(); NaN where no ground is known), and the ground's counts.
  const std::vector<float>& ground_height() const noexcept { return ground_height_; }
  const GroundGrid* ground() const noexcept { return ground_ ? &*ground_ : nullptr; }

  const ObstacleConfig& config() const noexcept { return config_; }
  const RevolutionCloud& cloud() const noexcept { return cloud_; }
  // The last revolution's points as aligned, to `to` (RevolutionCloud::
  // hand_over_aligned()): after process(), and after the last look at cloud().
  void hand_over_aligned(RevolutionCloud& to) noexcept { cloud_.hand_over_aligned(to); }
  const ObstacleModels& models() const noexcept { return models_; }
  // The map of the configured model.
  const ObstacleMap& map() const noexcept { return *maps_[static_cast<std::size_t>(config_.model)]; }
  // Every model's map unknown again (ObstacleMap::forget).
  void forget_maps() noexcept {
    for (auto& m : maps_) {
      if (m) m->forget();
    }
  }
  // The map of another model; null unless compare_models is set (or it is the configured one).
  const ObstacleMap* map(FusionModel m) const noexcept { return maps_[static_cast<std::size_t>(m)].get(); }
  PipelineCounters counters() const noexcept;

 private:
  ObstaclePipeline(const ObstacleConfig& config, const velodyne::RangeImageShape& shape);

  // Block b holds columns [b * kBlockColumns, min(columns, (b + 1) * kBlockColumns)).
  int block_begin(int b) const noexcept { return b * kBlockColumns; }
  int block_end(int b) const noexcept { return std::min(columns_, (b + 1) * kBlockColumns); }
  bool aligned_through(int lo, int hi) const noexcept;      // every point of columns [lo, hi) aligned
  bool smoothed_through(int lo, int hi) const noexcept;     // columns [lo, hi) smoothed (around the cut)
  int map_block(int m) const noexcept { return (m + head_blocks_) % blocks_; }  // m-th block to map
  void start_blocks(int columns) noexcept;
  int work_blocks(const PoseTrack* poses, const velodyne::RangeImage* image, int final_columns) noexcept;

  ObstacleConfig config_;
  CloudAligner aligner_;
  RevolutionCloud cloud_;
  ObstacleModels models_;
  std::array<std::unique_ptr<ObstacleMap>, kFusionModels> maps_;
  FeatureCounters feature_counters_;
  std::uint64_t revolutions_ = 0;
  // The revolution in progress.
  const TerrainClassMap* terrain_ = nullptr;
  int columns_ = 0;
  int blocks_ = 0;
  int head_blocks_ = 0;   // the first blocks, mapped last (they need the revolution's end)
  int aligned_blocks_ = 0;
  int mapped_ = 0;        // map_block(0 .. mapped_ - 1) done
  std::vector<std::uint8_t> smoothed_, featured_;  // per block
  std::vector<std::int32_t> fates_;                // keep_point_fates()
  std::optional<GroundGrid> ground_;               // config_.ground.enabled
  std::vector<float> ground_height_;
  bool grounded_ = false;                          // this revolution's ground applied
  bool ready_to_map() noexcept;
};

struct ObstaclePipeline::Created {
  std::unique_ptr<ObstaclePipeline> pipeline;
  std::string error;
};

// (Here, for the offline tools' loops over every point to inline them.)
inline ObstaclePipeline::PointAnswer ObstaclePipeline::answer(const TerrainSource& terrain, std::size_t k) const noexcept {
  const RevolutionCloud& c = cloud_;
  const bool measured = c.state[k] == PointState::measured;
  return answer_at(terrain, c.x[k], c.y[k], measured ? c.step_height[k] : 0.0f, measured ? c.sin_incline[k] : 0.0f);
}

inline ObstaclePipeline::PointAnswer ObstaclePipeline::answer_at(const TerrainSource& terrain, float x, float y, float step,
                                                          float sin_incline) const noexcept {
  PointAnswer a;
  const RevolutionCloud& c = cloud_;
  // (Without a terrain map to read, no cell is looked for: the offline
  // tools' answers for a whole scan are a third faster.)
  const TerrainCell* cell = terrain.adaptive_map() == nullptr
                                ? nullptr
                                : terrain.known_cell(c.ref_x + static_cast<double>(x), c.ref_y + static_cast<double>(y));
  a.terrain = cell != nullptr ? cell->best : terrain.fallback();
  a.terrain_known = cell != nullptr;
  const int cls = static_cast<int>(a.terrain);
  a.dirac = models_.dirac(cls, step, sin_incline);
  a.smooth = models_.smooth(cls, step, sin_incline);
  return a;
}

}  // namespace trailnav::perception
