#include "trailnav/navigation/pose/pose_estimator.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>

#include "trailnav/runtime/host_clock.hpp"

namespace trailnav::pose {

PoseEstimator::PoseEstimator(const PoseEstimatorOptions& options)
    : options_(options), odometry_(options.odometry), alignment_(options.utm) {}

std::int64_t PoseEstimator::fix_time(const gps::GpsFix& fix, std::int64_t receive_ns) const noexcept {
  const auto tolerance = static_cast<std::int64_t>(options_.gps_time_tolerance * 1e9);
  if (fix.has_date && std::llabs(fix.utc_ns - receive_ns) <= tolerance) return fix.utc_ns;
  return receive_ns - static_cast<std::int64_t>(options_.gps_latency * 1e9);
}

void PoseEstimator::add_gps(const gps::GpsFix& fix, std::int64_t receive_ns) noexcept {
  alignment_.add_fix(fix, fix_time(fix, receive_ns), odometry_);
}

void PoseEstimator::snapshot(PoseSnapshot& out, bool geodetic) const noexcept {
  out.local = odometry_.pose();
  out.utm = alignment_.utm(out.local, geodetic);
  out.odometry_counters = odometry_.counters();
  out.utm_counters = alignment_.counters();
}

namespace {

PoseEstimatorOptions with_imu(PoseEstimatorOptions options, bool imu) noexcept {
  options.odometry.imu_expected = options.odometry.imu_expected || imu;
  return options;
}

}  // namespace

PoseTask::PoseTask(const PoseEstimatorOptions& options, SpscQueue<imu::ImuReading, imu::kImuQueueCapacity>* imu,
                   SpscQueue<can::OdometryState, can::kOdometryQueueCapacity>* wheels,
                   Mailbox<gps::GpsReading>* gps)
    : estimator_(with_imu(options, imu != nullptr)), imu_(imu), wheels_(wheels), gps_(gps) {}

void PoseTask::correct(UtmPose& u, Nanos now) noexcept {
  if (!target_.valid || !u.position_valid || !u.heading_valid) return;
  // Step the applied correction towards the newest: first its turn, then
  // its shift at the robot's position.
  const double dt = last_correction_ < 0 ? 0.0 : std::min(1.0, static_cast<double>(now - last_correction_) * 1e-9);
  last_correction_ = now;
  if (!applied_.valid) applied_ = MapCorrection{true, 0, 0.0, 0.0, 0.0};
  // The turn about the robot (about the zone's origin, 500 km away, it
  // would throw the robot hundreds of metres): the robot's corrected
  // position kept, the shift then moves it.
  const double turn = std::remainder(target_.yaw - applied_.yaw, 2.0 * 3.14159265358979323846);
  const double max_turn = kCorrectionTurn * dt;
  const double c0 = std::cos(applied_.yaw), s0 = std::sin(applied_.yaw);
  const double qe = applied_.x + c0 * u.easting - s0 * u.northing, qn = applied_.y + s0 * u.easting + c0 * u.northing;
  applied_.yaw += std::clamp(turn, -max_turn, max_turn);
  const double ct = std::cos(target_.yaw), st = std::sin(target_.yaw);
  const double ca = std::cos(applied_.yaw), sa = std::sin(applied_.yaw);
  applied_.x = qe - (ca * u.easting - sa * u.northing);
  applied_.y = qn - (sa * u.easting + ca * u.northing);
  const double dx = (target_.x + ct * u.easting - st * u.northing) - (applied_.x + ca * u.easting - sa * u.northing);
  const double dy = (target_.y + st * u.easting + ct * u.northing) - (applied_.y + sa * u.easting + ca * u.northing);
  const double gap = std::hypot(dx, dy), max_shift = kCorrectionShift * dt;
  const double f = gap > max_shift ? max_shift / gap : 1.0;
  applied_.x += f * dx;
  applied_.y += f * dy;
  const double e = applied_.x + ca * u.easting - sa * u.northing;
  const double n = applied_.y + sa * u.easting + ca * u.northing;
  u.easting = e;
  u.northing = n;
  u.yaw = std::remainder(u.yaw + applied_.yaw, 2.0 * 3.14159265358979323846);
}

bool PoseTask::take_place(const perception::place::PlaceSnapshot& s) noexcept {
  if (place_use_.use == PlaceUse::off) return false;
  if (!(s.probability >= place_use_.min_probability) || (place_use_.need_sequence && !s.in_sequence) ||
      !std::isfinite(s.lat) || !std::isfinite(s.lon)) {
    ++local_.place_weak;
    return false;
  }
  const UtmAlignment& a = estimator_.alignment();
  if (place_use_.use == PlaceUse::gps_poor) {
    const std::uint64_t fixes = a.counters().used;
    const bool recent = fixes > 0 && s.stamp_ns - a.last_used().time_ns <= seconds_to_nanos(place_use_.gps_poor_after_s);
    const double sigma = a.utm(estimator_.odometry().pose(), false).sigma_position();
    if (recent && a.heading_valid() && sigma <= place_use_.gps_poor_sigma_m) {
      ++local_.place_gps_good;
      return false;
    }
  }
  // The larger axis of the position covariance.
  return estimator_.add_place(s.lat, s.lon, larger_sigma(s.cov_xx, s.cov_xy, s.cov_yy), s.stamp_ns);
}

void PoseTask::run(const TaskTick& tick) {
  ++local_.runs;
  std::size_t ni = 0;
  if (imu_ != nullptr) {
    imu::ImuReading r;
    while (ni < imu_batch_.size() && imu_->try_pop(r)) imu_batch_[ni++] = r.attitude;
  }
  if (ni > 0) {
    imu_newest_ns_ = std::max(imu_newest_ns_, imu_batch_[ni - 1].time_ns);
    imu_arrival_ = tick.started;
  }
  std::size_t nw = wheels_pending_;
  if (wheels_ != nullptr) {
    while (nw < wheel_batch_.size() && wheels_->try_pop(wheel_batch_[nw])) ++nw;
  }
  local_.imu_readings += ni;
  local_.wheel_readings += nw - wheels_pending_;
  // The two streams come through two threads: a wheel reading can be here
  // before the IMU readings of its time are (the IMU's thread lost its core
  // for a while, or its bytes came late). Stepping with it then would step
  // the odometry on the wheels' yaw rate alone, as if the IMU had failed,
  // and the IMU readings that follow would lie in the past and be lost
  // (gaps): the heading would drift. So wheel readings later than the newest
  // IMU reading wait for it (held here, across runs), as long as the IMU
  // spoke within imu_wait of host time; a silent IMU lets them go, and the
  // wheels alone carry the pose as designed. Before the IMU's first reading
  // they wait as long, from the first wheel reading on: at start-up the IMU
  // may begin later than the CAN bus (its device starting, its thread late).
  const Nanos imu_wait = seconds_to_nanos(estimator_.options().imu_wait);
  if (nw > 0 && first_wheels_arrival_ < 0) first_wheels_arrival_ = tick.started;
  const bool imu_live = imu_ != nullptr && (imu_arrival_ >= 0 ? tick.started - imu_arrival_ <= imu_wait
                                                                : first_wheels_arrival_ >= 0 &&
                                                                      tick.started - first_wheels_arrival_ <= imu_wait);
  std::size_t usable = nw;
  if (imu_live) {
    usable = 0;
    while (usable < nw && wheel_batch_[usable].time_ns <= imu_newest_ns_) ++usable;
    if (usable < nw && nw == wheel_batch_.size()) {  // the hold is full: let the oldest go
      ++local_.wheels_released_early;
      ++usable;
    }
  } else if (wheels_pending_ > 0) {
    local_.wheels_released_early += wheels_pending_;
  }
  // Merge by time: a wheel reading sets the speed the IMU steps after it use.
  std::size_t i = 0, w = 0;
  while (i < ni || w < usable) {
    if (w < usable && (i >= ni || wheel_batch_[w].time_ns <= imu_batch_[i].time_ns)) {
      estimator_.add_wheels(wheel_batch_[w++]);
    } else {
      estimator_.add_imu(imu_batch_[i++]);
    }
  }
  const std::size_t held = nw - usable;
  for (std::size_t k = 0; k < held; ++k) wheel_batch_[k] = wheel_batch_[usable + k];
  const std::size_t still_pending = wheels_pending_ > usable ? wheels_pending_ - usable : 0;  // held before, held again
  local_.wheels_held += held - still_pending;
  wheels_pending_ = held;
  bool changed = ni + usable > 0;
  if (gps_ != nullptr) {
    if (const gps::GpsReading* g = gps_->try_read()) {
      ++local_.gps_fixes;
      // The receiver's UTC in host time, which the other readings are on
      // (runtime/host_clock.hpp: the same unless the system clock was set
      // since start).
      gps::GpsFix fix = g->fix;
      if (fix.has_date) fix.utc_ns = host_from_realtime(fix.utc_ns);
      if (fix.has_date && estimator_.fix_time(fix, g->receive_ns) == fix.utc_ns) {
        ++local_.gps_fixes_at_utc;
      } else {
        ++local_.gps_fixes_at_receive;
      }
      if (fix.has_date) {
        local_.gps_has_utc = true;
        local_.gps_receive_minus_utc_ns = g->receive_ns - fix.utc_ns;
      }
      estimator_.add_gps(fix, g->receive_ns);
      changed = true;
      const UtmAlignment& a = estimator_.alignment();
      if (fix_out_ != nullptr && a.last_used().serial != fix_serial_) {
        fix_serial_ = a.last_used().serial;
        MappingFix m;
        m.fix = a.last_used();
        m.zone = a.zone();
        m.north = a.north();
        m.aligned = a.heading_valid();
        const Eigen::Vector3d t = a.transform();
        m.east = t.x();
        m.north_m = t.y();
        m.rotation = t.z();
        if (!fix_out_->try_push(m)) ++local_.fix_queue_drops;
      }
    }
  }
  if (place_ != nullptr) {
    if (const perception::place::PlaceSnapshot* ps = place_->try_read()) {
      ++local_.place_answers;
      changed = take_place(*ps) || changed;
    }
  }
  if (corrections_ != nullptr) {
    if (const MapCorrection* c = corrections_->try_read()) {
      target_ = *c;
      ++local_.map_corrections;
      changed = true;
    }
  }
  if (changed) {
    PoseSnapshot& slot = poses_.write_slot();
    // With a correction, the pose is moved before its one projection to
    // latitude and longitude.
    estimator_.snapshot(slot, !target_.valid);
    if (target_.valid) {
      correct(slot.utm, tick.started);
      estimator_.alignment().add_geodetic(slot.utm);
    }
    slot.sequence = ++local_.published;
    navigation_poses_.write_slot() = slot;
    navigation_poses_.publish();
    poses_.publish();
    local_.local = slot.local;
    local_.utm = slot.utm;
    local_.odometry_counters = slot.odometry_counters;
    local_.utm_counters = slot.utm_counters;
    const LocalPose& l = slot.local;
    if (pose_outputs_ > 0 && l.source != PoseSource::none && l.time_ns > last_out_ns_) {
      last_out_ns_ = l.time_ns;
      const perception::Pose pose{l.time_ns, l.x, l.y, l.z, l.roll, l.pitch, l.yaw,
                                         l.translation_valid && l.rotation_valid};
      for (std::size_t q = 0; q < pose_outputs_; ++q) {
        if (!pose_out_[q]->try_push(pose)) ++local_.pose_queue_drops;
      }
    }
  }
  shared_.post(local_);
}

}  // namespace trailnav::pose
