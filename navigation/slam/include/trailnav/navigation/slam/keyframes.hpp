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
//   - GPS with a wandering bias (`gps_white_sigma` > 0): a receiver's error
//     is mostly a bias that wanders over minutes (first-order Gauss–Markov,
//     correlation time τ = `gps_bias_time`) plus a white part. Taking the
//     whole σ as white makes fixes a few metres apart look unrelated and
//     loses the heading they show. So each attached fix gets a bias vertex
//     B_i (a pure translation: its rotation held at 0), and the GPS edge goes
//     B_i → keyframe with the white σ: the keyframe's position less the bias
//     is the fix. The first bias has the stationary prior, anchor → B_1 with
//     σ_b² = σ² − σ_w²; each next one follows the last, B_{i−1} → B_i with
//     σ_b² (1 − e^{−2Δt/τ}) (Δt between the fixes): the same model the GPS
//     alignment filters with (navigation/pose/utm_alignment.hpp).
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
#include <vector>

#include "trailnav/navigation/slam/pose_graph.hpp"
#include "trailnav/navigation/slam/poses.hpp"

namespace trailnav::slam {

struct KeyframeOptions {
  std::size_t max_keyframes = 20000;
  double spacing_m = 2.0;       // a keyframe after this much path ...
  double spacing_rad = 0.5;     // ... or this much turn
  // The odometry's noise: wheel odometry with an IMU's gyro whose bias the
  // GPS alignment keeps estimating (navigation/pose), about as tight as the
  // alignment's own random walks over a keyframe's 2 m (0.02 m/sqrt(m),
  // 0.003 rad/sqrt(m): 0.03 m and 0.004 rad).
  double sigma_per_metre = 0.02;     // a_d
  double sigma_theta_per_rad = 0.02; // a_θ
  double sigma_theta_per_metre = 0.002;  // b_θ, rad/m
  double sigma_floor_m = 0.01;       // σ_0
  double sigma_floor_rad = 0.002;    // σ_0θ
  double gps_max_distance = 1.0;     // m of path between a fix and the keyframe it joins
  // Holds the first keyframe where it was placed: the gauge of a graph
  // without GPS (odometry and loop closures only fix relative poses).
  bool fix_first = false;
  // The GPS error's white part (m; 0: a fix's whole σ taken as white, no
  // bias vertices) and the correlation time of the rest (s).
  double gps_white_sigma = 0.0;
  double gps_bias_time = 120.0;
};

// A GPS fix for the graph: the robot's position in the map frame and its
// standard deviation, when (the time the fix is valid for, on the
// odometry's clock) and the odometry pose then.
struct GpsMeasurement {
  double x = 0.0, y = 0.0, sigma = 0.0;
  std::int64_t time_ns = 0;
  Se2 odometry{};
};

struct KeyframeCounters {
  std::uint64_t keyframes = 0, gps_edges = 0, loop_closures = 0, bias_vertices = 0;
  std::uint64_t refused_full = 0;     // keyframes not added: capacity reached
  std::uint64_t gps_unattached = 0;   // fixes too far from the latest keyframe or after one was taken
};

class KeyframeGraph {
 public:
  enum class Added { none, keyframe, full };

  explicit KeyframeGraph(const KeyframeOptions& options);

  // Where the first keyframe starts in the map frame (by default at its
  // odometry pose); before the first on_odometry.
  void place_first(const Se2& map_pose) noexcept { first_guess_ = map_pose; placed_ = true; }
  // The odometry pose (odometry frame) at the pose thread's rate.
  Added on_odometry(const Se2& pose);
  // A GPS position of the robot in the map frame with its standard deviation
  // (m), taken at the latest odometry pose (no time: one bias for all) ...
  bool on_gps(double x, double y, double sigma);
  // ... or a whole measurement.
  bool on_gps(const GpsMeasurement& fix);
  // An edge between two keyframes (numbered from 1 in the order they were
  // made) with its information.
  bool add_loop_closure(std::int32_t from, std::int32_t to, const Se2& measurement, const Se2::Matrix& information);

  // Keyframes made, and keyframe i's vertex in the graph (i from 1; 0 is the anchor).
  std::size_t keyframe_count() const noexcept { return keyframes_.size() - 1; }
  std::int32_t keyframe_vertex(std::size_t i) const noexcept { return keyframes_[i]; }
  std::int32_t latest_vertex() const noexcept { return keyframes_.back(); }

  const PoseGraph2d& graph() const noexcept { return graph_; }
  PoseGraph2d& graph() noexcept { return graph_; }
  GraphCapacity capacity() const noexcept { return capacity_; }
  const KeyframeCounters& counters() const noexcept { return counters_; }
  bool full() const noexcept { return keyframe_count() >= options_.max_keyframes; }

 private:
  KeyframeOptions options_;
  GraphCapacity capacity_;
  PoseGraph2d graph_;
  KeyframeCounters counters_;
  bool started_ = false;
  bool placed_ = false;
  Se2 first_guess_{};
  Se2 last_odometry_{}, keyframe_odometry_{};  // the previous pose; the latest keyframe's odometry pose
  double path_ = 0.0, turn_ = 0.0;             // since the latest keyframe
  bool keyframe_has_gps_ = false;
  std::vector<std::int32_t> keyframes_;  // vertex of keyframe i (0: the anchor); reserved
  std::int32_t last_bias_ = -1;          // the newest bias vertex
  std::int64_t last_bias_time_ = 0;
  // A keyframe fits: a vertex and its odometry edge.
  bool room() const noexcept {
    return !full() && graph_.vertex_count() < capacity_.vertices && graph_.edge_count() < capacity_.edges;
  }
  void attach_gps(const GpsMeasurement& fix);
  struct Pending {
    bool valid = false;
    GpsMeasurement fix;
    double path = 0.0;  // path since the keyframe before it
  } pending_;
};

}  // namespace trailnav::slam
