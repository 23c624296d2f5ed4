// One lidar revolution in, the obstacle map(s) updated: alignment, smoothing,
// features and the map update, with everything allocated by create().
#pragma once

#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "trailnav/perception/cloud.hpp"
#include "trailnav/perception/obstacle_config.hpp"
#include "trailnav/perception/obstacle_map.hpp"
#include "trailnav/perception/obstacle_models.hpp"

namespace trailnav::perception {

struct PipelineCounters {
  std::uint64_t revolutions = 0;
  AlignCounters align;
  FeatureCounters features;
  MapCounters map;  // of the primary map
};

class ObstaclePipeline {
 public:
  struct Created;
  // `shape`: the range images this pipeline will be given.
  static Created create(const ObstacleConfig& config, const velodyne::RangeImageShape& shape);

  // Aligns, smooths, computes features and updates every map kept. `poses`
  // and `terrain` may be null (fixed orientation; no terrain map).
  void process(const velodyne::RangeImage& image, const PoseTrack* poses, const TerrainClassMap* terrain) noexcept;

  // The stages on their own (process() runs them in order), for benchmarks.
  void align(const velodyne::RangeImage& image, const PoseTrack* poses) noexcept;
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

  ObstacleConfig config_;
  CloudAligner aligner_;
  RevolutionCloud cloud_;
  ObstacleModels models_;
  std::array<std::unique_ptr<ObstacleMap>, kFusionModels> maps_;
  FeatureCounters feature_counters_;
  std::uint64_t revolutions_ = 0;
};

struct ObstaclePipeline::Created {
  std::unique_ptr<ObstaclePipeline> pipeline;
  std::string error;
};

}  // namespace trailnav::perception
