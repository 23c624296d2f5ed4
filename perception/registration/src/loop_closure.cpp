#include "trailnav/perception/registration/loop_closure.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "trailnav/perception/registration/carmen.hpp"

namespace trailnav::perception::registration {

namespace {

GicpConfig fine_gate(const LoopClosureConfig& c) noexcept {
  GicpConfig f = c.gicp;
  f.max_correspondence_distance = static_cast<float>(3.0 * c.max_rms);
  return f;
}

}  // namespace

std::string check_loop_closure_config(const LoopClosureConfig& c) {
  if (const char* e = check_gicp_config(c.gicp); *e != '\0') return std::string("gicp: ") + e;
  if (!(c.voxel > 0.0f) || !std::isfinite(c.voxel)) return "voxel: a positive number of metres";
  if (c.max_points < 16 || c.max_points > 1'000'000) return "max_points: 16 to 1000000";
  if (c.neighbours < 3 || c.neighbours > 64) return "neighbours: 3 to 64";
  if (c.capacity < 2) return "capacity: at least 2 keyframes";
  if (!(c.search_radius > 0.0)) return "search_radius: positive";
  if (!(c.min_path >= 0.0)) return "min_path: not negative";
  if (c.max_candidates < 1 || c.max_candidates > 100) return "max_candidates: 1 to 100";
  if (!(c.min_overlap > 0.0 && c.min_overlap <= 1.0)) return "min_overlap: above 0, at most 1";
  if (!(c.max_rms > 0.0)) return "max_rms: positive";
  if (!(c.max_jump_m > 0.0) || !(c.max_jump_rad > 0.0)) return "max_jump_m, max_jump_rad: positive";
  if (!(c.sigma_floor_m > 0.0) || !(c.sigma_floor_rad > 0.0)) return "sigma_floor_m, sigma_floor_rad: positive";
  return "";
}

LoopClosureConfig spinning_lidar_loop_config() {
  LoopClosureConfig c;
  c.planar = false;
  c.voxel = 0.3f;
  c.max_points = 2000;
  c.neighbours = 20;
  c.search_radius = 8.0;
  c.min_path = 25.0;
  c.max_rms = 0.1;
  c.min_overlap = 0.5;
  c.max_input_points = 200'000;  // an HDL-64E's revolution
  return c;
}

LoopCloser::LoopCloser(const LoopClosureConfig& config)
    : config_(config),
      pool_(config.capacity * config.max_points),
      sizes_(config.capacity, 0),
      voxels_(config.capacity, config.voxel),
      path_(config.capacity, 0.0),
      filter_(config.max_input_points > 0 ? config.max_input_points : config.max_points * 8),
      covariances_(config.neighbours, 1e-3f, config.planar),
      gicp_(config.gicp, config.max_points),
      fine_(fine_gate(config), config.max_points) {
  filtered_.points.reserve(config.max_input_points > 0 ? config.max_input_points : config.max_points * 8);
  target_.cloud.points.reserve(config.max_points);
  source_.points.reserve(config.max_points);
  candidates_.reserve(config.capacity);
}

bool LoopCloser::add_keyframe(std::span<const Point> cloud, double path_m) {
  if (count_ >= config_.capacity) {
    ++counters_.refused_full;
    return false;
  }
  // A coarser grid until the cloud fits its slot: the same grid for every
  // keyframe of a place, so two clouds sample a surface alike (thinning one
  // grid's voxels would keep different ones in each). Beyond 16 times the
  // voxel, the rest is thinned evenly.
  float voxel = config_.voxel;
  filter_.filter(cloud, voxel, filtered_);
  while (filtered_.size() > config_.max_points && voxel < 16.0f * config_.voxel) {
    voxel *= 1.25f;
    filter_.filter(cloud, voxel, filtered_);
  }
  const std::size_t n = filtered_.size();
  const std::size_t keep = std::min(n, config_.max_points);
  Point* slot = pool_.data() + count_ * config_.max_points;
  for (std::size_t i = 0; i < keep; ++i) slot[i] = filtered_.points[i * n / keep];
  voxels_[count_] = voxel;
  sizes_[count_] = keep;
  path_[count_] = path_m;
  ++count_;
  ++counters_.keyframes;
  return true;
}

std::optional<LoopClosure> LoopCloser::close(std::span<const Eigen::Isometry3d> poses) {
  if (count_ < 2 || poses.size() < count_) return std::nullopt;
  const std::size_t newest = count_ - 1;
  const Eigen::Vector3d at = poses[newest].translation();
  const double r2 = config_.search_radius * config_.search_radius;
  candidates_.clear();
  for (std::size_t j = 0; j < newest; ++j) {
    if (path_[newest] - path_[j] < config_.min_path) break;  // in driving order: the rest are nearer in path
    const Eigen::Vector3d d = poses[j].translation() - at;
    const double q = d.head<2>().squaredNorm();
    if (q <= r2) candidates_.emplace_back(q, j);
  }
  std::sort(candidates_.begin(), candidates_.end());
  const std::size_t tries = std::min(candidates_.size(), static_cast<std::size_t>(config_.max_candidates));
  for (std::size_t c = 0; c < tries; ++c) {
    const std::size_t j = candidates_[c].second;
    if (auto found = verify(j, newest, poses[j].inverse() * poses[newest])) return found;
  }
  return std::nullopt;
}

std::optional<LoopClosure> LoopCloser::verify(std::size_t from, std::size_t to, const Eigen::Isometry3d& guess) {
  ++counters_.candidates;
  const std::span<const Point> a = cloud(from), b = cloud(to);
  if (a.size() < 6 || b.size() < 6) {
    ++counters_.not_converged;
    return std::nullopt;
  }
  target_.cloud.points.assign(a.begin(), a.end());
  prepare_target(target_, covariances_);
  source_.points.assign(b.begin(), b.end());
  if (config_.gicp.metric == Metric::plane_to_plane) prepare_source(source_, covariances_, scratch_, normals_);
  const GicpResult coarse = gicp_.align(source_, target_, guess);
  if (!coarse.transform.matrix().allFinite() || coarse.correspondences < 6) {
    ++counters_.not_converged;
    return std::nullopt;
  }
  const GicpResult r = fine_.align(source_, target_, coarse.transform);
  if (!r.transform.matrix().allFinite() || r.correspondences < 6) {
    ++counters_.not_converged;
    return std::nullopt;
  }
  LoopClosure lc;
  lc.from = from;
  lc.to = to;
  lc.measurement = r.transform;
  // The RMS distance along the target's normals (point to plane): a wrong
  // place leaves its points off the surfaces, where the distance between
  // two samplings of the same surface (a 3D voxel grid's, up to its size
  // apart) would not tell the two apart.
  const float gate = std::max(static_cast<float>(3.0 * config_.max_rms), std::max(voxels_[from], voxels_[to]));
  const Eigen::Isometry3f tf = r.transform.cast<float>();
  double sum = 0.0;
  std::size_t n = 0;
  for (const Point& p : source_.points) {
    const Point q = tf * p;
    std::uint32_t j = 0;
    float d2 = 0.0f;
    if (!target_.tree.nearest(q, j, d2) || d2 > gate * gate) continue;
    const Point& normal = target_.normals[j];
    const double d = normal.isZero() ? std::sqrt(static_cast<double>(d2))
                                     : static_cast<double>(normal.dot(q - target_.cloud.points[j]));
    sum += d * d;
    ++n;
  }
  lc.rms = n > 0 ? std::sqrt(sum / static_cast<double>(n)) : std::numeric_limits<double>::infinity();
  lc.overlap = static_cast<double>(n) / static_cast<double>(source_.size());
  const Eigen::Isometry3d jump = guess.inverse() * r.transform;
  lc.jump_m = jump.translation().head<2>().norm();
  lc.jump_rad = std::abs(to_pose2(jump).theta);
  if (lc.overlap < config_.min_overlap) {
    ++counters_.low_overlap;
    return std::nullopt;
  }
  if (lc.rms > config_.max_rms) {
    ++counters_.high_rms;
    return std::nullopt;
  }
  if (lc.jump_m > config_.max_jump_m || lc.jump_rad > config_.max_jump_rad) {
    ++counters_.jumped;
    return std::nullopt;
  }
  // The edge's covariance: GICP's in-plane one plus the floor.
  const std::array<double, 9> c = planar_pose_covariance(r.information, r.transform.translation(), r.error, r.correspondences);
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  if (c[0] >= 0.0) {
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) cov(i, j) = c[static_cast<std::size_t>(3 * i + j)];
    }
  }
  // In the edge's own frame (g2o's error z⁻¹ x_i⁻¹ x_j: its translation in
  // the `to` keyframe's axes): the position block turned by R_zᵀ.
  Eigen::Matrix3d g = Eigen::Matrix3d::Identity();
  g.topLeftCorner<2, 2>() = r.transform.linear().topLeftCorner<2, 2>().transpose();
  cov = g * cov * g.transpose();
  cov(0, 0) += config_.sigma_floor_m * config_.sigma_floor_m;
  cov(1, 1) += config_.sigma_floor_m * config_.sigma_floor_m;
  cov(2, 2) += config_.sigma_floor_rad * config_.sigma_floor_rad;
  lc.information = cov.inverse();
  ++counters_.accepted;
  return lc;
}

}  // namespace trailnav::perception::registration
