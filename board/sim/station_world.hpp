// The stations of the thesis' chapter 4 simulation (§4.3.1): an 8 m x 6 m
// floor of three rooms, a box in one, a U-shaped shelf in another and a
// four-legged table in the third, seen by a 2D laser mounted parallel to the
// floor (180° field of view, 0.5° steps, range noise σ 0.01 m) on a
// differential-drive robot whose odometry follows a velocity motion model
// with zero-mean noise (σ 0.1 m/s and 0.1 rad/s). Objects move between
// visits by the thesis' six sets (0.05 m, 0.1 m, 5°, 10°, and both twice),
// about their own centres, in a direction drawn per run. Everything is a
// pure function of (seed, object, set, run): a run is reproducible bit for
// bit. Simulated truth, labelled so wherever it is reported.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Geometry>

namespace trailnav::sim::station {

struct Segment {
  Eigen::Vector2d a, b;
};

// A planar pose (x, y, heading).
struct Pose2 {
  double x = 0.0, y = 0.0, theta = 0.0;
};
Eigen::Isometry3d to_isometry(const Pose2& p) noexcept;
Pose2 compose(const Pose2& a, const Pose2& b) noexcept;  // a ∘ b
Pose2 inverse(const Pose2& p) noexcept;

// An object: rectangles (centre and size in its own frame) and where it
// stands (its frame in the world); the frame's origin is its centre.
struct Rect {
  double cx, cy, w, h;
};
struct ObjectShape {
  std::string name;
  std::vector<Rect> parts;
  Pose2 pose;         // as taught
  Pose2 view;         // where the robot stands to look at it (world frame), facing it
  std::array<Eigen::Vector2d, 4> mark;  // the polygon a user marks around it at teach-in (world frame)
};

struct World {
  std::vector<Segment> walls;
  std::vector<ObjectShape> objects;  // box, shelf, table
};
// The thesis' floor (Fig. 4.8): box lower right, shelf lower left, table
// upper right.
World thesis_world();

// The segments of every object at the given poses (one per object).
std::vector<Segment> object_segments(const World& w, const std::vector<Pose2>& poses);

struct LaserConfig {
  double fov = 3.14159265358979323846;  // rad
  double step = 0.5 * 3.14159265358979323846 / 180.0;
  double max_range = 8.0;
  double sigma = 0.01;  // m, range noise
};
// One scan from `sensor` (world frame): points in the sensor frame (z = 0),
// beams without a return left out. `noise_key` seeds the range noise.
std::vector<Eigen::Vector3f> cast(const std::vector<Segment>& segments, const Pose2& sensor, const LaserConfig& laser,
                                  std::uint64_t noise_key);

// The thesis' six sets: translation (m) and rotation (rad).
struct MoveSet {
  double translation;
  double rotation;
};
inline constexpr std::array<MoveSet, 6> kThesisSets{{{0.05, 0.0},
                                                    {0.10, 0.0},
                                                    {0.0, 5.0 * 3.14159265358979323846 / 180.0},
                                                    {0.0, 10.0 * 3.14159265358979323846 / 180.0},
                                                    {0.05, 5.0 * 3.14159265358979323846 / 180.0},
                                                    {0.10, 10.0 * 3.14159265358979323846 / 180.0}}};
// The object's motion (world frame, about its centre) for one run of a set:
// the translation in a direction drawn from the key, the rotation's sign too.
Pose2 move_of(const ObjectShape& o, const MoveSet& set, std::uint64_t key) noexcept;

// A drive: true poses and the odometry's increments (each in the previous
// pose's frame, noisy as the velocity motion model), one per scan.
struct Drive {
  std::vector<Pose2> truth;
  std::vector<Pose2> odometry;  // odometry[0] is the identity
};
// The teach-in: an arc around the object's view point, facing the object,
// `scans` poses (0.1 s apart). `odometry_noise` scales the model's σ.
Drive teach_drive(const ObjectShape& o, int scans, std::uint64_t key, double odometry_noise = 1.0);
// A visit: from about 2 m in front of the object (drawn from the key),
// driving towards its view point, `scans` poses 0.1 s apart.
Drive visit_drive(const ObjectShape& o, int scans, std::uint64_t key, double odometry_noise = 1.0);

}  // namespace trailnav::sim::station
