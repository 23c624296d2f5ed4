#include "trailnav/navigation/pose/utm_alignment.hpp"

#include "trailnav/navigation/pose/angles.hpp"

#include <GeographicLib/UTMUPS.hpp>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace trailnav::pose {
namespace {

constexpr double kDeg = kPi / 180.0;

Eigen::Matrix2d rotation(double a) noexcept {
  Eigen::Matrix2d r;
  r << std::cos(a), -std::sin(a), std::sin(a), std::cos(a);
  return r;
}

// d/dtheta of R(theta) v = J R v, J the 90-degree rotation.
Eigen::Vector2d perp(const Eigen::Vector2d& v) noexcept { return {-v.y(), v.x()}; }

bool finite(double v) noexcept { return std::isfinite(v); }

}  // namespace

double larger_sigma(double xx, double xy, double yy) noexcept {
  const double tr = xx + yy, det = xx * yy - xy * xy;
  const double disc = std::sqrt(std::max(0.0, tr * tr / 4 - det));
  return std::sqrt(std::max(0.0, tr / 2 + disc));
}

double UtmPose::sigma_position() const noexcept {
  return larger_sigma(covariance(0, 0), covariance(0, 1), covariance(1, 1));
}

UtmAlignment::UtmAlignment(const UtmAlignmentOptions& options) : options_(options), zone_(options.zone) {
  init_.reserve(std::max<std::size_t>(options.init_capacity, 8));
}

bool UtmAlignment::forward(double lat, double lon, double& easting, double& northing,
                           double& convergence) const noexcept {
  if (zone_ < 1 || zone_ > 60 || !(lat >= -80.0 && lat <= 84.0) || !(lon >= -180.0 && lon <= 180.0)) return false;
  int zone = 0;
  bool north = true;
  double gamma = 0.0, k = 0.0;
  try {
    GeographicLib::UTMUPS::Forward(lat, lon, zone, north, easting, northing, gamma, k, zone_);
  } catch (...) {
    return false;
  }
  // One hemisphere's northings throughout.
  if (north != north_) northing += north_ ? -1e7 : 1e7;
  convergence = gamma * kDeg;
  return true;
}

bool UtmAlignment::reverse(double easting, double northing, double& lat, double& lon) const noexcept {
  if (zone_ < 1 || zone_ > 60 || !finite(easting) || !finite(northing)) return false;
  try {
    GeographicLib::UTMUPS::Reverse(zone_, north_, easting, northing, lat, lon);
  } catch (...) {
    return false;
  }
  return true;
}

Eigen::Vector2d UtmAlignment::antenna_in_odom(const LocalPose& p) const noexcept {
  const double cr = std::cos(p.roll), sr = std::sin(p.roll);
  const double cp = std::cos(p.pitch), sp = std::sin(p.pitch);
  const double cy = std::cos(p.yaw), sy = std::sin(p.yaw);
  const double ax = options_.antenna[0], ay = options_.antenna[1], az = options_.antenna[2];
  // First two rows of Rz(yaw) Ry(pitch) Rx(roll).
  const double x = cy * cp * ax + (cy * sp * sr - sy * cr) * ay + (cy * sp * cr + sy * sr) * az;
  const double y = sy * cp * ax + (sy * sp * sr + cy * cr) * ay + (sy * sp * cr - cy * sr) * az;
  return {p.x + x, p.y + y};
}

double UtmAlignment::white_sigma(double fix_sigma) const noexcept {
  return std::max(options_.min_sigma, std::min(fix_sigma, options_.gps_white_sigma));
}

double UtmAlignment::wander_sigma(double fix_sigma) const noexcept {
  const double w = white_sigma(fix_sigma);
  return std::sqrt(std::max(0.0, fix_sigma * fix_sigma - w * w));
}

void UtmAlignment::add_drift(Eigen::Ref<Eigen::Matrix3d> cov, const Eigen::Vector2d& p, double dd,
                             double dt) const noexcept {
  const double q = options_.heading_walk * options_.heading_walk * dd +
                   options_.heading_walk_time * options_.heading_walk_time * dt;
  // A heading error of odometry rotates the frame about where the robot is now.
  const Eigen::Vector2d m = rotation(state_(2)) * p;
  const Eigen::Vector3d g(m.y(), -m.x(), 1.0);
  cov += q * g * g.transpose();
  cov.topLeftCorner<2, 2>() += options_.position_walk * options_.position_walk * dd * Eigen::Matrix2d::Identity();
}

void UtmAlignment::predict(const LocalPose& p) noexcept {
  const double dd = std::max(0.0, p.distance - last_distance_);
  const double dt = std::max(0.0, static_cast<double>(p.time_ns - last_time_) * 1e-9);
  const Eigen::Vector2d pos(p.x, p.y);
  // A residual gyro bias b turns odometry by b dt, so the transform turns
  // back by as much, about the robot's current position.
  Matrix6 f = Matrix6::Identity();
  const Eigen::Vector2d rp = rotation(state_(2)) * pos;
  f(2, 3) = -dt;
  f.block<2, 1>(0, 3) = perp(rp) * dt;
  const double turn = -state_(3) * dt;
  state_.head<2>() += rp - rotation(state_(2) + turn) * pos;
  state_(2) = wrap_angle(state_(2) + turn);
  // The GPS error decays towards zero.
  const double decay = options_.gps_bias_time > 0.0 ? std::exp(-dt / options_.gps_bias_time) : 0.0;
  f(4, 4) = f(5, 5) = decay;
  state_.tail<2>() *= decay;
  cov_ = f * cov_ * f.transpose();
  add_drift(cov_.topLeftCorner<3, 3>(), pos, dd, dt);
  cov_(3, 3) += options_.gyro_bias_walk * options_.gyro_bias_walk * dt;
  const double qb = wander_ * wander_ * (1.0 - decay * decay);
  cov_(4, 4) += qb;
  cov_(5, 5) += qb;
  last_distance_ = std::max(last_distance_, p.distance);
  last_time_ = std::max(last_time_, p.time_ns);
}

void UtmAlignment::try_initial_fit() noexcept {
  const std::size_t n = init_.size();
  if (n < 3) return;
  double baseline = 0.0;
  for (const Pair& q : init_) baseline = std::max(baseline, (q.odom - init_.front().odom).norm());
  if (baseline < options_.min_baseline) return;
  // Pairs the fit drops are marked by a negative sigma (no second buffer).
  double theta = 0.0;
  Eigen::Vector2d t = Eigen::Vector2d::Zero();
  double sw = 0.0, swa2 = 0.0;
  Eigen::Vector2d abar = Eigen::Vector2d::Zero();
  std::size_t kept = n;
  for (int pass = 0; pass < 3; ++pass) {
    sw = 0.0;
    abar.setZero();
    Eigen::Vector2d gbar = Eigen::Vector2d::Zero();
    for (const Pair& q : init_) {
      if (q.sigma <= 0.0) continue;
      const double w = 1.0 / (q.sigma * q.sigma);
      sw += w;
      abar += w * q.odom;
      gbar += w * q.utm;
    }
    if (sw <= 0.0) return;
    abar /= sw;
    gbar /= sw;
    double num = 0.0, den = 0.0;
    swa2 = 0.0;
    for (const Pair& q : init_) {
      if (q.sigma <= 0.0) continue;
      const double w = 1.0 / (q.sigma * q.sigma);
      const Eigen::Vector2d a = q.odom - abar, g = q.utm - gbar;
      num += w * (a.x() * g.y() - a.y() * g.x());
      den += w * a.dot(g);
      swa2 += w * a.squaredNorm();
    }
    theta = std::atan2(num, den);
    t = gbar - rotation(theta) * abar;
    if (pass == 2) break;
    // Drop pairs beyond 3 sigma of the fit (marked by a negative sigma).
    const Eigen::Matrix2d r = rotation(theta);
    kept = 0;
    for (Pair& q : init_) {
      if (q.sigma <= 0.0) continue;
      if ((q.utm - (r * q.odom + t)).norm() > 3.0 * q.sigma) {
        q.sigma = -q.sigma;
        ++counters_.initial_fit_rejected;
      } else {
        ++kept;
      }
    }
    if (kept < 3) {
      for (Pair& q : init_) q.sigma = std::abs(q.sigma);
      return;
    }
  }
  if (swa2 <= 0.0) return;
  // The fit's covariance from the white part of the fixes' noise; the
  // wandering GPS error is common to the buffered fixes (they span seconds,
  // its correlation time minutes), so the fit knows the transform plus that
  // error, and the transform alone only as well as the error's prior.
  Eigen::Matrix3d base = Eigen::Matrix3d::Zero();
  base(0, 0) = base(1, 1) = 1.0 / sw;
  base(2, 2) = 1.0 / swa2;
  Eigen::Matrix3d a = Eigen::Matrix3d::Identity();
  a.block<2, 1>(0, 2) = -perp(rotation(theta) * abar);
  state_.setZero();
  state_.head<2>() = t;
  state_(2) = theta;
  cov_.setZero();
  cov_.topLeftCorner<3, 3>() = a * base * a.transpose();
  const double b2 = wander_ * wander_;
  cov_.topLeftCorner<2, 2>() += b2 * Eigen::Matrix2d::Identity();
  cov_.block<2, 2>(4, 4) = b2 * Eigen::Matrix2d::Identity();
  cov_.block<2, 2>(0, 4) = cov_.block<2, 2>(4, 0) = -b2 * Eigen::Matrix2d::Identity();
  cov_(3, 3) = options_.gyro_bias_sigma * options_.gyro_bias_sigma;
  last_distance_ = init_.back().distance;
  last_time_ = init_.back().time_ns;
  aligned_ = true;
  init_.clear();
}

void UtmAlignment::add_fix(const gps::GpsFix& fix, std::int64_t time_ns, GyroOdometry& odometry) noexcept {
  ++counters_.fixes;
  if (!fix.has_fix() || !finite(fix.lat) || !finite(fix.lon)) {
    ++counters_.no_position;
    return;
  }
  double sigma = 2.0 * options_.uere;
  if (finite(fix.sigma_lat) && finite(fix.sigma_lon)) {
    sigma = std::max(fix.sigma_lat, fix.sigma_lon);
  } else if (finite(fix.hdop)) {
    sigma = fix.hdop * options_.uere;
  }
  sigma = std::max(sigma, options_.min_sigma);
  if (!(sigma <= options_.max_sigma)) {
    ++counters_.too_uncertain;
    return;
  }
  Eigen::Vector2d z;
  if (!project(fix.lat, fix.lon, z)) {
    ++counters_.no_position;
    return;
  }
  LocalPose p;
  if (!odometry.pose_at(time_ns, p) ||
      odometry.pose().time_ns - time_ns > static_cast<std::int64_t>(options_.max_fix_age * 1e9)) {
    ++counters_.no_odometry;
    return;
  }
  const Eigen::Vector2d a = antenna_in_odom(p);
  const double alt = finite(fix.alt_hae()) ? fix.alt_hae() : fix.alt_msl;
  if (finite(alt)) {
    last_altitude_ = alt - options_.antenna[2];
    last_altitude_z_ = p.z;
  }

  wander_ = wander_sigma(sigma);
  if (!aligned_) {
    if (init_.size() == init_.capacity()) init_.erase(init_.begin());
    init_.push_back({a, z, white_sigma(sigma), p.distance, time_ns});
    last_time_ = time_ns;
    ++counters_.used;
    record_used(z, a, p, sigma, time_ns);
    try_initial_fit();
    return;
  }

  predict(p);
  const double white = white_sigma(sigma);
  const Eigen::Vector2d ra = rotation(state_(2)) * a;
  Eigen::Matrix<double, 2, 6> h = Eigen::Matrix<double, 2, 6>::Zero();
  h(0, 0) = h(1, 1) = 1.0;
  h(0, 2) = -ra.y();
  h(1, 2) = ra.x();
  h(0, 4) = h(1, 5) = 1.0;
  const Eigen::Vector2d nu = z - (ra + state_.head<2>() + state_.tail<2>());
  const Eigen::Matrix2d s = h * cov_ * h.transpose() + white * white * Eigen::Matrix2d::Identity();
  const Eigen::Matrix2d s_inv = s.inverse();
  const double d2 = nu.dot(s_inv * nu);
  if (!(d2 <= options_.gate)) {
    ++counters_.outliers;
    if (rejected_count_ == static_cast<int>(rejected_.size())) {
      std::copy(rejected_.begin() + 1, rejected_.end(), rejected_.begin());
      --rejected_count_;
    }
    rejected_[static_cast<std::size_t>(rejected_count_++)] = nu;
    if (rejected_count_ >= options_.jump_after) {
      const auto first = static_cast<std::size_t>(rejected_count_ - options_.jump_after);
      const auto last = static_cast<std::size_t>(rejected_count_);
      Eigen::Vector2d mean = Eigen::Vector2d::Zero();
      for (std::size_t k = first; k < last; ++k) mean += rejected_[k];
      mean /= static_cast<double>(options_.jump_after);
      double spread = 0.0;
      for (std::size_t k = first; k < last; ++k) spread = std::max(spread, (rejected_[k] - mean).norm());
      if (spread <= options_.jump_agreement) {
        // The GPS moved for good: follow it, and say so in the uncertainty.
        state_.head<2>() += mean;
        cov_.topLeftCorner<2, 2>() += (mean * mean.transpose()) + sigma * sigma * Eigen::Matrix2d::Identity();
        ++counters_.jumps;
        rejected_count_ = 0;
      }
    }
    return;
  }
  rejected_count_ = 0;
  apply(h, nu, s_inv, white, odometry);
  ++counters_.used;
  record_used(z, a, p, sigma, time_ns);
}

bool UtmAlignment::project(double lat, double lon, Eigen::Vector2d& z) noexcept {
  if (!finite(lat) || !finite(lon)) return false;
  if (zone_ == 0) {
    if (!(lat >= -80.0 && lat <= 84.0)) return false;
    zone_ = GeographicLib::UTMUPS::StandardZone(lat, lon);
    north_ = lat >= 0.0;
  }
  double e = 0.0, n = 0.0, gamma = 0.0;
  if (!forward(lat, lon, e, n, gamma)) return false;
  z = {e, n};
  return true;
}

void UtmAlignment::apply(const Eigen::Matrix<double, 2, 6>& h, const Eigen::Vector2d& nu, const Eigen::Matrix2d& s_inv,
                         double white, GyroOdometry& odometry) noexcept {
  const Eigen::Matrix<double, 6, 2> k = cov_ * h.transpose() * s_inv;
  state_ += k * nu;
  state_(2) = wrap_angle(state_(2));
  const Matrix6 ikh = Matrix6::Identity() - k * h;
  cov_ = ikh * cov_ * ikh.transpose() + white * white * k * k.transpose();  // Joseph form
  cov_ = 0.5 * (cov_ + cov_.transpose());
  // Hand the gyro bias to the odometry: from now on it turns right, and the
  // state holds what is left.
  gyro_bias_applied_ += state_(3);
  state_(3) = 0.0;
  odometry.set_yaw_rate_bias(gyro_bias_applied_);
}

bool UtmAlignment::add_place(double lat, double lon, double sigma, std::int64_t time_ns, GyroOdometry& odometry) noexcept {
  ++counters_.place_offered;
  Eigen::Vector2d z;
  LocalPose p;
  if (!(sigma > 0.0) || !finite(sigma) || !project(lat, lon, z) || !odometry.pose_at(time_ns, p) ||
      odometry.pose().time_ns - time_ns > static_cast<std::int64_t>(options_.max_place_age * 1e9)) {
    ++counters_.place_refused;
    return false;
  }
  sigma = std::max(sigma, options_.min_sigma);
  const Eigen::Vector2d a(p.x, p.y);  // the robot's origin
  if (!aligned_) {
    if (init_.size() == init_.capacity()) init_.erase(init_.begin());
    init_.push_back({a, z, sigma, p.distance, time_ns});
    last_time_ = std::max(last_time_, time_ns);
    ++counters_.place_used;
    try_initial_fit();
    return true;
  }
  predict(p);
  const Eigen::Vector2d ra = rotation(state_(2)) * a;
  Eigen::Matrix<double, 2, 6> h = Eigen::Matrix<double, 2, 6>::Zero();
  h(0, 0) = h(1, 1) = 1.0;
  h(0, 2) = -ra.y();
  h(1, 2) = ra.x();
  const Eigen::Vector2d nu = z - (ra + state_.head<2>());
  const Eigen::Matrix2d s = h * cov_ * h.transpose() + sigma * sigma * Eigen::Matrix2d::Identity();
  const Eigen::Matrix2d s_inv = s.inverse();
  if (!(nu.dot(s_inv * nu) <= options_.gate)) {
    ++counters_.place_outliers;
    return false;
  }
  apply(h, nu, s_inv, sigma, odometry);
  ++counters_.place_used;
  return true;
}

void UtmAlignment::record_used(const Eigen::Vector2d& z, const Eigen::Vector2d& a, const LocalPose& p, double sigma,
                               std::int64_t time_ns) noexcept {
  last_used_.serial = counters_.used;
  last_used_.time_ns = time_ns;
  last_used_.utm = z;
  last_used_.antenna_odom = a;
  last_used_.x = p.x;
  last_used_.y = p.y;
  last_used_.yaw = p.yaw;
  last_used_.sigma = sigma;
}

UtmPose UtmAlignment::utm(const LocalPose& local, bool geodetic) const noexcept {
  UtmPose u;
  u.time_ns = local.time_ns;
  u.zone = zone_;
  u.north = north_;
  if (last_used_.serial == 0 && !aligned_) return u;  // aligned by place fixes alone: no GPS fix yet
  u.altitude = last_altitude_ + (local.z - last_altitude_z_);
  if (!aligned_) {
    // Position only: the last fix's antenna position, uncertain by its sigma
    // and by how far the robot has moved since.
    const double moved = std::hypot(local.x - last_used_.x, local.y - last_used_.y);
    const double s = last_used_.sigma + moved + std::hypot(options_.antenna[0], options_.antenna[1]);
    u.position_valid = true;
    u.easting = last_used_.utm.x();
    u.northing = last_used_.utm.y();
    u.covariance(0, 0) = u.covariance(1, 1) = s * s;
    u.covariance(2, 2) = kPi * kPi;
  } else {
    const Eigen::Vector2d pos(local.x, local.y);
    const Eigen::Vector2d rb = rotation(state_(2)) * pos;
    const Eigen::Vector2d m = rb + state_.head<2>();
    u.position_valid = u.heading_valid = true;
    u.easting = m.x();
    u.northing = m.y();
    u.yaw = wrap_angle(local.yaw + state_(2));
    // Propagate the transform's covariance, grown by the drift since the last fix.
    Eigen::Matrix3d c = cov_.topLeftCorner<3, 3>();
    const double dd = std::max(0.0, local.distance - last_distance_);
    const double dt = std::max(0.0, static_cast<double>(local.time_ns - last_time_) * 1e-9);
    add_drift(c, pos, dd, dt);
    c(2, 2) += cov_(3, 3) * dt * dt;
    Eigen::Matrix3d a = Eigen::Matrix3d::Identity();
    a.block<2, 1>(0, 2) = perp(rb);
    u.covariance = a * c * a.transpose();
  }
  if (geodetic) add_geodetic(u);
  return u;
}

void UtmAlignment::add_geodetic(UtmPose& u) const noexcept {
  if (!u.position_valid) return;
  double lat = 0.0, lon = 0.0;
  if (reverse(u.easting, u.northing, lat, lon)) {
    u.latitude = lat;
    u.longitude = lon;
    double e = 0.0, n = 0.0, gamma = 0.0;
    if (forward(lat, lon, e, n, gamma)) u.convergence = gamma;
  }
}

}  // namespace trailnav::pose
