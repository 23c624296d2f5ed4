// P(o | g, t): the probability that a point's geometric features g =
// (stepHeight, incline) show an obstacle on terrain class t.
//
//  - Dirac (Eq. 7.11): 1 when stepHeight > maxStepHeight and incline >
//    maxIncline, else 0.
//  - smooth (Eq. 7.12): (1 - exp(-alpha stepHeight)) sqrt(1 - exp(-beta sin(incline))).
//
// The smooth model is a product of a function of the step height and one of
// sin(incline), so it is tabulated per class as two 1-D tables (the step
// every 0.5 mm up to 2 m, sin(incline) every 1/2048): two loads and a
// multiply per point and class instead of two exponentials and a square
// root. The tables differ from the formula by less than 0.01 (test). A bin
// holds all classes side by side (kClassStride floats), so P_C's sum over
// the classes reads one cache line from each table.
#pragma once

#include <array>
#include <vector>

#include "trailnav/perception/obstacle_config.hpp"

namespace trailnav::perception {

class ObstacleModels {
 public:
  ObstacleModels(const std::array<ClassParams, kTerrainClasses>& classes, const MapParams& map);

  static constexpr int kStepBins = 4096;
  static constexpr float kStepScale = 2048.0f;  // bins per metre
  static constexpr int kSinBins = 2049;
  static constexpr float kSinScale = 2048.0f;
  static constexpr int kLogitBins = 4097;
  static constexpr std::size_t kClassStride = 8;
  static_assert(kTerrainClasses <= static_cast<int>(kClassStride));

  // Eq. 7.11.
  bool dirac(int cls, float step_height, float sin_incline) const noexcept {
    return step_height > max_step_[static_cast<std::size_t>(cls)] && sin_incline > max_sin_[static_cast<std::size_t>(cls)];
  }
  // Eq. 7.12 from the tables: one class's own copy of them (24 KB, which
  // stays in the first-level cache where one class answers many points in
  // a row; the interleaved ones below are for P_C's sum over the classes).
  float smooth(int cls, float step_height, float sin_incline) const noexcept {
    const auto c = static_cast<std::size_t>(cls);
    return step_one_[c * kStepBins + static_cast<std::size_t>(step_index(step_height))] *
           incline_one_[c * kSinBins + static_cast<std::size_t>(sin_index(sin_incline))];
  }
  // Eq. 7.12 evaluated directly.
  static float smooth_exact(const ClassParams& c, float step_height, float sin_incline) noexcept;

  static int step_index(float step_height) noexcept {
    const float s = step_height * kStepScale + 0.5f;
    return s >= static_cast<float>(kStepBins - 1) ? kStepBins - 1 : static_cast<int>(s);
  }
  static int sin_index(float sin_incline) noexcept {
    const float s = sin_incline * kSinScale + 0.5f;
    return s >= static_cast<float>(kSinBins - 1) ? kSinBins - 1 : static_cast<int>(s);
  }
  float step_part(int cls, int index) const noexcept {
    return step_[static_cast<std::size_t>(index) * kClassStride + static_cast<std::size_t>(cls)];
  }
  float incline_part(int cls, int index) const noexcept {
    return incline_[static_cast<std::size_t>(index) * kClassStride + static_cast<std::size_t>(cls)];
  }

  // PW: the class's top hold in seconds (ClassParams::top_hold_s, else the map's).
  float top_hold_s(int cls) const noexcept { return top_hold_s_[static_cast<std::size_t>(cls)]; }

  // logit(clamp(p, measurement_min, measurement_max)) - logit(prior): the
  // increment of Eq. 7.10, from a table over p.
  float increment(float p) const noexcept {
    const float s = p * static_cast<float>(kLogitBins - 1) + 0.5f;
    const int i = s <= 0.0f ? 0 : s >= static_cast<float>(kLogitBins - 1) ? kLogitBins - 1 : static_cast<int>(s);
    return increment_[static_cast<std::size_t>(i)];
  }

 private:
  std::array<float, kTerrainClasses> max_step_{};
  std::array<float, kTerrainClasses> max_sin_{};
  std::array<float, kTerrainClasses> top_hold_s_{};
  std::vector<float> step_;
  std::vector<float> incline_;
  std::vector<float> step_one_;     // class-major: [class * kStepBins + bin]
  std::vector<float> incline_one_;  // [class * kSinBins + bin]
  std::vector<float> increment_;
};

float logit(float p) noexcept;
float logistic(float l) noexcept;

}  // namespace trailnav::perception
