#include "trailnav/perception/obstacle_models.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace trailnav::perception {

float logit(float p) noexcept { return std::log(p / (1.0f - p)); }
float logistic(float l) noexcept { return 1.0f / (1.0f + std::exp(-l)); }

float ObstacleModels::smooth_exact(const ClassParams& c, float step_height, float sin_incline) noexcept {
  return (1.0f - std::exp(-c.alpha * step_height)) * std::sqrt(1.0f - std::exp(-c.beta * sin_incline));
}

ObstacleModels::ObstacleModels(const std::array<ClassParams, kTerrainClasses>& classes, const MapParams& map)
    : step_(static_cast<std::size_t>(kClassStride) * kStepBins, 0.0f),
      incline_(static_cast<std::size_t>(kClassStride) * kSinBins, 0.0f),
      increment_(kLogitBins) {
  for (std::size_t t = 0; t < classes.size(); ++t) {
    const ClassParams& c = classes[t];
    max_step_[t] = c.max_step_height;
    top_hold_s_[t] = c.top_hold_s.value_or(map.dirac_top_hold_s);
    max_sin_[t] = static_cast<float>(std::sin(static_cast<double>(c.max_incline_deg) * std::numbers::pi / 180.0));
    for (int i = 0; i < kStepBins; ++i) {
      const double h = i / static_cast<double>(kStepScale);
      step_[static_cast<std::size_t>(i) * kClassStride + t] = static_cast<float>(1.0 - std::exp(-static_cast<double>(c.alpha) * h));
    }
    for (int i = 0; i < kSinBins; ++i) {
      const double s = std::min(1.0, i / static_cast<double>(kSinScale));
      incline_[static_cast<std::size_t>(i) * kClassStride + t] =
          static_cast<float>(std::sqrt(1.0 - std::exp(-static_cast<double>(c.beta) * s)));
    }
  }
  step_one_.resize(static_cast<std::size_t>(kTerrainClasses) * kStepBins);
  incline_one_.resize(static_cast<std::size_t>(kTerrainClasses) * kSinBins);
  for (std::size_t t = 0; t < classes.size(); ++t) {
    for (std::size_t i = 0; i < kStepBins; ++i) step_one_[t * kStepBins + i] = step_[i * kClassStride + t];
    for (std::size_t i = 0; i < kSinBins; ++i) incline_one_[t * kSinBins + i] = incline_[i * kClassStride + t];
  }
  const float prior = logit(map.prior);
  for (int i = 0; i < kLogitBins; ++i) {
    const float p = std::clamp(static_cast<float>(i) / static_cast<float>(kLogitBins - 1), map.measurement_min, map.measurement_max);
    increment_[static_cast<std::size_t>(i)] = logit(p) - prior;
  }
}

}  // namespace trailnav::perception
