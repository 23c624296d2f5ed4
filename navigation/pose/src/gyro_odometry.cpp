#include "trailnav/navigation/pose/gyro_odometry.hpp"

#include "trailnav/navigation/pose/angles.hpp"

#include <algorithm>
#include <cmath>

namespace trailnav::pose {
namespace {


std::int64_t seconds_ns(double s) noexcept { return static_cast<std::int64_t>(s * 1e9); }

}  // namespace

const char* pose_source_name(PoseSource s) noexcept {
  switch (s) {
    case PoseSource::none: return "none";
    case PoseSource::gyro_odometry: return "gyro_odometry";
    case PoseSource::wheels_only: return "wheels_only";
  }
  return "?";
}

GyroOdometry::GyroOdometry(const GyroOdometryOptions& options)
    : options_(options), history_(std::max<std::size_t>(options.history, 2)) {}

void GyroOdometry::remember() noexcept {
  history_[head_] = pose_;
  head_ = (head_ + 1) % history_.size();
  count_ = std::min(count_ + 1, history_.size());
}

void GyroOdometry::step(std::int64_t t, double yaw_rate, double roll, double pitch, PoseSource source) noexcept {
  if (!started_) {
    started_ = true;
    pose_ = LocalPose{};
    pose_.time_ns = t;
    pose_.roll = roll;
    pose_.pitch = pitch;
    pose_.source = source;
    remember();
    return;
  }
  const std::int64_t dt_ns = t - pose_.time_ns;
  if (dt_ns == 0) {  // wheels and IMU of the same instant
    pose_.roll = roll;
    pose_.pitch = pitch;
    pose_.source = source;
    return;
  }
  if (dt_ns < 0 || dt_ns > seconds_ns(options_.max_step)) {
    ++counters_.gaps;
    if (dt_ns > 0) {
      pose_.time_ns = t;
      pose_.roll = roll;
      pose_.pitch = pitch;
      remember();
    }
    return;
  }
  const double dt = static_cast<double>(dt_ns) * 1e-9;
  const bool fresh = wheel_time_ >= 0 && t - wheel_time_ <= seconds_ns(options_.wheel_timeout);
  if (!fresh) ++counters_.stale_wheel_steps;
  const double speed = fresh ? wheel_speed_ : 0.0;
  const bool standstill = std::abs(speed) < options_.standstill_speed &&
                          (!fresh || std::abs(wheel_yaw_rate_) < options_.standstill_yaw_rate);
  pose_.standstill = standstill;
  pose_.speed = standstill ? 0.0 : speed;
  pose_.yaw_rate = standstill ? 0.0 : yaw_rate;
  if (standstill) {
    ++counters_.standstill_steps;
  } else {
    // Midpoint rule for heading and tilt.
    const double yaw_mid = pose_.yaw + 0.5 * yaw_rate * dt;
    const double pitch_mid = 0.5 * (pose_.pitch + pitch);
    const double ds = speed * dt;
    pose_.x += ds * std::cos(yaw_mid) * std::cos(pitch_mid);
    pose_.y += ds * std::sin(yaw_mid) * std::cos(pitch_mid);
    pose_.z -= ds * std::sin(pitch_mid);  // ZYX: positive pitch puts the nose down
    pose_.distance += std::abs(ds);
    pose_.yaw = wrap_angle(pose_.yaw + yaw_rate * dt);
  }
  pose_.roll = roll;
  pose_.pitch = pitch;
  pose_.time_ns = t;
  pose_.source = source;
  pose_.translation_valid = fresh || wheel_time_ < 0;  // a robot without wheel odometry has nothing better
  // Nor one without an IMU; but one whose IMU has not spoken yet waits for it.
  pose_.rotation_valid = source == PoseSource::gyro_odometry || (last_imu_ < 0 && !options_.imu_expected);
  remember();
}

void GyroOdometry::add_wheels(const can::OdometryState& wheels) noexcept {
  ++counters_.wheel_readings;
  wheel_time_ = wheels.time_ns;
  wheel_speed_ = wheels.speed;
  wheel_yaw_rate_ = wheels.yaw_rate;
  const bool imu_alive = last_imu_ >= 0 && wheels.time_ns - last_imu_ <= seconds_ns(options_.imu_timeout);
  if (!imu_alive) {
    ++counters_.wheel_steps;
    step(wheels.time_ns, wheels.yaw_rate, pose_.roll, pose_.pitch, PoseSource::wheels_only);
  }
}

void GyroOdometry::add_imu(const imu::Attitude& attitude) noexcept {
  last_imu_ = attitude.time_ns;
  ++counters_.imu_steps;
  step(attitude.time_ns, attitude.yaw_rate - yaw_rate_bias_, attitude.roll, attitude.pitch, PoseSource::gyro_odometry);
}

bool GyroOdometry::pose_at(std::int64_t t, LocalPose& out) const noexcept {
  if (count_ == 0) return false;
  const std::size_t n = history_.size();
  auto at = [&](std::size_t k) -> const LocalPose& { return history_[(head_ + n - count_ + k) % n]; };
  const LocalPose& newest = at(count_ - 1);
  if (t >= newest.time_ns) {
    if (t - newest.time_ns > seconds_ns(options_.max_step)) return false;
    out = newest;
    const double dt = static_cast<double>(t - newest.time_ns) * 1e-9;
    out.x += newest.speed * dt * std::cos(newest.yaw);
    out.y += newest.speed * dt * std::sin(newest.yaw);
    out.yaw = wrap_angle(newest.yaw + newest.yaw_rate * dt);
    out.time_ns = t;
    return true;
  }
  if (t < at(0).time_ns) return false;
  // Binary search for the first kept pose at or after t.
  std::size_t lo = 0, hi = count_ - 1;
  while (lo < hi) {
    const std::size_t mid = (lo + hi) / 2;
    if (at(mid).time_ns < t) {
      lo = mid + 1;
    } else {
      hi = mid;
    }
  }
  const LocalPose& b = at(lo);
  if (lo == 0 || b.time_ns == t) {
    out = b;
    return true;
  }
  const LocalPose& a = at(lo - 1);
  const double f = static_cast<double>(t - a.time_ns) / static_cast<double>(b.time_ns - a.time_ns);
  out = b;
  out.time_ns = t;
  out.x = a.x + f * (b.x - a.x);
  out.y = a.y + f * (b.y - a.y);
  out.z = a.z + f * (b.z - a.z);
  out.roll = a.roll + f * (b.roll - a.roll);
  out.pitch = a.pitch + f * (b.pitch - a.pitch);
  out.yaw = wrap_angle(a.yaw + f * wrap_angle(b.yaw - a.yaw));
  out.distance = a.distance + f * (b.distance - a.distance);
  return true;
}

}  // namespace trailnav::pose
