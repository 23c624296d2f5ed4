#include "trailnav/perception/registration/station_task.hpp"

#include <algorithm>
#include <cmath>
#include <new>

#include "trailnav/perception/registration/carmen.hpp"
#include "trailnav/runtime/heap_redirect.hpp"

namespace trailnav::perception::registration {


void band_scan(const velodyne::RangeImage& image, const RingBand& band, PlanarScan& out) noexcept {
  out.points.clear();
  out.dropped = 0;
  out.stamp_ns = image.reference_end_ns();
  const std::size_t capacity = out.points.capacity();
  const int first = std::max(0, band.first_ring), last = std::min(image.rings() - 1, band.last_ring);
  for (int r = first; r <= last; ++r) {
    for (int col = 0; col < image.columns(); ++col) {
      const velodyne::RangeCell& cell = image.at(0, r, col);
      if (!cell.valid() || cell.distance < band.min_range || cell.distance > band.max_range) continue;
      if (out.points.size() == capacity) {
        ++out.dropped;
        continue;
      }
      const Eigen::Vector3f p = band.mount * Eigen::Vector3f(cell.x, cell.y, cell.z);
      out.points.emplace_back(p.x(), p.y(), 0.0f);
    }
  }
}

StationTask::StationTask(const Station& station, const StationConfig& config, const StationTaskOptions& options,
                         Mailbox<PlanarScan>* scans, PoseQueue* poses, Mailbox<StationSnapshot>& out)
    : station_(station),
      config_(config),
      options_(options),
      scans_(scans),
      poses_(poses),
      out_(out),
      band_scan_(config.max_points),
      arena_(options.arena_bytes),
      track_(kPoseQueueCapacity) {
  localiser_.emplace(station, config);
  for (std::size_t k = 0; k < station.bodies.size(); ++k) centres_.push_back(body_centre(station, k));
  c_.arena_capacity = arena_.capacity();
  board_.post(c_);
}

StationTask::~StationTask() {
  // Whatever the localiser holds from the arena (its local model's k-d
  // tree) goes back there, not to the heap.
  heap_redirect::ArenaRedirect redirect(arena_);
  const heap_redirect::Scope scope(redirect);
  localiser_.reset();
}

Eigen::Isometry3d StationTask::motion(std::int64_t stamp_ns) noexcept {
  if (poses_ != nullptr) {
    track_.drain(*poses_);
    Pose now;
    if (track_.at(stamp_ns, now) != PoseLookup::empty) {
      const bool had = have_last_pose_;
      const Pose before = last_pose_;
      last_pose_ = now;
      have_last_pose_ = true;
      if (had) return to_isometry({before.x, before.y, before.yaw}).inverse() * to_isometry({now.x, now.y, now.yaw});
    }
  }
  ++c_.without_odometry;
  return last_step_;
}

void StationTask::run(const TaskTick&) {
  const PlanarScan* scan = nullptr;
  if (revolutions_ != nullptr) {
    if (const velodyne::RangeImage* image = revolutions_->try_read()) {
      band_scan(*image, band_, band_scan_);
      band_scan_.sequence = c_.scans + 1;
      scan = &band_scan_;
    }
  } else if (scans_ != nullptr) {
    scan = scans_->try_read();
  }
  if (scan == nullptr) return;
  step(*scan);
  c_.arena_high_water = arena_.high_water();
  board_.post(c_);
}

void StationTask::step(const PlanarScan& scan) noexcept {
  ++c_.scans;
  c_.dropped_points += scan.dropped;
  const bool silent = in_visit_ && scan.stamp_ns - last_stamp_ns_ > static_cast<std::int64_t>(options_.silence_s * 1e9);
  last_stamp_ns_ = scan.stamp_ns;
  heap_redirect::ArenaRedirect redirect(arena_);
  const heap_redirect::Scope scope(redirect);
  try {
    StationLocaliser& loc = *localiser_;
    if (!in_visit_ || silent) {
      loc.begin(options_.start);
      in_visit_ = true;
      have_last_pose_ = false;
      last_step_ = Eigen::Isometry3d::Identity();
      since_fix_ = 0;
      ++c_.visits;
      if (poses_ != nullptr) {  // the odometry's pose at the first scan
        track_.drain(*poses_);
        have_last_pose_ = track_.at(scan.stamp_ns, last_pose_) != PoseLookup::empty;
      }
      last_registered_ = loc.add(scan.points, Eigen::Isometry3d::Identity());
    } else {
      const Eigen::Isometry3d before = last_registered_;
      last_registered_ = loc.add(scan.points, motion(scan.stamp_ns));
      last_step_ = before.inverse() * last_registered_;
    }
    ++since_fix_;
    if (loc.scans() < static_cast<std::size_t>(config_.local_scans) || since_fix_ < options_.every) return;
    since_fix_ = 0;
    const StationFix fix = loc.localise();
    if (!fix.bodies[0].observed) {
      ++c_.lost;
    } else {
      // The surroundings' answer is the robot's pose in the station frame.
      loc.correct(fix.bodies[0].transform);
      last_registered_ = fix.bodies[0].transform;
    }
    publish(fix, scan);
  } catch (const std::bad_alloc&) {
    // The arena could not serve a k-d tree: the scan is lost, and the
    // visit begins again from the next one (its local model may be half-built).
    ++c_.arena_failures;
    in_visit_ = false;
  }
}

void StationTask::publish(const StationFix& fix, const PlanarScan& scan) noexcept {
  StationSnapshot& s = out_.write_slot();
  ++c_.fixes;
  s.stamp_ns = scan.stamp_ns;
  s.number = c_.fixes;
  s.scan_sequence = scan.sequence;
  s.visit = c_.visits;
  s.local_points = fix.local_points;
  s.iterations = fix.iterations;
  const std::size_t n = std::min(s.bodies.size(), fix.bodies.size());
  for (std::size_t k = 0; k < n; ++k) {
    const BodyResult& b = fix.bodies[k];
    StationBodyFix& o = s.bodies[k];
    const Eigen::Vector3d t = b.transform.translation();
    o.x = t.x();
    o.y = t.y();
    o.yaw = to_pose2(b.transform).theta;
    o.covariance = planar_pose_covariance(b.information, t, b.error, b.correspondences);
    o.correspondences = static_cast<std::uint32_t>(b.correspondences);
    o.observed = b.observed;
    o.fitness = b.fitness;
    if (k == 0) {
      o.moved_x = o.moved_y = o.turned = o.centre_moved = 0.0;
    } else {
      const Eigen::Isometry3d m = fix.moved(k);
      o.moved_x = m.translation().x();
      o.moved_y = m.translation().y();
      o.turned = to_pose2(m).theta;
      o.centre_moved = (m * centres_[k] - centres_[k]).head<2>().norm();
    }
  }
  out_.publish();
  if (notify_ != nullptr) notify_->notify();
}

}  // namespace trailnav::perception::registration
