#include "trailnav/navigation/slam/keyframes.hpp"

#include <cmath>

namespace trailnav::slam {

namespace {
constexpr double kGpsHeadingInformation = 1e-9;
}

// Edges: one odometry edge a keyframe, at most one GPS edge a keyframe, and
// as many again for loop closures.
KeyframeGraph::KeyframeGraph(const KeyframeOptions& options)
    : options_(options),
      capacity_{options.max_keyframes + 1, 4 * options.max_keyframes},
      graph_(capacity_) {
  graph_.add_vertex(0, Se2{}, true);
}

KeyframeGraph::Added KeyframeGraph::on_odometry(const Se2& pose) {
  if (!started_) {
    started_ = true;
    last_odometry_ = pose;
    if (!room()) {
      ++counters_.refused_full;
      return Added::full;
    }
    keyframe_odometry_ = pose;
    graph_.add_vertex(1, pose);
    ++counters_.keyframes;
    keyframe_has_gps_ = false;
    return Added::keyframe;
  }
  const Se2 step = last_odometry_.inverse() * pose;
  path_ += std::hypot(step.x, step.y);
  turn_ += std::fabs(step.theta);
  last_odometry_ = pose;
  if (path_ < options_.spacing_m && turn_ < options_.spacing_rad) return Added::none;
  if (!room()) {
    ++counters_.refused_full;
    path_ = turn_ = 0.0;
    return Added::full;
  }
  // The relative motion since the latest keyframe and its covariance.
  GraphEdge<Se2> e;
  e.from = static_cast<std::int32_t>(graph_.vertex_count() - 1);
  e.to = static_cast<std::int32_t>(graph_.vertex_count());
  e.measurement = keyframe_odometry_.inverse() * pose;
  const double sxy = options_.sigma_per_metre * path_, sth = options_.sigma_theta_per_rad * turn_ + options_.sigma_theta_per_metre * path_;
  const double vxy = sxy * sxy + options_.sigma_floor_m * options_.sigma_floor_m;
  const double vth = sth * sth + options_.sigma_floor_rad * options_.sigma_floor_rad;
  e.information = Se2::Matrix::Zero();
  e.information(0, 0) = e.information(1, 1) = 1.0 / vxy;
  e.information(2, 2) = 1.0 / vth;
  // The keyframe starts where the latest keyframe's estimate and the motion put it.
  const Se2 guess = graph_.pose(graph_.vertex_count() - 1) * e.measurement;
  graph_.add_vertex(static_cast<std::int64_t>(graph_.vertex_count()), guess);
  graph_.add_edge(e);
  keyframe_odometry_ = pose;
  keyframe_has_gps_ = false;
  ++counters_.keyframes;
  // A fix taken since the previous keyframe, close enough to this one.
  if (pending_.valid) {
    if (path_ - pending_.path <= options_.gps_max_distance && graph_.edge_count() < capacity_.edges) {
      attach_gps(pending_.odometry, pending_.x, pending_.y, pending_.sigma);
    } else {
      ++counters_.gps_unattached;
    }
    pending_.valid = false;
  }
  path_ = turn_ = 0.0;
  return Added::keyframe;
}

bool KeyframeGraph::on_gps(double x, double y, double sigma) {
  if (graph_.vertex_count() < 2 || !(sigma > 0.0) || !std::isfinite(x) || !std::isfinite(y) ||
      graph_.edge_count() >= capacity_.edges) {
    ++counters_.gps_unattached;
    return false;
  }
  if (!keyframe_has_gps_ && path_ <= options_.gps_max_distance) {
    attach_gps(last_odometry_, x, y, sigma);
    return true;
  }
  // For the next keyframe, if it comes within reach (a newer fix replaces it).
  if (pending_.valid) ++counters_.gps_unattached;
  pending_ = Pending{true, last_odometry_, x, y, sigma, path_};
  return true;
}

void KeyframeGraph::attach_gps(const Se2& fix_odometry, double x, double y, double sigma) {
  const std::size_t k = graph_.vertex_count() - 1;
  const Se2 r = keyframe_odometry_.inverse() * fix_odometry;
  const double th = graph_.pose(k).theta, c = std::cos(th), s = std::sin(th);
  GraphEdge<Se2> e;
  e.from = 0;
  e.to = static_cast<std::int32_t>(k);
  // The heading of the measurement is the keyframe's current one: with
  // (almost) no information on it, only the position counts.
  e.measurement = Se2{x - (c * r.x - s * r.y), y - (s * r.x + c * r.y), th};
  e.information = Se2::Matrix::Zero();
  e.information(0, 0) = e.information(1, 1) = 1.0 / (sigma * sigma);
  e.information(2, 2) = kGpsHeadingInformation;
  graph_.add_edge(e);
  keyframe_has_gps_ = true;
  ++counters_.gps_edges;
}

bool KeyframeGraph::add_loop_closure(std::int32_t from, std::int32_t to, const Se2& measurement,
                                     const Se2::Matrix& information) {
  const auto n = static_cast<std::int32_t>(graph_.vertex_count());
  if (from < 1 || to < 1 || from >= n || to >= n || from == to || graph_.edge_count() >= capacity_.edges) return false;
  GraphEdge<Se2> e;
  e.from = from;
  e.to = to;
  e.measurement = measurement;
  e.information = information;
  graph_.add_edge(e);
  ++counters_.loop_closures;
  return true;
}

}  // namespace trailnav::slam
