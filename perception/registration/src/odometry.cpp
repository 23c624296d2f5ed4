#include "trailnav/perception/registration/odometry.hpp"

#include <Eigen/Eigenvalues>

#include "gicp_terms.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace trailnav::perception::registration {

namespace {
constexpr double kMaxJump = 1.0;  // m from the prediction
constexpr double kMaxTurn = 0.5;  // rad from the prediction
}  // namespace

double LidarOdometry::truncated_cost(const GicpResult& r, std::size_t points) const noexcept {
  if (points == 0 || !r.transform.matrix().allFinite()) return std::numeric_limits<double>::infinity();
  const double gate = config_.gicp.max_correspondence_distance;
  const auto n = static_cast<double>(points), c = static_cast<double>(r.correspondences);
  return (r.fitness * c + (n - c) * gate * gate) / n;
}

LidarOdometry::LidarOdometry(const OdometryConfig& config)
    : config_(config),
      filter_(config.max_points),
      covariances_(20, 1e-3f, config.planar),
      gicp_(config.gicp, config.max_points),
      keyframes_(static_cast<std::size_t>(std::max(config.local_scans, 1))),
      map_filter_(config.max_points * static_cast<std::size_t>(std::max(config.local_scans, 1))) {
  scan_.points.reserve(config.max_points);
  scan_.covariances.reserve(config.max_points);
  scan_normals_.reserve(config.max_points);
  for (auto& k : keyframes_) k.reserve(config.max_points);
  merged_.reserve(config.max_points * keyframes_.size());
  map_.cloud.points.reserve(config.max_points * keyframes_.size());
}

void LidarOdometry::rebuild_map() {
  merged_.clear();
  for (const auto& k : keyframes_) merged_.insert(merged_.end(), k.begin(), k.end());
  map_filter_.filter(merged_, config_.voxel, map_.cloud);
  prepare_target(map_, covariances_);
  have_map_ = map_.cloud.size() >= 6;
}

Eigen::Isometry3d LidarOdometry::add(std::span<const Point> scan, const Eigen::Isometry3d* motion) {
  ++counters_.scans;
  filter_.filter(scan.first(std::min(scan.size(), config_.max_points)), config_.voxel, scan_);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  if (counters_.scans > 1 && have_map_) {
    // A measured motion, or constant velocity: the last motion again.
    const Eigen::Isometry3d predicted = motion != nullptr              ? last_ * *motion
                                        : config_.constant_velocity ? last_ * (previous_.inverse() * last_)
                                                                    : last_;
    prepare_source(scan_, covariances_, scan_tree_, scan_normals_);
    GicpResult r = gicp_.align(scan_, map_, predicted);
    counters_.iterations += static_cast<std::uint64_t>(r.iterations);
    // A second start from the last pose when the prediction moved away from
    // it: a turn that stops makes the constant-velocity prediction overshoot,
    // and GICP can settle in a wrong minimum beside it. The answer with the
    // smaller truncated cost (unassociated points at the gate) is taken.
    const Eigen::Isometry3d extrapolated = last_.inverse() * predicted;
    if (config_.two_starts && motion == nullptr && (extrapolated.translation().norm() > 0.02 ||
                               Eigen::AngleAxisd(extrapolated.linear()).angle() > 0.01)) {
      const GicpResult s = gicp_.align(scan_, map_, last_);
      counters_.iterations += static_cast<std::uint64_t>(s.iterations);
      if (truncated_cost(s, scan_.size()) < truncated_cost(r, scan_.size())) {
        r = s;
        ++counters_.second_start;
      }
    }
    if (!r.converged) ++counters_.not_converged;
    conditioning_ = Conditioning{};
    if (r.transform.matrix().allFinite() && r.covariance.allFinite()) {
      // The covariance is of a perturbation (ω, v) of the odometry frame
      // about its origin: x + ω × x + v. The sensor's own translation is
      // v' = v + ω × t (t its position), so Cov(v') = J Σ Jᵀ, J = [−[t]×, I].
      Eigen::Matrix<double, 3, 6> j;
      j << -detail::skew(r.transform.translation()), Eigen::Matrix3d::Identity();
      const Eigen::Matrix3d c = j * r.covariance * j.transpose();
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(0.5 * (c + c.transpose()));
      conditioning_.weakest = eig.eigenvalues()(2);
      conditioning_.strongest = eig.eigenvalues()(0);
      conditioning_.direction = eig.eigenvectors().col(2);
      // With a measured motion: in a direction the scan pins weak_ratio
      // times less than its best one, the measured motion stands (the
      // registration's answer there is the scene's bias, not a measurement:
      // on flat ground the rings move with the sensor and pull it back).
      if (motion != nullptr && config_.weak_ratio > 0.0 && eig.eigenvalues()(0) > 0.0) {
        Eigen::Vector3d d = r.transform.translation() - predicted.translation();
        bool kept = false;
        for (int k = 1; k < 3; ++k) {
          if (eig.eigenvalues()(k) > config_.weak_ratio * eig.eigenvalues()(0)) {
            const Eigen::Vector3d e = eig.eigenvectors().col(k);
            d -= e * e.dot(d);
            kept = true;
          }
        }
        if (kept) {
          r.transform.translation() = predicted.translation() + d;
          ++counters_.prior_kept;
        }
      }
    }
    // A registration that lost its associations or ran away from the
    // prediction is not taken.
    const Eigen::Isometry3d jump = predicted.inverse() * r.transform;
    const bool plausible = r.transform.matrix().allFinite() && r.correspondences >= 6 &&
                           jump.translation().norm() < kMaxJump && Eigen::AngleAxisd(jump.linear()).angle() < kMaxTurn;
    if (!plausible) {
      ++counters_.rejected;
      conditioning_ = Conditioning{};
    }
    // Rejected: the measured motion, or else the last pose stands (no
    // motion extrapolated from a scan that could not be placed).
    pose = plausible ? r.transform : motion != nullptr ? predicted : last_;
  }
  previous_ = counters_.scans > 1 ? last_ : pose;
  last_ = pose;
  // A keyframe: the first scan, or far enough from the last keyframe.
  const Eigen::Isometry3d since = last_keyframe_.inverse() * pose;
  const bool keyframe = counters_.keyframes == 0 || since.translation().norm() >= config_.keyframe_distance ||
                        Eigen::AngleAxisd(since.linear()).angle() >= config_.keyframe_angle;
  if (keyframe) {
    std::vector<Point>& k = keyframes_[next_keyframe_];
    next_keyframe_ = (next_keyframe_ + 1) % keyframes_.size();
    k.clear();
    for (const Point& p : scan_.points) k.push_back((pose * p.cast<double>()).cast<float>());
    last_keyframe_ = pose;
    ++counters_.keyframes;
    rebuild_map();
  }
  return pose;
}

RelativePoseError relative_pose_error(std::span<const Eigen::Isometry3d> reference,
                                      std::span<const Eigen::Isometry3d> estimate, double segment) {
  RelativePoseError e;
  const std::size_t n = std::min(reference.size(), estimate.size());
  if (n < 2) return e;
  std::vector<double> along(n, 0.0);
  for (std::size_t i = 1; i < n; ++i) {
    along[i] = along[i - 1] + (reference[i].translation() - reference[i - 1].translation()).norm();
  }
  double t_sum = 0.0, r_sum = 0.0;
  std::size_t j = 0;
  for (std::size_t i = 0; i < n; ++i) {
    j = std::max(j, i + 1);
    while (j < n && along[j] - along[i] < segment) ++j;
    if (j >= n) break;
    const double length = along[j] - along[i];
    const Eigen::Isometry3d ref = reference[i].inverse() * reference[j];
    const Eigen::Isometry3d est = estimate[i].inverse() * estimate[j];
    const Eigen::Isometry3d err = ref.inverse() * est;
    t_sum += err.translation().norm() / length * 100.0;
    r_sum += Eigen::AngleAxisd(err.linear()).angle() * 180.0 / M_PI / length * 100.0;
    ++e.segments;
  }
  if (e.segments > 0) {
    e.translation_percent = t_sum / static_cast<double>(e.segments);
    e.rotation_deg_per_100m = r_sum / static_cast<double>(e.segments);
  }
  return e;
}

double path_length(std::span<const Eigen::Isometry3d> poses) noexcept {
  double length = 0.0;
  for (std::size_t i = 1; i < poses.size(); ++i) length += (poses[i].translation() - poses[i - 1].translation()).norm();
  return length;
}

void deskew(std::span<Point> points, std::span<const float> fraction, const Eigen::Isometry3d& motion) noexcept {
  const Eigen::AngleAxisd turn(motion.linear());
  const Eigen::Vector3d axis = turn.angle() > 1e-12 ? turn.axis() : Eigen::Vector3d::UnitZ();
  const double angle = turn.angle();
  const Eigen::Vector3d move = motion.translation();
  // Points of one firing share their fraction: the transform is worked out
  // again only when it changes.
  float last = std::numeric_limits<float>::quiet_NaN();
  Eigen::Matrix3f r = Eigen::Matrix3f::Identity();
  Eigen::Vector3f t = Eigen::Vector3f::Zero();
  const std::size_t n = std::min(points.size(), fraction.size());
  for (std::size_t i = 0; i < n; ++i) {
    if (fraction[i] != last) {
      last = fraction[i];
      const double u = static_cast<double>(last) - 1.0;
      r = Eigen::AngleAxisd(u * angle, axis).toRotationMatrix().cast<float>();
      t = (u * move).cast<float>();
    }
    points[i] = r * points[i] + t;
  }
}

}  // namespace trailnav::perception::registration
