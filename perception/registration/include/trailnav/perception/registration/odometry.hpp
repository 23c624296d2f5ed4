// Lidar odometry by scan-to-local-map GICP (issue 40): each scan, voxel
// filtered, is registered onto a local map made of the last `local_scans`
// keyframes (in the odometry frame), starting from a constant-velocity
// prediction; a scan becomes a keyframe when the robot has moved
// `keyframe_distance` or turned `keyframe_angle` since the last one, and the
// local map is rebuilt then (its k-d tree allocates: this runs off the
// real-time threads). `planar`: 2D scans (z = 0), covariances of lines.
//
// And the evaluation's measure: the relative pose error per segment of
// travel (10 m by default), as KITTI's odometry benchmark defines it: for
// every pose i, the first pose j at least `segment` metres of reference
// path further, E = (T_i⁻¹ T_j)_ref⁻¹ (T_i⁻¹ T_j)_est; its translation as a
// percentage of the segment, its rotation in degrees per 100 m, averaged.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "trailnav/perception/registration/gicp.hpp"

namespace trailnav::perception::registration {

struct OdometryConfig {
  GicpConfig gicp;
  float voxel = 0.1f;              // m, the scans' and the local map's
  int local_scans = 10;            // keyframes in the local map
  double keyframe_distance = 0.5;  // m
  double keyframe_angle = 0.17;    // rad (about 10°)
  bool planar = false;
  bool constant_velocity = true;  // predict the last motion again; false: the last pose
  bool two_starts = true;         // also start from the last pose; keep the better answer
  // With a measured motion (add()'s `motion`): a direction of the sensor's
  // translation whose covariance eigenvalue is more than this many times the
  // smallest takes the measured motion instead of the registration's (0: never).
  double weak_ratio = 100.0;
  std::size_t max_points = 200'000;  // per scan before filtering
};

struct OdometryCounters {
  std::uint64_t scans = 0;
  std::uint64_t keyframes = 0;
  std::uint64_t not_converged = 0;  // registrations that hit max_iterations or lost their associations
  std::uint64_t iterations = 0;
  std::uint64_t second_start = 0;  // scans whose answer came from the start at the last pose
  // Results 1 m or 0.5 rad from the prediction, or without associations:
  // the measured motion taken when add() was given one, else the last pose kept.
  std::uint64_t rejected = 0;
  std::uint64_t prior_kept = 0;  // scans with a weakly pinned direction that took the measured motion there
};

class LidarOdometry {
 public:
  explicit LidarOdometry(const OdometryConfig& config);

  // One scan in the sensor's frame; returns its pose in the odometry frame
  // (the first scan's pose is the identity). `motion`: the sensor's motion
  // since the last scan as another sensor measured it (wheels and IMU), the
  // registration's start instead of the constant-velocity prediction (and
  // no second start: a measured motion does not overshoot a stopping turn
  // as the repeated one does). Where the scene leaves a direction unpinned
  // (a straight street between flat sides) the answer stays near it.
  Eigen::Isometry3d add(std::span<const Point> scan, const Eigen::Isometry3d* motion = nullptr);
  const OdometryCounters& counters() const noexcept { return counters_; }
  // The motion from the scan before the last to the last one (in the
  // former's frame): what the constant-velocity prediction repeats, and
  // what de-skewing the next scan assumes (the identity before two scans).
  Eigen::Isometry3d last_motion() const noexcept { return previous_.inverse() * last_; }
  // How well the last scan's registration pinned its translation: the
  // largest and smallest eigenvalues of the covariance (the inverse of the
  // objective's Hessian; m² per unit of the objective) of the sensor's
  // position, and the direction of the largest, in the odometry frame. A
  // ratio in the hundreds is a direction the scene hardly constrains (a
  // straight street across an open square: along it, about 500; streets
  // with buildings 30-70). Zeros before the second scan and for a rejected one.
  struct Conditioning {
    double weakest = 0.0;
    double strongest = 0.0;
    Eigen::Vector3d direction = Eigen::Vector3d::Zero();
  };
  const Conditioning& last_conditioning() const noexcept { return conditioning_; }

 private:
  void rebuild_map();
  // The mean squared distance over all points, unassociated ones at the gate.
  double truncated_cost(const GicpResult& r, std::size_t points) const noexcept;

  OdometryConfig config_;
  VoxelFilter filter_;
  CovarianceEstimator covariances_;
  Gicp gicp_;
  Cloud scan_;
  KdTree scan_tree_;
  std::vector<Point> scan_normals_;
  std::vector<std::vector<Point>> keyframes_;  // ring, odometry frame
  std::size_t next_keyframe_ = 0;
  std::vector<Point> merged_;
  VoxelFilter map_filter_;
  Target map_;
  bool have_map_ = false;
  Eigen::Isometry3d last_ = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d previous_ = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d last_keyframe_ = Eigen::Isometry3d::Identity();
  OdometryCounters counters_;
  Conditioning conditioning_;
};

// Motion compensation of a spinning lidar's scan (de-skewing): a point
// measured at the fraction s of the scan (0 its first firing, 1 its last),
// while the sensor moved by `motion` over the whole scan (constant
// velocity, in the scan's first frame), goes into the sensor's frame at the
// scan's end: p_end = motion^(s − 1) · p, where motion^u turns by u times
// its rotation (about the same axis) and moves by u times its translation.
// `points` and `fraction` are parallel.
void deskew(std::span<Point> points, std::span<const float> fraction, const Eigen::Isometry3d& motion) noexcept;

struct RelativePoseError {
  double translation_percent = 0.0;
  double rotation_deg_per_100m = 0.0;
  std::size_t segments = 0;
};
RelativePoseError relative_pose_error(std::span<const Eigen::Isometry3d> reference,
                                      std::span<const Eigen::Isometry3d> estimate, double segment = 10.0);
// The length of the path through the poses' positions (m).
double path_length(std::span<const Eigen::Isometry3d> poses) noexcept;

}  // namespace trailnav::perception::registration
