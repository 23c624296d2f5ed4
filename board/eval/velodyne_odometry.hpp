// Lidar odometry over a spinning lidar's revolutions (issue 40): a recording
// directory, a capture (pcap, raw packets) or a sequence of point-cloud
// files (KITTI .bin, PCD, PLY) through RevolutionSource, each
// revolution's points taken from its range image (the strongest return),
// de-skewed into the sensor's frame at the revolution's last firing with
// the motion of the revolution before (constant velocity; the columns'
// firing times give each point's share of the revolution), and registered
// by LidarOdometry (scan to local map). A simulated recording's true
// trajectory, moved to the lidar by its mount, is the reference for the
// relative pose error per 10 m.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "trailnav/perception/registration/odometry.hpp"

namespace trailnav::eval {

struct VelodyneOdometryOptions {
  std::string input;        // recording directory or capture file
  // Or a sequence of point-cloud files (KITTI .bin, PCD, PLY), a revolution
  // each, in this order (used instead of `input` when not empty).
  std::vector<std::string> inputs;
  std::string calibration;  // as RevolutionSource::open takes it ("" = the recording's or the model's)
  perception::registration::OdometryConfig odometry;
  float min_range = 2.0f;   // m: nearer returns are the robot and its mast
  float max_range = 80.0f;  // m
  bool deskew = true;
  // A recording's wheel and IMU odometry (its CAN and IMU streams through the
  // pose estimator, as trailnavd's pose thread runs them: evaluate_pose)
  // predicts each registration and de-skews each revolution, instead of the
  // last motion repeated. Needs a simulated recording (the pose evaluation
  // reads its truth).
  bool wheel_prior = false;
  long max_revolutions = 0;  // 0: all
  std::function<void(double)> progress;
  // After each revolution: its estimated pose (the reference's frame), its
  // reference pose (nullptr without a truth) and its points as registered
  // (the sensor's frame, de-skewed): what the loop closures take.
  std::function<void(const Eigen::Isometry3d& estimate, const Eigen::Isometry3d* reference,
                     std::span<const perception::registration::Point> points)>
      on_revolution;
};

struct VelodyneOdometryReport {
  std::string error;
  std::string lidar;
  std::size_t revolutions = 0;
  std::size_t points = 0;  // used, over all revolutions
  std::vector<std::int64_t> times_ns;  // each revolution's last firing
  std::vector<Eigen::Isometry3d> estimate;  // the lidar's pose at each, odometry frame (the first: the reference's)
  std::vector<Eigen::Isometry3d> reference;  // the same from the simulated truth; empty without one
  // Each revolution's registration (LidarOdometry::last_conditioning()).
  std::vector<perception::registration::LidarOdometry::Conditioning> conditioning;
  perception::registration::RelativePoseError rpe;
  // wheel_prior: the wheels' and IMU's odometry alone, moved to the lidar
  // and started at the reference's first pose, and its error per 10 m.
  std::vector<Eigen::Isometry3d> wheels;
  perception::registration::RelativePoseError rpe_wheels;
  double path_m = 0.0;       // along the reference
  double end_error_m = 0.0;  // NaN without a reference
  double ms_per_revolution = 0.0;  // registration and de-skew, not decoding
  perception::registration::OdometryCounters counters;
};

VelodyneOdometryReport run_velodyne_odometry(const VelodyneOdometryOptions& options);

}  // namespace trailnav::eval
