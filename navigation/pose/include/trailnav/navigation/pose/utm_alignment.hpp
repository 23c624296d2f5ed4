// The robot in UTM: GPS fixes aligned with the local odometry frame.
//
// The GPS track is smoothed by estimating the transform from the odometry
// frame to UTM (a 2-D rotation and translation) rather than the robot's
// position itself: between fixes the pose comes from odometry, which is
// smooth, and each fix corrects the transform. An extended Kalman filter
// carries six states with their covariance: the transform (easting,
// northing, rotation), the residual yaw-rate bias of the odometry's gyro,
// and the GPS's own slowly wandering error (east, north; a first-order
// Gauss-Markov process with correlation time `gps_bias_time`, which keeps a
// receiver's correlated error from looking like a thousand independent
// measurements). A fix's sigma (GST, or HDOP x UERE) is taken as its total
// error: `gps_white_sigma` of it is white noise, the rest the wandering error:
//
//   - prediction: the transform rotates at the gyro bias' rate, and takes a
//     random walk per metre driven and per second, applied as a rotation
//     about the robot's current position (the current position is what
//     odometry knows best), and its translation a random walk per metre;
//   - update: the antenna's UTM position (the GPS lever arm rotated by the
//     robot's attitude) = transform(antenna) + GPS error + white noise, the
//     white part being what the fix's GST sigma (or HDOP x UERE) leaves
//     beyond the wandering error;
//   - the gyro bias estimate is handed back to the odometry after each fix
//     (GyroOdometry::set_yaw_rate_bias), so the local frame stops drifting
//     once GPS has seen the robot turn or drive straight for a while;
//   - outliers: a fix whose squared Mahalanobis distance exceeds `gate` is
//     rejected and counted; `jump_after` rejected fixes in a row that agree
//     with each other mean the GPS itself jumped (a new correction source,
//     RTK lost): the filter re-anchors on them and counts a jump.
//
// Heading needs motion: fixes are buffered until the robot has moved
// `min_baseline` metres, then a robust least-squares fit of all buffered
// pairs (two passes, residuals beyond 3 sigma dropped) starts the filter.
// Before that only the position is known (`heading_valid` false).
//
// Place fixes (add_place: the camera's place recognition, docs/place.md)
// are positions of the robot's origin from a database recorded on an earlier
// drive: the same update without the GPS error states (their error is the
// database's and the match's, not the receiver's wandering one), gated the
// same way but never taken as a jump; before the heading is known they join
// the fixes the initial fit uses.
//
// Coordinates are in one UTM zone, chosen from the first fix unless
// configured, and kept when the robot crosses into the next zone. Headings
// are grid headings (counter-clockwise from grid east); `convergence` gives
// the angle from grid north to true north at the robot. Allocates only in
// the constructor.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "trailnav/drivers/gps/fix.hpp"
#include "trailnav/navigation/pose/gyro_odometry.hpp"

namespace trailnav::pose {

struct UtmAlignmentOptions {
  int zone = 0;                       // UTM zone 1..60; 0: from the first fix
  std::array<double, 3> antenna{0.0, 0.0, 0.0};  // m, GPS antenna in the robot frame (x forward, y left, z up)
  double min_baseline = 5.0;          // m the robot must move before the heading is estimated
  std::size_t init_capacity = 256;    // fixes buffered before the heading is known (oldest dropped)
  double uere = 4.0;                  // m, sigma = HDOP x UERE for fixes without GST
  double min_sigma = 0.3;             // m, floor of a fix's sigma
  double max_sigma = 30.0;            // m, fixes less certain than this are not used
  double heading_walk = 0.003;        // rad per sqrt(m) driven
  double heading_walk_time = 0.0005;  // rad per sqrt(s)
  double position_walk = 0.02;        // m per sqrt(m) driven
  double gyro_bias_sigma = 0.005;     // rad/s, prior of the odometry's residual yaw-rate bias
  double gyro_bias_walk = 2e-5;       // rad/s per sqrt(s)
  double gps_white_sigma = 1.5;       // m, the white part of a fix's error (the rest wanders)
  double gps_bias_time = 120.0;       // s, correlation time of the wandering part
  double gate = 16.0;                 // squared Mahalanobis distance (2 dof) beyond which a fix is an outlier
  int jump_after = 5;                 // outliers in a row that agree: the GPS jumped
  double jump_agreement = 2.0;        // m: how closely those outliers must agree
  double max_fix_age = 1.0;           // s between a fix's time and the newest odometry; older fixes are skipped
  double max_place_age = 5.0;         // s, the same for place fixes (they come a lag of frames late)
};

struct UtmAlignmentCounters {
  std::uint64_t fixes = 0;          // fixes offered
  std::uint64_t no_position = 0;    // without a 2-D or 3-D fix
  std::uint64_t too_uncertain = 0;  // sigma above max_sigma
  std::uint64_t no_odometry = 0;    // no odometry pose at the fix's time
  std::uint64_t used = 0;           // accepted by the filter or the initial fit
  std::uint64_t outliers = 0;       // rejected by the gate
  std::uint64_t jumps = 0;          // re-anchored after agreeing outliers
  std::uint64_t initial_fit_rejected = 0;  // buffered fixes the initial fit dropped
  // Place fixes (add_place): offered, used, rejected by the gate, and
  // refused (no position, no odometry pose at their time).
  std::uint64_t place_offered = 0, place_used = 0, place_outliers = 0, place_refused = 0;
};

// The standard deviation along the larger axis of a 2-D covariance
// [xx xy; xy yy]: the square root of its larger eigenvalue.
double larger_sigma(double xx, double xy, double yy) noexcept;

struct UtmPose {
  bool position_valid = false;
  bool heading_valid = false;
  std::int64_t time_ns = 0;
  int zone = 0;
  bool north = true;
  double easting = 0.0, northing = 0.0;  // m, the robot's origin (not the antenna)
  double altitude = 0.0;                 // m above the ellipsoid (from the last fix and odometry's z)
  double yaw = 0.0;                      // rad, grid heading, counter-clockwise from grid east
  double latitude = 0.0, longitude = 0.0;  // degrees, WGS84
  double convergence = 0.0;              // rad, meridian convergence at the robot
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // (easting, northing, yaw)
  double sigma_position() const noexcept;  // m, sqrt of the larger eigenvalue of the position covariance
};

// A fix the alignment took (not an outlier, not too uncertain), as the
// online mapping uses it (navigation/slam/mapping_task.hpp): where the
// antenna was in UTM and in the odometry frame, the odometry pose of the
// fix's time and the fix's standard deviation.
struct UsedFix {
  std::uint64_t serial = 0;  // counts the fixes used; 0: none yet
  std::int64_t time_ns = 0;
  Eigen::Vector2d utm = Eigen::Vector2d::Zero();           // antenna, easting and northing
  Eigen::Vector2d antenna_odom = Eigen::Vector2d::Zero();  // antenna, odometry frame
  double x = 0.0, y = 0.0, yaw = 0.0;                      // the robot's odometry pose at time_ns
  double sigma = 0.0;                                      // m
};

class UtmAlignment {
 public:
  explicit UtmAlignment(const UtmAlignmentOptions& options = {});

  // A GPS fix; `time_ns` is the time it is valid for, on the odometry's
  // clock. Hands the gyro bias estimate back to the odometry.
  void add_fix(const gps::GpsFix& fix, std::int64_t time_ns, GyroOdometry& odometry) noexcept;
  // A position of the robot's origin (WGS84 degrees) with a standard
  // deviation (m), valid at `time_ns` (which may be up to `max_place_age`
  // before the newest odometry). True when used.
  bool add_place(double lat, double lon, double sigma, std::int64_t time_ns, GyroOdometry& odometry) noexcept;
  // The robot's pose in UTM for a local pose.
  // `geodetic`: also latitude, longitude and convergence (one projection);
  // without, a caller that moves the pose first adds them with add_geodetic().
  UtmPose utm(const LocalPose& local, bool geodetic = true) const noexcept;
  void add_geodetic(UtmPose& u) const noexcept;

  bool heading_valid() const noexcept { return aligned_; }
  // The transform odometry -> UTM: easting, northing, rotation.
  Eigen::Vector3d transform() const noexcept { return state_.head<3>(); }
  // Its covariance.
  Eigen::Matrix3d covariance() const noexcept { return cov_.topLeftCorner<3, 3>(); }
  // The yaw-rate bias handed to the odometry so far (rad/s), and the GPS
  // error estimate (east, north, m).
  double gyro_bias() const noexcept { return gyro_bias_applied_; }
  Eigen::Vector2d gps_error() const noexcept { return state_.tail<2>(); }
  int zone() const noexcept { return zone_; }
  bool north() const noexcept { return north_; }
  // The newest fix used (serial 0 before the first).
  const UsedFix& last_used() const noexcept { return last_used_; }
  const UtmAlignmentCounters& counters() const noexcept { return counters_; }
  const UtmAlignmentOptions& options() const noexcept { return options_; }

  // UTM in the alignment's zone (GeographicLib); false outside its range.
  bool forward(double lat, double lon, double& easting, double& northing, double& convergence) const noexcept;
  bool reverse(double easting, double northing, double& lat, double& lon) const noexcept;

 private:
  struct Pair {
    Eigen::Vector2d odom;  // antenna in the odometry frame
    Eigen::Vector2d utm;
    double sigma = 1.0;
    double distance = 0.0;  // odometry distance at the fix
    std::int64_t time_ns = 0;
  };
  Eigen::Vector2d antenna_in_odom(const LocalPose& p) const noexcept;
  using Vector6 = Eigen::Matrix<double, 6, 1>;
  using Matrix6 = Eigen::Matrix<double, 6, 6>;
  void predict(const LocalPose& p) noexcept;
  // Process noise of the transform for a step of dd metres and dt seconds
  // at odometry position p (rotation about p).
  void add_drift(Eigen::Ref<Eigen::Matrix3d> cov, const Eigen::Vector2d& p, double dd, double dt) const noexcept;
  double white_sigma(double fix_sigma) const noexcept;
  double wander_sigma(double fix_sigma) const noexcept;
  void try_initial_fit() noexcept;
  // The Kalman update for innovation nu, measurement matrix h and white noise.
  void apply(const Eigen::Matrix<double, 2, 6>& h, const Eigen::Vector2d& nu, const Eigen::Matrix2d& s_inv, double white,
             GyroOdometry& odometry) noexcept;
  // The zone from a first position, and the position in it; false outside UTM.
  bool project(double lat, double lon, Eigen::Vector2d& z) noexcept;

  UtmAlignmentOptions options_;
  int zone_ = 0;
  bool north_ = true;
  bool aligned_ = false;
  Vector6 state_ = Vector6::Zero();  // tx, ty, theta, gyro bias, GPS error east, north
  Matrix6 cov_ = Matrix6::Identity();
  double gyro_bias_applied_ = 0.0;
  double wander_ = 0.0;  // m, the wandering error's sigma from the latest fix
  double last_distance_ = 0.0;
  std::int64_t last_time_ = 0;
  std::vector<Pair> init_;  // capacity fixed at construction
  std::array<Eigen::Vector2d, 16> rejected_{};
  int rejected_count_ = 0;
  double last_altitude_ = 0.0;
  double last_altitude_z_ = 0.0;
  UsedFix last_used_;  // also the position before the heading is known
  void record_used(const Eigen::Vector2d& z, const Eigen::Vector2d& a, const LocalPose& p, double sigma,
                   std::int64_t time_ns) noexcept;
  UtmAlignmentCounters counters_;
};

}  // namespace trailnav::pose
