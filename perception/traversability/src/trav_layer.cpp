#include "trailnav/perception/trav_layer.hpp"

#include <algorithm>
#include <cmath>

namespace trailnav::perception::trav {

TravLayer::Created TravLayer::create(const TravModels& models, Method method, double local_map_distance, double max_range,
                                     std::int32_t size_x, std::int32_t size_y, double resolution) {
  if (models.models() > kLayerModels) {
    return {nullptr, "the traversability model has " + std::to_string(models.models()) + " terrain models; the layer holds " +
                         std::to_string(kLayerModels) + " (train with --max-models " + std::to_string(kLayerModels) + ")"};
  }
  if (!(local_map_distance > 0.0) || !(max_range > 0.0) || size_x <= 0 || size_y <= 0 || !(resolution > 0.0)) {
    return {nullptr, "traversability layer: local map distance, range, grid size and resolution must be positive"};
  }
  return {std::unique_ptr<TravLayer>(
              new TravLayer(models, method, local_map_distance, max_range, size_x, size_y, resolution)),
          ""};
}

TravLayer::TravLayer(const TravModels& models, Method method, double local_map_distance, double max_range,
                     std::int32_t size_x, std::int32_t size_y, double resolution)
    : models_(&models),
      method_(method),
      local_map_distance_(local_map_distance),
      max_range_(max_range),
      grid_(size_x, size_y, resolution, TravCell{}),
      ground_(size_x * resolution, size_y * resolution) {}

void TravLayer::move_to(double x, double y) noexcept {
  if (have_pose_) travelled_ += std::hypot(x - x_, y - y_);
  have_pose_ = true;
  x_ = x;
  y_ = y;
  grid_.move_to(x, y);
  ground_.move_to(x, y);
  if (travelled_ >= local_map_distance_) {
    travelled_ = 0.0;
    // 0 marks "never": wrap from 65535 to 1.
    local_map_ = static_cast<std::uint16_t>(local_map_ == 0xFFFF ? 1 : local_map_ + 1);
  }
}

bool TravLayer::classify(CellIndex cell, const CellStats& sums, const FeatureVector* feature, double x, double y,
                         std::uint32_t& word) noexcept {
  if (have_pose_ && std::hypot(x - x_, y - y_) > max_range_) {
    ++counters_.too_far;
    return false;
  }
  if (!grid_.contains(cell)) {
    ++counters_.outside;
    return false;
  }
  const float height = ground_.height(x, y, sums);
  Feature f;
  if (!cell_feature(sums, f, feature, height)) return false;
  word = models_->vocabulary().word(f);
  TravCell& c = grid_.at(cell);
  if (c.words > 0 && (c.local_map != local_map_ || c.models != models_epoch_)) {
    c = TravCell{};
    ++counters_.restarted;
  }
  c.local_map = local_map_;
  c.models = models_epoch_;
  if (c.words < 0xFFFF) ++c.words;
  const std::uint32_t models = std::min(models_->models(), kLayerModels);
  for (std::uint32_t m = 0; m < models; ++m) c.pnb[m] += models_->pnb_log_ratio(m, word);
  c.pos += models_->pos_log_ratio(word);
  ++counters_.words;
  if (map_ != nullptr) {
    if (TerrainCell* t = map_->grid().find(x, y)) t->traversable = probability(c);
  }
  return true;
}

void TravLayer::step_begins(double robot_x, double robot_y, std::int64_t, TerrainClassMap& map) noexcept {
  move_to(robot_x, robot_y);
  map_ = &map;
}

float TravLayer::probability(const TravCell& c) const noexcept {
  const std::uint32_t models = std::min(models_->models(), kLayerModels);
  if (c.words == 0 || models == 0) return -1.0f;
  if (method_ == Method::pos) return 1.0f / (1.0f + std::exp(-(models_->pos_prior_logit() + c.pos)));
  float best = 0.0f;
  for (std::uint32_t m = 0; m < models; ++m) {
    best = std::max(best, 1.0f / (1.0f + std::exp(-(models_->pnb_prior_logit(m) + c.pnb[m]))));  // Eq. 6.16
  }
  return best;
}

void TravLayer::export_costs(std::span<std::int8_t> out) const noexcept {
  const CellIndex o = grid_.origin();
  const auto nx = static_cast<std::size_t>(grid_.size_x());
  for (std::int32_t y = 0; y < grid_.size_y(); ++y) {
    for (std::int32_t x = 0; x < grid_.size_x(); ++x) {
      const std::size_t k = static_cast<std::size_t>(y) * nx + static_cast<std::size_t>(x);
      if (k >= out.size()) return;
      const float p = probability(grid_.at({o.x + x, o.y + y}));
      out[k] = p < 0.0f ? std::int8_t{-1} : static_cast<std::int8_t>(std::lround(100.0f * (1.0f - p)));
    }
  }
}

}  // namespace trailnav::perception::trav
