#include "trailnav/navigation/pose/pose_estimator.hpp"

#include <cmath>
#include <cstdlib>

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

void PoseEstimator::snapshot(PoseSnapshot& out) const noexcept {
  out.local = odometry_.pose();
  out.utm = alignment_.utm(out.local);
  out.odometry_counters = odometry_.counters();
  out.utm_counters = alignment_.counters();
}

PoseTask::PoseTask(const PoseEstimatorOptions& options, SpscQueue<imu::ImuReading, imu::kImuQueueCapacity>* imu,
                   SpscQueue<can::OdometryState, can::kOdometryQueueCapacity>* wheels,
                   Mailbox<gps::GpsReading>* gps)
    : estimator_(options), imu_(imu), wheels_(wheels), gps_(gps) {}

void PoseTask::run(const TaskTick& tick) {
  (void)tick;
  ++local_.runs;
  std::size_t ni = 0, nw = 0;
  if (imu_ != nullptr) {
    imu::ImuReading r;
    while (ni < imu_batch_.size() && imu_->try_pop(r)) imu_batch_[ni++] = r.attitude;
  }
  if (wheels_ != nullptr) {
    while (nw < wheel_batch_.size() && wheels_->try_pop(wheel_batch_[nw])) ++nw;
  }
  local_.imu_readings += ni;
  local_.wheel_readings += nw;
  // Merge by time: a wheel reading sets the speed the IMU steps after it use.
  std::size_t i = 0, w = 0;
  while (i < ni || w < nw) {
    if (w < nw && (i >= ni || wheel_batch_[w].time_ns <= imu_batch_[i].time_ns)) {
      estimator_.add_wheels(wheel_batch_[w++]);
    } else {
      estimator_.add_imu(imu_batch_[i++]);
    }
  }
  bool changed = ni + nw > 0;
  if (gps_ != nullptr) {
    if (const gps::GpsReading* g = gps_->try_read()) {
      ++local_.gps_fixes;
      if (g->fix.has_date && estimator_.fix_time(g->fix, g->receive_ns) == g->fix.utc_ns) {
        ++local_.gps_fixes_at_utc;
      } else {
        ++local_.gps_fixes_at_receive;
      }
      if (g->fix.has_date) {
        local_.gps_has_utc = true;
        local_.gps_receive_minus_utc_ns = g->receive_ns - g->fix.utc_ns;
      }
      estimator_.add_gps(g->fix, g->receive_ns);
      changed = true;
    }
  }
  if (changed) {
    PoseSnapshot& slot = poses_.write_slot();
    estimator_.snapshot(slot);
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
      const perception::Pose pose{l.time_ns, l.x, l.y, l.z, l.roll, l.pitch, l.yaw, l.translation_valid};
      for (std::size_t q = 0; q < pose_outputs_; ++q) {
        if (!pose_out_[q]->try_push(pose)) ++local_.pose_queue_drops;
      }
    }
  }
  shared_.post(local_);
}

}  // namespace trailnav::pose
