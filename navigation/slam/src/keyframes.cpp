#include "trailnav/navigation/slam/keyframes.hpp"

#include <algorithm>
#include <cmath>

namespace trailnav::slam {

namespace {
constexpr double kGpsHeadingInformation = 1e-9;
// A bias vertex is a translation: its rotation held at 0 by every edge it has.
constexpr double kBiasRotationInformation = 1e6;
}

// Vertices: the anchor, the keyframes and at most one bias vertex a keyframe.
// Edges: one odometry edge a keyframe, at most one GPS edge and one bias
// edge a keyframe, and as many again for loop closures.
KeyframeGraph::KeyframeGraph(const KeyframeOptions& options)
    : options_(options),
      capacity_{2 * options.max_keyframes + 1, 4 * options.max_keyframes},
      graph_(capacity_) {
  graph_.add_vertex(0, Se2{}, true);
  keyframes_.reserve(options.max_keyframes + 1);
  keyframes_.push_back(0);
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
    const auto v = static_cast<std::int32_t>(graph_.vertex_count());
    graph_.add_vertex(v, placed_ ? first_guess_ : pose, options_.fix_first);
    keyframes_.push_back(v);
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
  e.from = latest_vertex();
  e.to = static_cast<std::int32_t>(graph_.vertex_count());
  e.measurement = keyframe_odometry_.inverse() * pose;
  const double sxy = options_.sigma_per_metre * path_, sth = options_.sigma_theta_per_rad * turn_ + options_.sigma_theta_per_metre * path_;
  const double vxy = sxy * sxy + options_.sigma_floor_m * options_.sigma_floor_m;
  const double vth = sth * sth + options_.sigma_floor_rad * options_.sigma_floor_rad;
  e.information = Se2::Matrix::Zero();
  e.information(0, 0) = e.information(1, 1) = 1.0 / vxy;
  e.information(2, 2) = 1.0 / vth;
  // The keyframe starts where the latest keyframe's estimate and the motion put it.
  const Se2 guess = graph_.pose(static_cast<std::size_t>(latest_vertex())) * e.measurement;
  graph_.add_vertex(e.to, guess);
  graph_.add_edge(e);
  keyframes_.push_back(e.to);
  keyframe_odometry_ = pose;
  keyframe_has_gps_ = false;
  ++counters_.keyframes;
  // A fix taken since the previous keyframe, close enough to this one.
  if (pending_.valid) {
    if (path_ - pending_.path <= options_.gps_max_distance) {
      attach_gps(pending_.fix);
    } else {
      ++counters_.gps_unattached;
    }
    pending_.valid = false;
  }
  path_ = turn_ = 0.0;
  return Added::keyframe;
}

bool KeyframeGraph::on_gps(double x, double y, double sigma) {
  GpsMeasurement m;
  m.x = x;
  m.y = y;
  m.sigma = sigma;
  m.odometry = last_odometry_;
  return on_gps(m);
}

bool KeyframeGraph::on_gps(const GpsMeasurement& fix) {
  if (keyframe_count() < 1 || !(fix.sigma > 0.0) || !std::isfinite(fix.x) || !std::isfinite(fix.y)) {
    ++counters_.gps_unattached;
    return false;
  }
  if (!keyframe_has_gps_ && path_ <= options_.gps_max_distance) {
    attach_gps(fix);
    return true;
  }
  // For the next keyframe, if it comes within reach (a newer fix replaces it).
  if (pending_.valid) ++counters_.gps_unattached;
  pending_ = Pending{true, fix, path_};
  return true;
}

void KeyframeGraph::attach_gps(const GpsMeasurement& fix) {
  const bool bias = options_.gps_white_sigma > 0.0;
  if (graph_.edge_count() + (bias ? 2u : 1u) > capacity_.edges || (bias && graph_.vertex_count() >= capacity_.vertices)) {
    ++counters_.gps_unattached;
    return;
  }
  const std::int32_t k = latest_vertex();
  const Se2 r = keyframe_odometry_.inverse() * fix.odometry;
  const double th = graph_.pose(static_cast<std::size_t>(k)).theta, c = std::cos(th), s = std::sin(th);
  GraphEdge<Se2> e;
  e.from = 0;
  e.to = k;
  // The heading of the measurement is the keyframe's current one: with
  // (almost) no information on it, only the position counts.
  e.measurement = Se2{fix.x - (c * r.x - s * r.y), fix.y - (s * r.x + c * r.y), th};
  e.information = Se2::Matrix::Zero();
  double white = fix.sigma;
  if (bias) {
    // The bias vertex of this fix, and its edge from the one before (or the prior).
    white = std::min(fix.sigma, options_.gps_white_sigma);
    const double wander = std::sqrt(std::max(fix.sigma * fix.sigma - white * white, 1e-6));
    const auto b = static_cast<std::int32_t>(graph_.vertex_count());
    const Se2 previous = last_bias_ >= 0 ? graph_.pose(static_cast<std::size_t>(last_bias_)) : Se2{};
    graph_.add_vertex(b, Se2{previous.x, previous.y, 0.0});
    GraphEdge<Se2> chain;
    chain.from = last_bias_ >= 0 ? last_bias_ : 0;
    chain.to = b;
    chain.measurement = Se2{};
    double sd = wander;  // the stationary prior of the first
    if (last_bias_ >= 0) {
      const double dt = std::max(0.0, static_cast<double>(fix.time_ns - last_bias_time_) * 1e-9);
      sd = std::max(wander * std::sqrt(1.0 - std::exp(-2.0 * dt / options_.gps_bias_time)), 1e-3);
    }
    chain.information = Se2::Matrix::Zero();
    chain.information(0, 0) = chain.information(1, 1) = 1.0 / (sd * sd);
    chain.information(2, 2) = kBiasRotationInformation;
    graph_.add_edge(chain);
    last_bias_ = b;
    last_bias_time_ = fix.time_ns;
    ++counters_.bias_vertices;
    e.from = b;  // the keyframe's position less the bias is the fix
  }
  e.information(0, 0) = e.information(1, 1) = 1.0 / (white * white);
  e.information(2, 2) = kGpsHeadingInformation;
  graph_.add_edge(e);
  keyframe_has_gps_ = true;
  ++counters_.gps_edges;
}

bool KeyframeGraph::add_loop_closure(std::int32_t from, std::int32_t to, const Se2& measurement,
                                     const Se2::Matrix& information) {
  const auto n = static_cast<std::int32_t>(keyframe_count());
  if (from < 1 || to < 1 || from > n || to > n || from == to || graph_.edge_count() >= capacity_.edges) return false;
  GraphEdge<Se2> e;
  e.from = keyframes_[static_cast<std::size_t>(from)];
  e.to = keyframes_[static_cast<std::size_t>(to)];
  e.measurement = measurement;
  e.information = information;
  graph_.add_edge(e);
  ++counters_.loop_closures;
  return true;
}

}  // namespace trailnav::slam
