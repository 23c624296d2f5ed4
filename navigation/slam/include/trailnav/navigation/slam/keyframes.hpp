// Keyframes for online mapping: the robot's odometry poses thinned to one
// every few metres (or a turn), joined by odometry edges, and GPS fixes
// attached as virtual pose–pose constraints from a fixed anchor, the thesis'
// way of bringing other kinds of constraint into a pose graph (§3.1: every
// measurement is an edge between two poses).
//
// The graph's vertex 0 is the anchor: the map frame's origin, fixed. Each
// keyframe k ≥ 1 starts at its odometry pose (the odometry frame is taken as
// the map frame until the first optimisation corrects it). Its edges:
//
//   - odometry, keyframe k−1 → k: the relative motion measured, with a
//     covariance that grows with the path driven between them, d, and the
//     angle turned, |Δθ| (a diagonal model in the robot frame):
//       σ_x² = σ_y² = (a_d d)² + σ_0²,  σ_θ² = (a_θ |Δθ| + b_θ d)² + σ_0θ²;
//   - GPS, anchor → keyframe: a fix taken within `gps_max_distance` of path
//     from a keyframe (the latest one, or the next one when it comes)
//     constrains that keyframe's position with information I/σ² (σ the
//     fix's own), its heading barely (information 1e-9: GPS does not measure
//     it). The fix is moved to the keyframe by the odometry between them,
//     r = k⁻¹ p: the keyframe's position is measured as g − R(θ_k) r_t, with
//     θ_k the keyframe's current estimate. One fix a keyframe.
//
// Loop closures from lidar registration (a later capability) enter here as
// edges between two keyframes: add_loop_closure().
//
// At the configured capacity (keyframes, edges) no keyframe is added: the
// builder reports `full` and counts what it refused; the graph already built
// stays as it is and can still be optimised. Pure: no threads; storage
// reserved in the constructor.
#pragma once

#include <cstddef>
#include <cstdint>

#include "trailnav/navigation/slam/pose_graph.hpp"
#include "trailnav/navigation/slam/poses.hpp"

namespace trailnav::slam {

struct KeyframeOptions {
  std::size_t max_keyframes = 20000;
  double spacing_m = 2.0;       // a keyframe after this much path ...
  double spacing_rad = 0.5;     // ... or this much turn
  double sigma_per_metre = 0.05;     // a_d
  double sigma_theta_per_rad = 0.05; // a_θ
  double sigma_theta_per_metre = 0.005;  // b_θ, rad/m
  double sigma_floor_m = 0.01;       // σ_0
  double sigma_floor_rad = 0.002;    // σ_0θ
  double gps_max_distance = 1.0;     // m of path between a fix and the keyframe it joins
};

struct KeyframeCounters {
  std::uint64_t keyframes = 0, gps_edges = 0, loop_closures = 0;
  std::uint64_t refused_full = 0;     // keyframes not added: capacity reached
  std::uint64_t gps_unattached = 0;   // fixes too far from the latest keyframe or after one was taken
};

class KeyframeGraph {
 public:
  enum class Added { none, keyframe, full };

  explicit KeyframeGraph(const KeyframeOptions& options);

  // The odometry pose (odometry frame) at the pose thread's rate.
  Added on_odometry(const Se2& pose);
  // A GPS position in the map frame with its standard deviation (m).
  bool on_gps(double x, double y, double sigma);
  // An edge between two keyframes (indices ≥ 1) with its information.
  bool add_loop_closure(std::int32_t from, std::int32_t to, const Se2& measurement, const Se2::Matrix& information);

  const PoseGraph2d& graph() const noexcept { return graph_; }
  PoseGraph2d& graph() noexcept { return graph_; }
  GraphCapacity capacity() const noexcept { return capacity_; }
  const KeyframeCounters& counters() const noexcept { return counters_; }
  bool full() const noexcept { return graph_.vertex_count() >= capacity_.vertices; }

 private:
  KeyframeOptions options_;
  GraphCapacity capacity_;
  PoseGraph2d graph_;
  KeyframeCounters counters_;
  bool started_ = false;
  Se2 last_odometry_{}, keyframe_odometry_{};  // the previous pose; the latest keyframe's odometry pose
  double path_ = 0.0, turn_ = 0.0;             // since the latest keyframe
  bool keyframe_has_gps_ = false;
  // A keyframe fits: a vertex and its odometry edge.
  bool room() const noexcept { return !full() && graph_.edge_count() < capacity_.edges; }
  void attach_gps(const Se2& fix_odometry, double x, double y, double sigma);
  struct Pending {
    bool valid = false;
    Se2 odometry{};
    double x = 0.0, y = 0.0, sigma = 0.0, path = 0.0;  // path since the keyframe before it
  } pending_;
};

}  // namespace trailnav::slam
