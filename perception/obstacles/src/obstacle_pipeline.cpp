#include "trailnav/perception/obstacle_pipeline.hpp"

namespace trailnav::perception {

ObstaclePipeline::Created ObstaclePipeline::create(const ObstacleConfig& config, const velodyne::RangeImageShape& shape) {
  if (std::string problem = check_obstacle_config(config); !problem.empty()) return {nullptr, problem};
  if (shape.rings < 2 || shape.max_columns < 8) {
    return {nullptr, "range images of " + std::to_string(shape.rings) + " rings x " + std::to_string(shape.max_columns) +
                         " columns are too small for obstacle detection"};
  }
  if (config.features.cross_neighbours >= shape.rings) {
    return {nullptr, "features.cross_neighbours (" + std::to_string(config.features.cross_neighbours) +
                         ") must be below the sensor's ring count (" + std::to_string(shape.rings) + ")"};
  }
  return {std::unique_ptr<ObstaclePipeline>(new ObstaclePipeline(config, shape)), {}};
}

ObstaclePipeline::ObstaclePipeline(const ObstacleConfig& config, const velodyne::RangeImageShape& shape)
    : config_(config),
      aligner_(config.mount, config.features),
      cloud_(CloudShape{shape.rings, shape.max_columns}),
      models_(config.classes, config.map) {
  for (int m = 0; m < kFusionModels; ++m) {
    const auto model = static_cast<FusionModel>(m);
    if (model == config.model || config.compare_models) {
      maps_[static_cast<std::size_t>(m)] = std::make_unique<ObstacleMap>(config.map, model);
    }
  }
}

void ObstaclePipeline::align(const velodyne::RangeImage& image, const PoseTrack* poses) noexcept {
  aligner_.align(image, poses, cloud_);
}

void ObstaclePipeline::features() noexcept {
  smooth_rings(cloud_, config_.features);
  compute_features(cloud_, config_.features, feature_counters_);
}

TerrainSource ObstaclePipeline::terrain_source(const TerrainClassMap* terrain) const noexcept {
  TerrainSource source;
  source.map = terrain;
  source.fixed = config_.fixed_class.has_value();
  if (source.fixed) source.fixed_class = *config_.fixed_class;
  source.unknown_class = config_.unknown_class;
  return source;
}

void ObstaclePipeline::update_maps(const TerrainClassMap* terrain) noexcept {
  const TerrainSource source = terrain_source(terrain);
  for (auto& m : maps_) {
    if (m) m->integrate(cloud_, models_, source);
  }
}

void ObstaclePipeline::process(const velodyne::RangeImage& image, const PoseTrack* poses,
                               const TerrainClassMap* terrain) noexcept {
  ++revolutions_;
  align(image, poses);
  features();
  update_maps(terrain);
}

PipelineCounters ObstaclePipeline::counters() const noexcept {
  PipelineCounters c;
  c.revolutions = revolutions_;
  c.align = aligner_.counters();
  c.features = feature_counters_;
  c.map = map().counters();
  return c;
}

ObstaclePipeline::PointAnswer ObstaclePipeline::answer(const TerrainSource& terrain, std::size_t k) const noexcept {
  PointAnswer a;
  const RevolutionCloud& c = cloud_;
  const TerrainCell* cell = terrain.known_cell(c.ref_x + static_cast<double>(c.x[k]), c.ref_y + static_cast<double>(c.y[k]));
  a.terrain = cell != nullptr ? cell->best : terrain.fallback();
  a.terrain_known = cell != nullptr;
  const bool measured = c.state[k] == PointState::measured;
  const float step = measured ? c.step_height[k] : 0.0f;
  const float incline = measured ? c.sin_incline[k] : 0.0f;
  const int cls = static_cast<int>(a.terrain);
  a.dirac = models_.dirac(cls, step, incline);
  a.smooth = models_.smooth(cls, step, incline);
  return a;
}

}  // namespace trailnav::perception
