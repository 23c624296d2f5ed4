#include "trailnav/perception/trav_ground.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace trailnav::perception::trav {

namespace {
constexpr float kNone = std::numeric_limits<float>::infinity();  // a block nothing was seen in
}  // namespace

GroundReference::GroundReference(double extent_x, double extent_y, double block, int radius)
    : lows_(static_cast<std::int32_t>(std::ceil(extent_x / block)) + 2 * radius + 2 * kValleyRadius + 1,
            static_cast<std::int32_t>(std::ceil(extent_y / block)) + 2 * radius + 2 * kValleyRadius + 1, block, kNone),
      marks_(lows_.size_x(), lows_.size_y(), block, Mark{State::unknown, 0.0f}),
      radius_(radius) {}

void GroundReference::move_to(double x, double y) noexcept {
  lows_.move_to(x, y);
  marks_.move_to(x, y);
}

bool GroundReference::valley(CellIndex c) noexcept {
  Mark& m = marks_.at(c);
  if (m.state != State::unknown) return m.state == State::valley;
  // Across the block in four directions (the axes and the diagonals), on
  // each side the highest lowest point of the next block and of the two
  // next; the lower side of the two is the bank. A valley's bank stands
  // kValleyDepth above its bottom in some direction, right beside it on one
  // side at least (a ditch is one or two blocks wide; the middle of a track
  // three blocks wide between undergrowth is no valley).
  constexpr std::int32_t kDirections[4][2] = {{1, 0}, {0, 1}, {1, 1}, {1, -1}};
  auto low_at = [&](std::int32_t dx, std::int32_t dy) {
    const CellIndex n{c.x + dx, c.y + dy};
    if (!lows_.contains(n)) return -kNone;
    const float v = lows_.at(n);
    return v == kNone ? -kNone : v;
  };
  const float rim = lows_.at(c) + kValleyDepth;
  float bank = -kNone;
  for (const auto& d : kDirections) {
    const float a1 = low_at(d[0], d[1]), b1 = low_at(-d[0], -d[1]);
    if (std::max(a1, b1) < rim) continue;  // the usual case on open ground: no bank beside it
    const float a2 = std::max(a1, low_at(2 * d[0], 2 * d[1])), b2 = std::max(b1, low_at(-2 * d[0], -2 * d[1]));
    if (std::min(a2, b2) >= rim) bank = std::max(bank, std::min(a2, b2));
  }
  const bool is_valley = bank >= rim;
  m.state = is_valley ? State::valley : State::open;
  m.bank = bank;
  return is_valley;
}

float GroundReference::height(double x, double y, const CellStats& s) noexcept {
  const float low = s.z0 + s.min_dz;
  const CellIndex c = lows_.world_to_index(x, y);
  if (!lows_.contains(c)) return 0.0f;
  float& own = lows_.at(c);
  if (low < own) {
    own = low;
    // Every block whose test reads this one must look again.
    for (std::int32_t dy = -kValleyRadius; dy <= kValleyRadius; ++dy) {
      for (std::int32_t dx = -kValleyRadius; dx <= kValleyRadius; ++dx) {
        const CellIndex k{c.x + dx, c.y + dy};
        if (marks_.contains(k)) marks_.at(k).state = State::unknown;
      }
    }
  }
  // A cell in a valley below its bank: its depth there (negative).
  if (valley(c) && low < marks_.at(c).bank) return low - marks_.at(c).bank;
  // The lowest block within the radius that is not a valley (asked only of
  // a block lower than the lowest found so far).
  float ground = kNone;
  for (std::int32_t dy = -radius_; dy <= radius_; ++dy) {
    for (std::int32_t dx = -radius_; dx <= radius_; ++dx) {
      const CellIndex n{c.x + dx, c.y + dy};
      if (!lows_.contains(n)) continue;
      const float v = lows_.at(n);
      if (v < ground && !valley(n)) ground = v;
    }
  }
  return ground == kNone ? 0.0f : low - ground;  // only valleys around: the cell is its own ground
}

}  // namespace trailnav::perception::trav
