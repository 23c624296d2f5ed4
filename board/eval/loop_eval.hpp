// Loop closures offline (issue 40), the way trailnavd's mapping thread makes
// them: an odometry's poses thinned to keyframes in a pose graph
// (navigation/slam/keyframes.hpp: odometry edges whose covariance grows
// with path and turn, the first keyframe the gauge), each keyframe's cloud
// kept, loop closures found and verified by GICP
// (perception/registration/loop_closure.hpp) at each new keyframe from the
// map's current poses, added as edges, and the graph solved with SMF after
// each closure. Scored against reference poses where there are some (a
// CARMEN log's SLAM-corrected ones, a simulated recording's truth): the
// keyframes' relative pose error and end point before and after, the
// absolute error (RMS, the first keyframe on the reference's first pose),
// and how many accepted closures disagree with the reference (a false one).
#pragma once

#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "trailnav/navigation/slam/keyframes.hpp"
#include "trailnav/perception/registration/carmen.hpp"
#include "trailnav/perception/registration/loop_closure.hpp"
#include "trailnav/perception/registration/odometry.hpp"

namespace trailnav::eval {

struct LoopEvalOptions {
  perception::registration::LoopClosureConfig loops;
  slam::KeyframeOptions keyframes;
  int scans_per_keyframe = 5;  // CARMEN: the keyframe's scan and the ones before it, in its cloud
  float max_range = 20.0f;     // CARMEN: m, returns kept in the clouds
  double false_m = 0.3, false_rad = 0.1;  // an accepted closure this far from the reference's relative pose is false
  std::function<void(double fraction)> progress;
};

// For a 2D laser's log (indoors, keyframes every metre).
LoopEvalOptions default_loop_eval_options();
// For a spinning lidar's revolutions (outdoors: 3D clouds at 0.3 m, keyframes every 2 m).
LoopEvalOptions default_loop_eval_options_3d();

struct LoopEvalResult {
  std::size_t keyframes = 0;
  perception::registration::LoopCounters counters;
  std::size_t false_closures = 0;
  int optimisations = 0, failed_optimisations = 0;
  double solve_ms_max = 0.0, close_ms_max = 0.0;
  perception::registration::RelativePoseError rpe_odometry, rpe_loops;  // over the keyframes
  double end_odometry_m = 0.0, end_loops_m = 0.0;
  double ate_odometry_m = 0.0, ate_loops_m = 0.0;  // RMS of the keyframes' position errors
  std::vector<Eigen::Isometry3d> reference, odometry, optimised;  // per keyframe
  std::vector<std::pair<std::size_t, std::size_t>> closures;      // accepted (from, to) keyframes
  std::string error;
};

// Online: one odometry pose at a time.
class LoopMapper {
 public:
  explicit LoopMapper(const LoopEvalOptions& options);
  ~LoopMapper();
  LoopMapper(const LoopMapper&) = delete;
  LoopMapper& operator=(const LoopMapper&) = delete;
  const std::string& error() const noexcept { return error_; }
  // One pose of the odometry (its frame), its reference (nullptr: none; then
  // every pose has none), and what fills the cloud in this pose's frame,
  // called only when the pose becomes a keyframe.
  void add(const Eigen::Isometry3d& odometry, const Eigen::Isometry3d* reference,
           const std::function<void(std::vector<perception::registration::Point>&)>& cloud);
  // The last solve and the scores.
  LoopEvalResult finish();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::string error_;
};

// A CARMEN log: `odometry[i]` scan i's pose by lidar odometry, in the log's
// frame (the first scan on the log's first pose); `scans[i].pose` the reference.
LoopEvalResult evaluate_loops(std::span<const perception::registration::LaserScan2> scans,
                              std::span<const Eigen::Isometry3d> odometry, const LoopEvalOptions& options);

}  // namespace trailnav::eval
