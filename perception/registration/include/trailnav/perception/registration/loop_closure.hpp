// Loop closures for the pose-graph mapping (issue 40; thesis chapter 3's
// graphs take them as edges between two poses): each keyframe keeps a
// voxel-filtered cloud of what the lidar saw there (robot frame, a fixed
// pool); when a keyframe is made, the earlier keyframes that the map's
// current (optimised) poses put within `search_radius` of it, and at least
// `min_path` metres of driving before it, are the candidates, nearest first;
// each is verified by GICP of the new keyframe's cloud onto the candidate's,
// starting from the poses' relative guess, and accepted when
//
//   - after a second pass from the first's answer with a gate of 3 × `max_rms`,
//     at least `min_overlap` of the new cloud's points have a partner within
//     that gate or the two clouds' voxel size, whichever is larger,
//   - the RMS distance of the associated points from the candidate's
//     surfaces (along their normals) is at most `max_rms` (a wrong place
//     aligns its walls only in part), and
//   - its answer lies within `max_jump_m` / `max_jump_rad` of the guess
//     (the map is off by its drift, not by anything).
//
// The edge (candidate → new keyframe, the new keyframe's pose in the
// candidate's frame) carries GICP's in-plane covariance (gicp.hpp,
// planar_pose_covariance) plus a floor (`sigma_floor_m`, `sigma_floor_rad`):
// GICP's own is that of the noise alone and knows nothing of a wrong
// association, and an edge a thousand times tighter than the odometry's
// would bend the whole map round one registration.
//
// Memory: the pool (`capacity` keyframes × `max_points`) and the filters are
// sized at construction; a verification builds the candidate's k-d tree and
// covariances (nanoflann's node pool allocates: run it off the real-time
// threads, or behind a heap redirect as trailnavd does).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include <Eigen/Geometry>

#include "trailnav/perception/registration/cloud.hpp"
#include "trailnav/perception/registration/gicp.hpp"

namespace trailnav::perception::registration {

struct LoopClosureConfig {
  GicpConfig gicp{Metric::plane_to_plane, 60, 1.0f, 2e-5, 5e-5, 0.0};
  float voxel = 0.1f;             // m, a keyframe's cloud (coarser, by steps of 1.25, until it fits max_points)
  std::size_t max_points = 1500;  // per keyframe after the filter
  std::size_t max_input_points = 0;  // a keyframe's cloud before the filter at most (0: 8 × max_points)
  int neighbours = 15;            // k for the covariances
  bool planar = true;             // 2D scans (z = 0)
  std::size_t capacity = 5000;    // keyframes
  double search_radius = 4.0;     // m between the map's poses of the two
  double min_path = 15.0;         // m driven between them
  int max_candidates = 2;         // tried per keyframe, nearest first
  double min_overlap = 0.6;       // share of the new cloud's points associated
  double max_rms = 0.04;          // m, point to plane (the fine pass's gate: 3 times this)
  double max_jump_m = 2.0, max_jump_rad = 0.35;
  double sigma_floor_m = 0.05, sigma_floor_rad = 0.01;  // added to the edge's σ
};
// "" if usable, else what is wrong.
std::string check_loop_closure_config(const LoopClosureConfig& c);
// The defaults for a spinning lidar's revolutions outdoors (trailnavd's
// mapping.loops, `lidar-odometry --loops` on a recording): 3D clouds at
// 0.3 m, 2,000 points a keyframe, candidates within 8 m and 25 m of
// driving back, 50 % overlap, 0.1 m RMS along the normals.
LoopClosureConfig spinning_lidar_loop_config();

struct LoopClosure {
  std::size_t from = 0, to = 0;  // keyframes: the candidate and the new one
  Eigen::Isometry3d measurement = Eigen::Isometry3d::Identity();  // `to` in `from`'s frame
  // Of (x, y, yaw) in the edge's own frame (g2o's convention, slam/poses.hpp:
  // the error z⁻¹ x_from⁻¹ x_to, its translation in `to`'s axes).
  Eigen::Matrix3d information = Eigen::Matrix3d::Identity();
  double rms = 0.0, overlap = 0.0;
  double jump_m = 0.0, jump_rad = 0.0;  // from the map's guess
};

struct LoopCounters {
  std::uint64_t keyframes = 0;        // clouds stored
  std::uint64_t refused_full = 0;     // keyframes beyond the pool's capacity
  std::uint64_t candidates = 0;       // verifications tried
  std::uint64_t accepted = 0;
  std::uint64_t not_converged = 0, low_overlap = 0, high_rms = 0, jumped = 0;  // rejections, by reason
};

class LoopCloser {
 public:
  explicit LoopCloser(const LoopClosureConfig& config);

  // Keyframe k's cloud (robot frame) and the path driven up to it; keyframes
  // come in order (k = 0, 1, ...). False when the pool is full.
  bool add_keyframe(std::span<const Point> cloud, double path_m);
  std::size_t keyframes() const noexcept { return count_; }
  std::span<const Point> cloud(std::size_t k) const noexcept {
    return {pool_.data() + k * config_.max_points, sizes_[k]};
  }

  // Candidates for the newest keyframe from the map's poses of every
  // keyframe so far (`poses[k]`, k < keyframes()), verified nearest first;
  // the first accepted, if any.
  std::optional<LoopClosure> close(std::span<const Eigen::Isometry3d> poses);
  const LoopCounters& counters() const noexcept { return counters_; }
  const LoopClosureConfig& config() const noexcept { return config_; }

 private:
  std::optional<LoopClosure> verify(std::size_t from, std::size_t to, const Eigen::Isometry3d& guess);

  LoopClosureConfig config_;
  std::vector<Point> pool_;          // capacity × max_points
  std::vector<std::size_t> sizes_;   // per keyframe
  std::vector<float> voxels_;        // per keyframe: the voxel its cloud fitted at
  std::vector<double> path_;         // per keyframe
  std::size_t count_ = 0;
  VoxelFilter filter_;
  Cloud filtered_;
  CovarianceEstimator covariances_;
  Gicp gicp_, fine_;
  Target target_;
  Cloud source_;
  KdTree scratch_;
  std::vector<Point> normals_;
  std::vector<std::pair<double, std::size_t>> candidates_;  // squared distance, keyframe
  LoopCounters counters_;
};

}  // namespace trailnav::perception::registration
