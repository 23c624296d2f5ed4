// The ground under every point of one revolution, from the revolution
// itself (no terrain map, no earlier scan), and what it says about the
// point's step (docs/obstacles.md "Height above the ground").
//
// The thesis' features (§7.1.2) compare a point with its first neighbours
// farther than x along and across the rings. Two cases they cannot see
// from there: a point whose neighbours all lie on the same object (a pole,
// a tree trunk, a wall or a fence a few rings tall), or whose next ring
// lands metres behind it, so its step is measured against a far, low point
// and the incline looks flat; and the reverse, a low step on the ground
// itself (a curb, a lawn's edge, rough grass) that the robot crosses. Both
// are answered by how high the point stands above the ground around it:
//
//   lowest(c)  the second lowest point of cell c (a square of `cell` m; the
//              lowest alone may be a stray return below the ground), over
//              the revolution's points
//   ground(c)  = min over cells n with |dx| + |dy| <= radius of
//                lowest(n) + max_slope * (|dx| + |dy|)
//              the highest surface no steeper than max_slope (in the L1
//              metric, so the minimum is two passes of one dimension)
//              that stays at or below every cell's lowest point
//   h(p)       = z(p) - ground(cell of p)
//
// and a point's step (Eq. 7.5) becomes
//
//   h > height:   max(step, h), incline vertical: it stands on the ground
//                 at least this high, whatever its neighbours
//   otherwise:    min(step, max(h, 0)): a step cannot rise higher above
//                 the ground than the point itself does
//
// so each class's thresholds (Table 7.1) then judge it as before.
#pragma once

#include <cstdint>
#include <vector>

#include "trailnav/perception/cloud.hpp"
#include "trailnav/perception/obstacle_config.hpp"

namespace trailnav::perception {

struct GroundCounters {
  std::uint64_t raised = 0;     // points whose step became their height above the ground
  std::uint64_t lowered = 0;    // points whose step was cut to their height above the ground
  std::uint64_t no_ground = 0;  // points with no ground cell within the radius (left as they were)
};

class GroundGrid {
 public:
  // Covers `max_range` around the revolution's reference point (plus the
  // radius), for clouds of up to `points` points (rings * max_columns);
  // allocates here, nothing after.
  GroundGrid(const GroundParams& params, float max_range, std::size_t points);

  // The ground under the cloud's points (its x, y, z: the features' own).
  void build(const RevolutionCloud& cloud) noexcept;
  // Writes each valid point's height above the ground (NaN where there is
  // none) to `height` (the cloud's size) and changes its step and incline
  // as above.
  void apply(RevolutionCloud& cloud, std::vector<float>& height) noexcept;

  // The ground at (x, y) of the cloud's frame; NaN where none is known.
  float ground_at(float x, float y) const noexcept;
  const GroundCounters& counters() const noexcept { return counters_; }

 private:
  int cell_of(float x, float y) const noexcept;  // -1 outside
  GroundParams params_;
  int n_ = 0;          // cells per side
  float half_ = 0.0f;  // m from the centre to the grid's edge
  float inv_cell_ = 0.0f;
  int taps_ = 0;       // radius in cells
  struct Lowest {
    float first, second;
  };
  std::vector<Lowest> low_;
  std::vector<float> pass_, ground_;
  std::vector<std::int32_t> cell_;  // per point of the cloud built from: its cell, or -1
  int row_lo_ = 0, row_hi_ = -1;     // the grid rows the last build's points reached (none: lo > hi)
  GroundCounters counters_;
};

}  // namespace trailnav::perception
