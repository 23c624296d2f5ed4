#include "trailnav/perception/trav_ground.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace trailnav::perception::trav {

namespace {
constexpr float kNone = std::numeric_limits<float>::infinity();  // a block nothing was seen in
}  // namespace

GroundReference::GroundReference(double extent_x, double extent_y, double block, int radius)
    : blocks_(static_cast<std::int32_t>(std::ceil(extent_x / block)) + 2 * radius + 1,
              static_cast<std::int32_t>(std::ceil(extent_y / block)) + 2 * radius + 1, block, kNone),
      radius_(radius) {}

void GroundReference::move_to(double x, double y) noexcept { blocks_.move_to(x, y); }

float GroundReference::height(double x, double y, const CellStats& s) noexcept {
  const float low = s.z0 + s.min_dz;
  const CellIndex c = blocks_.world_to_index(x, y);
  if (!blocks_.contains(c)) return 0.0f;
  float& own = blocks_.at(c);
  own = std::min(own, low);
  float ground = own;
  for (std::int32_t dy = -radius_; dy <= radius_; ++dy) {
    for (std::int32_t dx = -radius_; dx <= radius_; ++dx) {
      const CellIndex n{c.x + dx, c.y + dy};
      if (blocks_.contains(n)) ground = std::min(ground, blocks_.at(n));
    }
  }
  return std::max(0.0f, low - ground);
}

}  // namespace trailnav::perception::trav
