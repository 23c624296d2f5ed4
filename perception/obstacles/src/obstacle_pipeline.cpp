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
      models_(config.classes, config.map),
      smoothed_(static_cast<std::size_t>((shape.max_columns + kBlockColumns - 1) / kBlockColumns), 0),
      featured_(smoothed_.size(), 0) {
  if (config.ground.enabled) {
    ground_.emplace(config.ground, config.features.max_range, cloud_.x.size());
    ground_height_.assign(cloud_.x.size(), 0.0f);
  }
  for (int m = 0; m < kFusionModels; ++m) {
    const auto model = static_cast<FusionModel>(m);
    if (model == config.model || config.compare_models) {
      maps_[static_cast<std::size_t>(m)] = std::make_unique<ObstacleMap>(config.map, model);
    }
  }
}

void ObstaclePipeline::start_blocks(int columns) noexcept {
  columns_ = columns;
  blocks_ = (columns + kBlockColumns - 1) / kBlockColumns;
  aligned_blocks_ = 0;
  mapped_ = 0;
  grounded_ = false;
  std::fill_n(smoothed_.begin(), blocks_, std::uint8_t{0});
  std::fill_n(featured_.begin(), blocks_, std::uint8_t{0});
  // A block's features read the smoothed blocks ring_neighbours columns on,
  // whose smoothing reads half_window + 1 columns more, whose points come
  // from firings up to the spread away: the first blocks, whose chain reaches
  // back past the cut to the revolution's end, go last.
  const int k = std::min(config_.features.ring_neighbours, std::max(columns_ / 2 - 1, 0));
  const int reach = config_.features.smoothing_half_window + 1 + aligner_.spread_columns();
  head_blocks_ = 0;
  while (head_blocks_ < blocks_) {
    const int first_smoothed = std::max(0, block_begin(head_blocks_) - k) / kBlockColumns;
    if (block_begin(first_smoothed) - reach >= 0) break;
    ++head_blocks_;
  }
}

bool ObstaclePipeline::aligned_through(int lo, int hi) const noexcept {
  const int aligned = aligned_columns();
  if (aligned >= columns_) return true;
  // A column's points come from the firings up to the spread either side of
  // it, around the cut too.
  const int spread = aligner_.spread_columns();
  return lo - spread >= 0 && hi - 1 + spread < aligned;
}

bool ObstaclePipeline::smoothed_through(int lo, int hi) const noexcept {
  if (!cloud_.full_turn) {
    lo = std::max(lo, 0);
    hi = std::min(hi, columns_);
  }
  for (int c = lo; c < hi;) {
    const int column = ((c % columns_) + columns_) % columns_;
    const int b = column / kBlockColumns;
    if (smoothed_[static_cast<std::size_t>(b)] == 0) return false;
    c += block_end(b) - column;
  }
  return true;
}

// Without the ground, a block is mapped once its features are there. The
// ground needs every point of the revolution (a cell near the sensor takes
// points from many columns): the maps then wait for the last block's
// features, and the ground goes first.
bool ObstaclePipeline::ready_to_map() noexcept {
  if (!ground_) return true;
  if (grounded_) return true;
  for (int b = 0; b < blocks_; ++b) {
    if (featured_[static_cast<std::size_t>(b)] == 0) return false;
  }
  ground_->build(cloud_);
  ground_->apply(cloud_, ground_height_);
  grounded_ = true;
  return true;
}

int ObstaclePipeline::work_blocks(const PoseTrack* poses, const velodyne::RangeImage* image, int final_columns) noexcept {
  const int half = config_.features.smoothing_half_window;
  const int k = std::min(config_.features.ring_neighbours, std::max(columns_ / 2 - 1, 0));
  const TerrainSource source = terrain_source(terrain_);
  // Block by block: after each block aligned, whatever that made ready (a
  // block or two behind it) while its points are still in the cache. The
  // smoothing and the features of a block do not depend on when they run;
  // the firings go in order (a point whose column is taken is dropped: the
  // first one there keeps it, whatever the steps) and so do the map updates.
  int worked = 0;
  for (;;) {
    int done = 0;
    if (image != nullptr && aligned_blocks_ < blocks_ && block_end(aligned_blocks_) <= final_columns) {
      aligner_.align_columns(*image, poses, block_begin(aligned_blocks_), block_end(aligned_blocks_), cloud_);
      ++aligned_blocks_;
      ++done;
    }
    for (int b = 0; b < blocks_; ++b) {
      const auto i = static_cast<std::size_t>(b);
      if (smoothed_[i] == 0 &&
          aligned_through(std::max(0, block_begin(b) - half - 1), std::min(columns_, block_end(b) + half + 1))) {
        smooth_rings(cloud_, config_.features, block_begin(b), block_end(b));
        smoothed_[i] = 1;
        ++done;
      }
    }
    for (int b = 0; b < blocks_; ++b) {
      const auto i = static_cast<std::size_t>(b);
      if (featured_[i] == 0 && smoothed_[i] != 0 && smoothed_through(block_begin(b) - k, block_end(b) + k)) {
        compute_features(cloud_, config_.features, feature_counters_, block_begin(b), block_end(b));
        featured_[i] = 1;
        ++done;
      }
    }
    while (mapped_ < blocks_ && featured_[static_cast<std::size_t>(map_block(mapped_))] != 0 && ready_to_map()) {
      const int b = map_block(mapped_);
      for (auto& m : maps_) {
        if (m) m->integrate_columns(cloud_, models_, source, block_begin(b), block_end(b));
      }
      ++mapped_;
      ++done;
    }
    worked += done;
    if (done == 0) return worked;
  }
}

void ObstaclePipeline::begin(const velodyne::RangeImage& image, const PoseTrack* poses,
                             const TerrainClassMap* terrain) noexcept {
  aligner_.begin(image, poses, cloud_);
  start_blocks(cloud_.columns());
  terrain_ = terrain;
  for (auto& m : maps_) {
    if (m) m->begin_revolution(cloud_, models_);
  }
}

int ObstaclePipeline::advance(const velodyne::RangeImage& image, const PoseTrack* poses, int final_columns) noexcept {
  return work_blocks(poses, &image, std::min(final_columns, columns_));
}

void ObstaclePipeline::finish(const velodyne::RangeImage& image, const PoseTrack* poses) noexcept {
  work_blocks(poses, &image, columns_);
  aligner_.finish(image, poses, cloud_);
  ++revolutions_;
}

void ObstaclePipeline::process(const velodyne::RangeImage& image, const PoseTrack* poses,
                               const TerrainClassMap* terrain) noexcept {
  begin(image, poses, terrain);
  finish(image, poses);
}

void ObstaclePipeline::align(const velodyne::RangeImage& image, const PoseTrack* poses) noexcept {
  ++revolutions_;
  aligner_.begin(image, poses, cloud_);
  start_blocks(cloud_.columns());
  aligner_.align_columns(image, poses, 0, columns_, cloud_);
  aligned_blocks_ = blocks_;
  aligner_.finish(image, poses, cloud_);
}

void ObstaclePipeline::align_scan(const cloud::ScanCells& scan) noexcept {
  ++revolutions_;
  aligner_.align_scan(scan, cloud_);
  start_blocks(cloud_.columns());
  aligned_blocks_ = blocks_;
}

void ObstaclePipeline::features() noexcept {
  // Every column at once: the same bits as block by block (smooth_rings(),
  // compute_features()).
  smooth_rings(cloud_, config_.features);
  compute_features(cloud_, config_.features, feature_counters_);
  std::fill_n(smoothed_.begin(), blocks_, std::uint8_t{1});
  std::fill_n(featured_.begin(), blocks_, std::uint8_t{1});
  grounded_ = false;
  ready_to_map();
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
  terrain_ = terrain;
  for (auto& m : maps_) {
    if (m) m->begin_revolution(cloud_, models_);
  }
  mapped_ = 0;
  work_blocks(nullptr, nullptr, 0);
}

PipelineCounters ObstaclePipeline::counters() const noexcept {
  PipelineCounters c;
  c.revolutions = revolutions_;
  c.align = aligner_.counters();
  c.features = feature_counters_;
  c.map = map().counters();
  if (ground_) c.ground = ground_->counters();
  return c;
}

}  // namespace trailnav::perception
