#include "trailnav/perception/registration/station_task.hpp"

#include <algorithm>
#include <cmath>
#include <new>

#include "trailnav/runtime/heap_redirect.hpp"

namespace trailnav::perception::registration {

namespace {

double yaw_of(const Eigen::Isometry3d& t) noexcept { return std::atan2(t.linear()(1, 0), t.linear()(0, 0)); }

Eigen::Isometry3d planar(double x, double y, double yaw) noexcept {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  t.translation() = Eigen::Vector3d(x, y, 0.0);
  return t;
}

}  // namespace

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
  // Each object's centre: that of the polygon it was marked by (its area's
  // centroid: the user drew it around the whole object, where the taught
  // points are only the faces the teach-in saw); else its points' mean.
  for (std::size_t k = 0; k < station.bodies.size(); ++k) {
    const std::vector<Eigen::Vector2d>* poly = k < station.polygons.size() ? &station.polygons[k] : nullptr;
    double area = 0.0;
    Eigen::Vector2d c = Eigen::Vector2d::Zero();
    if (poly != nullptr && poly->size() >= 3) {
      for (std::size_t i = 0; i < poly->size(); ++i) {
        const Eigen::Vector2d& a = (*poly)[i];
        const Eigen::Vector2d& b = (*poly)[(i + 1) % poly->size()];
        const double cross = a.x() * b.y() - b.x() * a.y();
        area += cross;
        c += cross * (a + b);
      }
    }
    if (std::abs(area) > 1e-12) {
      c /= 3.0 * area;
      centres_.emplace_back(c.x(), c.y(), 0.0);
      continue;
    }
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (const Point& p : station.bodies[k].cloud.points) sum += p.cast<double>();
    const auto n = station.bodies[k].cloud.points.size();
    centres_.push_back(n == 0 ? sum : Eigen::Vector3d(sum / static_cast<double>(n)));
  }
  c_.arena_capacity = arena_.capacity();
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
      if (had) return planar(before.x, before.y, before.yaw).inverse() * planar(now.x, now.y, now.yaw);
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
  scans_seen_.store(c_.scans, std::memory_order_relaxed);
  fixes_seen_.store(c_.fixes, std::memory_order_relaxed);
  lost_seen_.store(c_.lost, std::memory_order_relaxed);
  visits_seen_.store(c_.visits, std::memory_order_relaxed);
  without_odometry_seen_.store(c_.without_odometry, std::memory_order_relaxed);
  arena_failures_seen_.store(c_.arena_failures, std::memory_order_relaxed);
  dropped_seen_.store(c_.dropped_points, std::memory_order_relaxed);
  high_water_seen_.store(arena_.high_water(), std::memory_order_relaxed);
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
    o.yaw = yaw_of(b.transform);
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
      o.turned = yaw_of(m);
      o.centre_moved = k < centres_.size() ? (m * centres_[k] - centres_[k]).head<2>().norm() : 0.0;
    }
  }
  out_.publish();
  if (notify_ != nullptr) notify_->notify();
}

StationCounters StationTask::counters() const noexcept {
  StationCounters c;
  c.scans = scans_seen_.load(std::memory_order_relaxed);
  c.fixes = fixes_seen_.load(std::memory_order_relaxed);
  c.lost = lost_seen_.load(std::memory_order_relaxed);
  c.visits = visits_seen_.load(std::memory_order_relaxed);
  c.without_odometry = without_odometry_seen_.load(std::memory_order_relaxed);
  c.arena_failures = arena_failures_seen_.load(std::memory_order_relaxed);
  c.dropped_points = dropped_seen_.load(std::memory_order_relaxed);
  c.arena_high_water = high_water_seen_.load(std::memory_order_relaxed);
  c.arena_capacity = c_.arena_capacity;
  return c;
}

}  // namespace trailnav::perception::registration
