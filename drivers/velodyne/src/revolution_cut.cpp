#include "trailnav/drivers/velodyne/revolution_cut.hpp"

#include <cmath>
#include <numbers>

namespace trailnav::velodyne {

RevolutionCut::RevolutionCut(const Calibration& calibration, double cut_azimuth_rad)
    : cut_(static_cast<float>(cut_azimuth_rad)) {
  for (const LaserCorrection& c : calibration.lasers) rot_.push_back(static_cast<float>(c.rot_correction));
}

bool RevolutionCut::starts_revolution(const Point& p) noexcept {
  constexpr float kTwoPi = 2.0f * std::numbers::pi_v<float>;
  float relative = p.azimuth + rot_[p.laser] - cut_;
  while (relative < 0.0f) relative += kTwoPi;
  while (relative >= kTwoPi) relative -= kTwoPi;
  // A drop of more than half a turn is the wrap past the cut; small backward
  // steps (dual-return pairs, laser offsets) are not.
  const bool wrapped = previous_ >= 0.0f && relative + std::numbers::pi_v<float> < previous_;
  previous_ = relative;
  return wrapped;
}

}  // namespace trailnav::velodyne
