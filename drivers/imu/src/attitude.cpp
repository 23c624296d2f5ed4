#include "trailnav/drivers/imu/attitude.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace trailnav::imu {
namespace {

Eigen::Quaterniond to_eigen(const std::array<double, 4>& q) noexcept { return {q[0], q[1], q[2], q[3]}; }
std::array<double, 4> from_eigen(const Eigen::Quaterniond& q) noexcept { return {q.w(), q.x(), q.y(), q.z()}; }
Eigen::Vector3d vec(const std::array<double, 3>& v) noexcept { return {v[0], v[1], v[2]}; }

// Averaging time of the standstill detector's running means and spreads.
constexpr double kWindow = 0.5;

}  // namespace

std::string check_attitude_options(const AttitudeOptions& o) {
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (!(std::isfinite(o.tilt_gain) && o.tilt_gain >= 0.0)) return "tilt_gain must be zero or positive";
  if (!(std::isfinite(o.tilt_bias_gain) && o.tilt_bias_gain >= 0.0)) return "tilt_bias_gain must be zero or positive";
  if (!positive(o.gravity_tolerance) || o.gravity_tolerance >= 1.0) return "gravity_tolerance must be in (0, 1)";
  if (!(std::isfinite(o.accel_smoothing) && o.accel_smoothing >= 0.0)) return "accel_smoothing must be zero or positive";
  if (!positive(o.standstill_gyro_std)) return "standstill_gyro_std must be positive";
  if (!positive(o.standstill_accel_std)) return "standstill_accel_std must be positive";
  if (!(std::isfinite(o.standstill_time) && o.standstill_time >= 0.0)) return "standstill_time must be zero or positive";
  if (!positive(o.bias_time_constant)) return "bias_time_constant must be positive";
  if (!positive(o.max_bias)) return "max_bias must be positive";
  if (!positive(o.max_gap)) return "max_gap must be positive";
  if (!positive(o.nominal_rate)) return "nominal_rate must be positive";
  return {};
}

void AttitudeFilter::reset() noexcept {
  const AttitudeOptions o = options_;
  *this = AttitudeFilter(o);
}

double AttitudeFilter::step(const ImuSample& s) noexcept {
  double dt = 0.0;
  bool known = true;
  if (s.has(kSampleTimeFine)) {
    dt = static_cast<double>(static_cast<std::uint32_t>(s.sample_time_fine - last_fine_)) * 1e-4;
  } else if (s.has(kSampleTime)) {
    dt = s.sample_time - last_time_;
  } else if (s.time_ns != 0) {
    dt = static_cast<double>(s.time_ns - last_ns_) * 1e-9;
  } else {
    known = false;
  }
  const bool first = !have_time_;
  last_fine_ = s.sample_time_fine;
  last_time_ = s.sample_time;
  last_ns_ = s.time_ns;
  have_time_ = true;
  if (first) return 0.0;
  if (!known) return 1.0 / options_.nominal_rate;
  if (!(dt > 0.0) || dt > options_.max_gap) {
    ++counters_.gaps;
    return 0.0;
  }
  return dt;
}

void AttitudeFilter::detect_standstill(const ImuSample& s, double dt) noexcept {
  if (counters_.samples == 1) {
    gyro_mean_ = s.rate_of_turn;
    accel_mean_ = s.acceleration;
    gyro_var_ = accel_var_ = 1.0;  // unknown spread: not still yet
  } else if (dt > 0.0) {
    const double a = std::min(1.0, dt / kWindow);
    double gv = 0.0, av = 0.0;
    for (std::size_t i = 0; i < 3; ++i) {
      const double dg = s.rate_of_turn[i] - gyro_mean_[i];
      const double da = s.acceleration[i] - accel_mean_[i];
      gyro_mean_[i] += a * dg;
      accel_mean_[i] += a * da;
      gv += dg * dg;
      av += da * da;
    }
    gyro_var_ += a * (gv - gyro_var_);
    accel_var_ += a * (av - accel_var_);
  }
  bool still = false;
  if (hint_ >= 0) {
    still = hint_ == 1;
  } else {
    const double g = vec(s.acceleration).norm();
    still = std::sqrt(gyro_var_) < options_.standstill_gyro_std &&
            std::sqrt(accel_var_) < options_.standstill_accel_std &&
            std::abs(g - kStandardGravity) < options_.gravity_tolerance * kStandardGravity;
  }
  still_for_ = still ? still_for_ + dt : 0.0;
  out_.standstill = still && still_for_ >= options_.standstill_time;
  if (!out_.standstill) return;
  ++counters_.standstill_samples;
  if (vec(s.rate_of_turn).norm() > options_.max_bias || dt <= 0.0) return;
  const double b = std::min(1.0, dt / options_.bias_time_constant);
  for (std::size_t i = 0; i < 3; ++i) out_.gyro_bias[i] += b * (s.rate_of_turn[i] - out_.gyro_bias[i]);
  ++counters_.bias_updates;
}

const Attitude& AttitudeFilter::update(const ImuSample& s) noexcept {
  ++counters_.samples;
  out_.time_ns = s.time_ns;
  const bool device = options_.use_device_orientation && s.has(kOrientation);
  if (!s.has(kRateOfTurn) || !s.has(kAcceleration)) {
    ++counters_.without_inertial;
    if (!device) return out_;
  }
  const double dt = step(s);
  Eigen::Vector3d omega = Eigen::Vector3d::Zero();
  if (s.has(kRateOfTurn) && s.has(kAcceleration)) {
    detect_standstill(s, dt);
    omega = vec(s.rate_of_turn) - vec(out_.gyro_bias);
    const Eigen::Vector3d measured = vec(s.acceleration) - vec(kinematic_);
    Eigen::Vector3d f = vec(gravity_);
    if (!initialised_ || options_.accel_smoothing <= 0.0) {
      f = measured;
    } else if (dt > 0.0) {
      f += std::min(1.0, dt / options_.accel_smoothing) * (measured - f);
    }
    gravity_ = {f.x(), f.y(), f.z()};
    const double g = f.norm();
    Eigen::Quaterniond q = to_eigen(q_);
    if (!initialised_ && g > 0.0) {
      // Level the first estimate with gravity; heading starts at zero.
      const double roll = std::atan2(f.y(), f.z());
      const double pitch = std::atan2(-f.x(), std::hypot(f.y(), f.z()));
      q = Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) * Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX());
      initialised_ = true;
    } else if (dt > 0.0) {
      Eigen::Vector3d correction = Eigen::Vector3d::Zero();
      const double weight = std::max(0.0, 1.0 - std::abs(g / kStandardGravity - 1.0) / options_.gravity_tolerance);
      if (weight > 0.0) {
        const Eigen::Vector3d up = q.conjugate() * Eigen::Vector3d::UnitZ();  // predicted, sensor frame
        const Eigen::Vector3d error = weight * (f / g).cross(up);
        correction = options_.tilt_gain * error;
        if (!out_.standstill && options_.tilt_bias_gain > 0.0) {
          Eigen::Vector3d b = vec(out_.gyro_bias) - options_.tilt_bias_gain * dt * error;
          if (b.norm() > options_.max_bias) b *= options_.max_bias / b.norm();
          out_.gyro_bias = {b.x(), b.y(), b.z()};
        }
      }
      const Eigen::Vector3d theta = (omega + correction) * dt;
      const double angle = theta.norm();
      if (angle > 0.0) q = q * Eigen::Quaterniond(Eigen::AngleAxisd(angle, theta / angle));
      q.normalize();
    }
    q_ = from_eigen(q);
  }
  Eigen::Quaterniond o = device ? to_eigen(s.orientation).normalized() : to_eigen(q_);
  out_.source = device ? AttitudeSource::device : AttitudeSource::filter;
  if (!device && !initialised_) out_.source = AttitudeSource::none;
  out_.orientation = from_eigen(o);
  const Eigen::Matrix3d r = o.toRotationMatrix();
  out_.roll = std::atan2(r(2, 1), r(2, 2));
  out_.pitch = std::asin(std::clamp(-r(2, 0), -1.0, 1.0));
  out_.yaw = std::atan2(r(1, 0), r(0, 0));
  out_.yaw_rate = (r * omega).z();
  out_.samples = counters_.samples;
  return out_;
}

}  // namespace trailnav::imu
