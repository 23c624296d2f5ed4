// The ground around a cell, for the traversability feature's sixth and
// seventh dimensions (trav_vocabulary.hpp): blocks of 1 m holding the lowest
// point seen in them (odometry frame), on a rolling grid that follows the
// robot. A cell's height is its lowest point above the lowest block within
// `radius` blocks (3 m) that is not a valley: the ground of a street, a
// meadow or a track under trees lies at it (whatever else the cell holds
// above: grass, a canopy), while a cell in which the lidar saw only the
// leaves of undergrowth — from afar, its returns never reach the ground —
// lies a metre and more above it. A valley — a block with banks 0.2 m or
// more above its lowest point on both sides within 2 m, the bottom of a
// ditch — is never that ground: a track beside a ditch is not raised above
// it. A cell in a valley gets its depth below the lower bank instead, the
// seventh dimension: a ditch's flat bottom otherwise looks like a road. The
// recorder and the layer each keep one and feed it the cells in the order
// the terrain step hands them over, so that training and the robot make the
// same words; in trailnavd's demonstration mode the layer's serves both
// (TravOnline). Whether a block is a valley is kept beside its lowest point
// and worked out again only after a block within kValleyRadius of it got a
// lower point.
// Allocated at construction; no heap afterwards.
#pragma once

#include <cstddef>
#include <cstdint>

#include "trailnav/perception/terrain_features.hpp"
#include "trailnav/runtime/rolling_grid.hpp"

namespace trailnav::perception::trav {

class GroundReference {
 public:
  // Covers `extent_x` x `extent_y` metres around the robot (the terrain grid's).
  GroundReference(double extent_x, double extent_y, double block = 1.0, int radius = 3);

  void move_to(double x, double y) noexcept;
  // Registers the lowest point of the cell at (x, y) in its block and gives
  // its height above the lowest ground within the radius that is not a
  // valley (below): 0 or more, except in a valley, where the cell lies
  // below the ground around and the answer is negative (its depth).
  float height(double x, double y, const CellStats& s) noexcept;

  // A block is a valley — the bottom of a ditch or a furrow — when, along an
  // axis or a diagonal, blocks on both sides within kValleyRadius blocks
  // hold lowest points kValleyDepth or more above its own (its banks), on
  // one side at least in the next block.
  // Valleys are never the ground a cell's height is measured from: a track
  // beside a ditch is not raised above the ground.
  static constexpr std::int32_t kValleyRadius = 2;
  static constexpr float kValleyDepth = 0.2f;

 private:
  enum class State : std::uint8_t { unknown, open, valley };
  struct Mark {
    State state;  // whether the block is a valley, unknown until asked after a change around it
    float bank;   // a valley's: the lower of its banks' lowest points
  };
  bool valley(CellIndex c) noexcept;

  RollingGrid<float> lows_;  // the lowest point seen in each block, odometry frame
  RollingGrid<Mark> marks_;  // the same blocks
  int radius_;
};

}  // namespace trailnav::perception::trav
