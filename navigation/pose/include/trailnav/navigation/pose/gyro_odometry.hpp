// The local odometry frame: wheel odometry's speed with the IMU's yaw rate
// (gyro-aided odometry) and its roll and pitch, integrated at the IMU rate.
//
// The frame starts at the robot's first pose, heading 0, z up along gravity.
// Each IMU sample advances the pose by the wheel speed (held from the latest
// CAN reading) along the robot's forward axis tilted by pitch, and turns it by
// the bias-corrected yaw rate about gravity. When the wheels report a
// standstill (no speed and no turning), nothing moves and the heading is held,
// so gyro drift does not turn a parked robot. Without IMU samples for
// `imu_timeout`, the wheels alone (their yaw rate) carry the pose, flagged.
// Poses are kept for `history` steps so that a GPS fix or a lidar revolution
// can look up the pose at its own time. Allocates only in the constructor.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "trailnav/drivers/can/wheel_odometry.hpp"
#include "trailnav/drivers/imu/attitude.hpp"

namespace trailnav::pose {

enum class PoseSource : std::uint8_t { none, gyro_odometry, wheels_only };
const char* pose_source_name(PoseSource s) noexcept;

struct LocalPose {
  std::int64_t time_ns = 0;  // the clock of the readings (host time, runtime/host_clock.hpp, or a recording's time)
  double x = 0.0, y = 0.0, z = 0.0;           // m, odometry frame (x: initial heading, z: up)
  double roll = 0.0, pitch = 0.0, yaw = 0.0;  // rad, ZYX Euler angles of the robot in the odometry frame
  double speed = 0.0;                         // m/s, forward
  double yaw_rate = 0.0;                      // rad/s about gravity
  double distance = 0.0;                      // m driven (absolute)
  bool standstill = false;
  // False while the wheels, once heard, have gone quiet (a CAN bus-off, a
  // cable): the speed is then unknown and the position stands still while
  // the robot may not. What was mapped in the odometry frame before and what
  // is seen after no longer fit together (docs/pose.md).
  bool translation_valid = true;
  // False while the IMU, once heard, has gone quiet (a cable, a serial port
  // whose bytes stopped coming) and the wheels' yaw rate alone turns the
  // pose: wheel slip then turns the odometry frame, and what was mapped
  // before and what is seen after no longer fit together either.
  bool rotation_valid = true;
  PoseSource source = PoseSource::none;
};

struct GyroOdometryOptions {
  double imu_timeout = 0.1;        // s without IMU samples before the wheels alone carry the pose
  double wheel_timeout = 0.25;     // s after which a wheel speed is stale (speed taken as 0, counted)
  double max_step = 0.2;           // s: a longer step is a gap, not integrated (counted)
  double standstill_speed = 0.01;  // m/s
  double standstill_yaw_rate = 0.005;  // rad/s (wheel odometry's)
  std::size_t history = 1024;      // poses kept for lookups by time (about 10 s at 100 Hz)
  // An IMU is configured (trailnavd sets it when it runs one). Then a pose
  // the wheels alone turned is never a measured rotation, also before the
  // IMU's first reading: at start-up the IMU may speak later than the CAN
  // bus, and a map made with the wheels' slipping yaw rate and continued
  // with the IMU's would not fit together.
  bool imu_expected = false;
};

struct GyroOdometryCounters {
  std::uint64_t imu_steps = 0;
  std::uint64_t wheel_steps = 0;       // steps carried by the wheels alone
  std::uint64_t wheel_readings = 0;
  std::uint64_t gaps = 0;              // steps longer than max_step (or time going backwards)
  std::uint64_t stale_wheel_steps = 0; // IMU steps without a fresh wheel speed
  std::uint64_t standstill_steps = 0;
};

class GyroOdometry {
 public:
  explicit GyroOdometry(const GyroOdometryOptions& options = {});

  // A wheel odometry reading (speed, yaw rate). Integrates itself only while
  // the IMU is silent.
  void add_wheels(const can::OdometryState& wheels) noexcept;
  // An IMU sample through the attitude filter: roll, pitch, yaw rate.
  void add_imu(const imu::Attitude& attitude) noexcept;

  // A yaw-rate bias to take off the IMU's yaw rate from now on (rad/s; the
  // UTM alignment estimates it from GPS).
  void set_yaw_rate_bias(double bias) noexcept { yaw_rate_bias_ = bias; }
  double yaw_rate_bias() const noexcept { return yaw_rate_bias_; }

  const LocalPose& pose() const noexcept { return pose_; }
  // The pose at time t, interpolated between kept poses (extrapolated by at
  // most max_step past the newest). False outside what is kept.
  bool pose_at(std::int64_t t, LocalPose& out) const noexcept;
  const GyroOdometryCounters& counters() const noexcept { return counters_; }
  const GyroOdometryOptions& options() const noexcept { return options_; }

 private:
  void step(std::int64_t t, double yaw_rate, double roll, double pitch, PoseSource source) noexcept;
  void remember() noexcept;

  GyroOdometryOptions options_;
  LocalPose pose_;
  bool started_ = false;
  std::int64_t last_imu_ = -1;
  std::int64_t wheel_time_ = -1;
  double wheel_speed_ = 0.0;
  double wheel_yaw_rate_ = 0.0;
  double yaw_rate_bias_ = 0.0;
  std::vector<LocalPose> history_;  // ring
  std::size_t head_ = 0;            // next slot
  std::size_t count_ = 0;
  GyroOdometryCounters counters_;
};

}  // namespace trailnav::pose
