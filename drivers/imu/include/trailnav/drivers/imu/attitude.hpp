// Roll and pitch for gravity alignment, and the bias-corrected yaw rate for
// gyro-aided odometry, from an IMU's samples.
//
// The device's own orientation is used when it sends one and the options
// allow it; otherwise a complementary filter integrates the rate of turn and
// pulls the tilt towards the measured gravity direction (Mahony-style, with a
// proportional gain that fades out while the acceleration's magnitude is far
// from g). The gravity direction is taken from the low-passed specific force,
// so that a vehicle's vibration and bumps average out instead of switching
// the correction off. Gyro bias is learned only at standstill: when, over a window, the
// rate of turn and the specific force barely vary and the latter is close to
// g (or when the odometry says the wheels stand still); while moving, the
// integral of the gravity error keeps learning the bias of the tilt axes
// (the heading axis' bias is unobservable from gravity on level ground). Pure: no allocation.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "trailnav/drivers/imu/imu_sample.hpp"

namespace trailnav::imu {

struct AttitudeOptions {
  bool use_device_orientation = true;  // take roll/pitch from the device's quaternion when present
  double tilt_gain = 1.0;              // 1/s: how fast the tilt follows gravity (Kp)
  double tilt_bias_gain = 0.05;        // 1/s^2: gyro bias learned from the gravity error while moving (Ki)
  double gravity_tolerance = 0.05;     // fraction of g: beyond it the gravity correction is off
  double accel_smoothing = 0.2;        // s: low-pass of the specific force used for the correction (vibration)
  double standstill_gyro_std = 0.01;   // rad/s: rate-of-turn spread below which the IMU may be still
  double standstill_accel_std = 0.05;  // m/s^2: specific-force spread below which it may be still
  double standstill_time = 1.0;        // s the above must hold before bias learning starts
  double bias_time_constant = 2.0;     // s: bias learning's averaging time at standstill
  double max_bias = 0.05;              // rad/s: larger apparent biases are not learned (a slow turn)
  double max_gap = 0.5;                // s: a longer gap between samples restarts integration
  double nominal_rate = 100.0;         // Hz: the step used when the device gives no usable time
};
// An empty string when consistent, otherwise which option and why.
std::string check_attitude_options(const AttitudeOptions& options);

enum class AttitudeSource : std::uint8_t { none, device, filter };

struct Attitude {
  std::int64_t time_ns = 0;
  double roll = 0.0, pitch = 0.0;  // rad; sensor frame relative to gravity (ZYX Euler angles)
  double yaw = 0.0;                // rad: device heading, or the filter's integrated heading (arbitrary origin)
  double yaw_rate = 0.0;           // rad/s about the gravity axis, bias corrected
  std::array<double, 3> gyro_bias{0, 0, 0};
  std::array<double, 4> orientation{1, 0, 0, 0};  // w, x, y, z
  bool standstill = false;
  AttitudeSource source = AttitudeSource::none;
  std::uint64_t samples = 0;
};

struct AttitudeCounters {
  std::uint64_t samples = 0;
  std::uint64_t gaps = 0;              // samples after a gap over max_gap (or time going backwards)
  std::uint64_t without_inertial = 0;  // samples lacking rate of turn or acceleration: ignored
  std::uint64_t standstill_samples = 0;
  std::uint64_t bias_updates = 0;
};

class AttitudeFilter {
 public:
  explicit AttitudeFilter(const AttitudeOptions& options = {}) noexcept : options_(options) {}

  // Consumes one sample; returns the attitude after it.
  const Attitude& update(const ImuSample& sample) noexcept;
  // From the wheel odometry: the robot stands still (true) or moves.
  void set_standstill_hint(bool still) noexcept { hint_ = still ? 1 : 0; }
  void clear_standstill_hint() noexcept { hint_ = -1; }
  // From the odometry: the acceleration of the IMU's motion (forward dv/dt,
  // sideways v * yaw rate) in the sensor frame, m/s^2; held until replaced.
  void set_kinematic_acceleration(const std::array<double, 3>& a) noexcept { kinematic_ = a; }

  const Attitude& attitude() const noexcept { return out_; }
  const AttitudeCounters& counters() const noexcept { return counters_; }
  void reset() noexcept;

 private:
  double step(const ImuSample& s) noexcept;  // seconds since the previous sample
  void detect_standstill(const ImuSample& s, double dt) noexcept;

  AttitudeOptions options_;
  Attitude out_;
  AttitudeCounters counters_;
  std::array<double, 4> q_{1, 0, 0, 0};  // filter state, sensor to level frame
  bool initialised_ = false;
  bool have_time_ = false;
  std::uint32_t last_fine_ = 0;
  double last_time_ = 0.0;
  std::int64_t last_ns_ = 0;
  // Exponential means and variances for standstill detection.
  std::array<double, 3> gyro_mean_{}, accel_mean_{};
  std::array<double, 3> gravity_{0, 0, 0};  // low-passed specific force minus kinematic acceleration
  double gyro_var_ = 0.0, accel_var_ = 0.0;
  double still_for_ = 0.0;
  int hint_ = -1;
  std::array<double, 3> kinematic_{0, 0, 0};
};

}  // namespace trailnav::imu
