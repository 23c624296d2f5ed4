// The robot's motion: a differential-drive platform following the route's
// true centreline with pure pursuit, speed limited by its acceleration, by
// the curvature ahead and at the route's end; height, roll and pitch follow
// the ground under its four wheels through a damped suspension.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Geometry>

#include "roads.hpp"
#include "scenario.hpp"
#include "world.hpp"

namespace trailnav::sim {

struct PoseSample {
  double t = 0.0;          // s since the simulation's start
  Vec3 p{0, 0, 0};         // robot frame origin (ground level between the axles), world frame
  double roll = 0.0;       // rad, about x (forward); left side up positive
  double pitch = 0.0;      // rad, about y (left); nose down positive
  double yaw = 0.0;        // rad, from east counter-clockwise (unwrapped)
  double v = 0.0;          // m/s forward
  double yaw_rate = 0.0;   // rad/s
  double v_left = 0.0;     // m/s, wheel ground speeds
  double v_right = 0.0;
  double arc = 0.0;        // m along the route
};

class Trajectory {
 public:
  static constexpr double kRate = 200.0;  // Hz

  std::vector<PoseSample> samples;

  double duration() const noexcept { return samples.empty() ? 0.0 : samples.back().t; }
  PoseSample at(double t) const noexcept;  // linear interpolation, clamped
};

// Rotation from the robot frame to the world frame (z-y-x Euler angles).
Eigen::Matrix3d rotation(double roll, double pitch, double yaw) noexcept;

// Drives the route for `duration` seconds (0: until the robot has stopped at
// its end, plus one second).
Trajectory drive(const Scenario& scenario, const RoadNetwork& roads, const World& world, double duration,
                 std::uint64_t seed);

}  // namespace trailnav::sim
