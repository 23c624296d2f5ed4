// The ground around a cell, for the traversability feature's sixth
// dimension (trav_vocabulary.hpp): blocks of 1 m holding the lowest point
// seen in them (odometry frame), on a rolling grid that follows the robot.
// A cell's height is its lowest point above the lowest block within
// `radius` blocks (3 m): the ground of a street, a meadow or a track under
// trees lies at it (whatever else the cell holds above: grass, a canopy),
// while a cell in which the lidar saw only the leaves of undergrowth — from
// afar, its returns never reach the ground — lies a metre and more above it. The recorder and the
// layer each keep one and feed it the cells in the order the terrain step
// hands them over, so that training and the robot make the same words.
// Allocated at construction; no heap afterwards.
#pragma once

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
  // its height above the lowest ground within the radius (0 or more).
  float height(double x, double y, const CellStats& s) noexcept;

 private:
  RollingGrid<float> blocks_;
  int radius_;
};

}  // namespace trailnav::perception::trav
