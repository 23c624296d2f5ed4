// Splits the stream of decoded points into revolutions exactly at a chosen
// azimuth, point by point, so that no packet's points are shifted into the
// wrong revolution. The cut uses each firing's azimuth before the laser's own
// rotation correction, so the lasers of one firing always stay together.
#pragma once

#include <vector>

#include "trailnav/drivers/velodyne/calibration.hpp"
#include "trailnav/drivers/velodyne/decoder.hpp"

namespace trailnav::velodyne {

class RevolutionCut {
 public:
  RevolutionCut(const Calibration& calibration, double cut_azimuth_rad);

  // True when `p` is the first point of a new revolution (never for the very
  // first point seen).
  bool starts_revolution(const Point& p) noexcept;

 private:
  std::vector<float> rot_;  // per laser id
  float cut_;
  float previous_ = -1.0f;  // last firing azimuth, relative to the cut
};

}  // namespace trailnav::velodyne
