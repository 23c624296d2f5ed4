// Scores the pose estimate on a simulated recording against its truth: the
// recording's GPS, IMU and CAN streams go through the same decoders, attitude
// filter, wheel odometry and PoseEstimator as on the robot (in recorded time),
// and the estimate at every IMU sample is compared with the true trajectory.
//
//   local drift: over every 100 m stretch of the route (starting each 10 m),
//     the odometry frame is put on the true pose at the start and the
//     position and heading error at the end are taken (as KITTI's odometry
//     benchmark scores drift); reported as m and degrees per 100 m;
//   UTM error: the estimated UTM position of the robot against the true
//     one, over the whole run and per 100 m driven, next to the raw GPS
//     fixes' error; and how often the truth lies within the estimate's own
//     2-sigma ellipse.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "trailnav/navigation/pose/pose_estimator.hpp"

namespace trailnav::eval {

struct PoseEvalOptions {
  pose::PoseEstimatorOptions estimator;  // antenna and wheel track come from the scenario
  double segment = 100.0;                // m, drift stretch and UTM table row
  std::string csv;                       // optional: write the per-sample comparison here
  std::function<void(double fraction)> progress;
  // Called with the estimate at every IMU sample once the heading is known
  // (the subgoal evaluation takes the robot's UTM pose from it).
  std::function<void(const pose::UtmPose&)> on_utm;
  // Called with the odometry-frame pose (wheels and IMU, as the pose
  // thread's) at every IMU sample (lidar odometry's wheel prior takes it).
  std::function<void(const pose::LocalPose&)> on_odometry;
};

struct PoseSegmentRow {
  double from = 0.0, to = 0.0;  // m driven
  double utm_mean = 0.0, utm_max = 0.0;
  double gps_mean = 0.0;        // raw fixes in the same stretch
  double heading_mean_deg = 0.0;
  std::uint64_t samples = 0;
};

struct PoseEvalResult {
  std::string error;
  std::string recording;
  double duration = 0.0;   // s
  double distance = 0.0;   // m, true
  // Local frame.
  double odometry_distance = 0.0;  // m, estimated
  std::uint64_t drift_segments = 0;
  double drift_mean = 0.0, drift_max = 0.0;          // m per segment
  double yaw_drift_mean_deg = 0.0, yaw_drift_max_deg = 0.0;
  double end_error = 0.0;                            // m, whole run, start aligned
  // UTM.
  double aligned_after_m = -1.0;   // m driven before the heading was known
  std::uint64_t utm_samples = 0;
  double utm_mean = 0.0, utm_rms = 0.0, utm_p95 = 0.0, utm_max = 0.0;
  double heading_mean_deg = 0.0, heading_max_deg = 0.0;
  double within_2sigma = 0.0;      // fraction of samples
  double gps_mean = 0.0, gps_rms = 0.0;  // raw fixes (antenna) against the true antenna position
  std::uint64_t gps_fixes = 0;
  std::vector<PoseSegmentRow> rows;
  pose::UtmAlignmentCounters utm_counters;
  pose::GyroOdometryCounters odometry_counters;
};

PoseEvalResult evaluate_pose(const std::string& recording, const PoseEvalOptions& options);

}  // namespace trailnav::eval
