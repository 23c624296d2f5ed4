#include "trailnav/navigation/osm/router.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace trailnav::osm {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();

}  // namespace

Router::Router(const RoadGraph& graph) : graph_(graph) {
  const std::size_t n = graph.vertex_count() + 2;  // + start, goal
  g_.assign(n, kInf);
  parent_.assign(n, kNone);
  stamp_.assign(n, 0);
  heap_.reserve(graph.edge_count() + 8);
}

RouteStats Router::route(const RoadProjection& from, const RoadProjection& to, std::vector<Point2>& path,
                         Algorithm algorithm) {
  path.clear();
  RouteStats stats;
  const auto n = static_cast<std::uint32_t>(graph_.vertex_count());
  const std::uint32_t start = n, goal = n + 1;
  const auto vertices = graph_.vertices();
  const RoadSegment& ss = graph_.segments()[from.segment];
  const RoadSegment& gs = graph_.segments()[to.segment];
  const double ss_len = graph_.segment_length(from.segment);
  const double gs_len = graph_.segment_length(to.segment);

  if (++search_ == 0) {  // wrapped: forget every stamp
    std::fill(stamp_.begin(), stamp_.end(), 0);
    search_ = 1;
  }
  auto touch = [&](std::uint32_t v) {
    if (stamp_[v] != search_) {
      stamp_[v] = search_;
      g_[v] = kInf;
      parent_[v] = kNone;
    }
  };
  auto xy = [&](std::uint32_t v, double& x, double& y) {
    if (v == start) { x = from.x; y = from.y; }
    else if (v == goal) { x = to.x; y = to.y; }
    else { x = vertices[v].x; y = vertices[v].y; }
  };
  auto h = [&](std::uint32_t v) {
    if (algorithm == Algorithm::dijkstra) return 0.0;
    double x = 0.0, y = 0.0;
    xy(v, x, y);
    return std::hypot(x - to.x, y - to.y);
  };
  heap_.clear();
  auto greater = [](const QueueEntry& a, const QueueEntry& b) { return a.f > b.f || (a.f == b.f && a.v > b.v); };
  auto relax = [&](std::uint32_t u, std::uint32_t v, double cost) {
    touch(v);
    const double g = g_[u] + cost;
    if (g < g_[v]) {
      g_[v] = g;
      parent_[v] = u;
      heap_.push_back({g + h(v), v});
      std::push_heap(heap_.begin(), heap_.end(), greater);
    }
  };

  touch(start);
  touch(goal);
  g_[start] = 0.0;
  heap_.push_back({h(start), start});
  while (!heap_.empty()) {
    std::pop_heap(heap_.begin(), heap_.end(), greater);
    const QueueEntry e = heap_.back();
    heap_.pop_back();
    const std::uint32_t u = e.v;
    if (e.f > g_[u] + h(u) + 1e-9) continue;  // stale entry
    ++stats.expanded;
    if (u == goal) break;
    if (u == start) {
      // Along the start segment to its ends, or straight to the goal on the same segment.
      if (ss.backward) relax(start, ss.a, from.t * ss_len);
      if (ss.forward) relax(start, ss.b, (1.0 - from.t) * ss_len);
      if (from.segment == to.segment && ((to.t >= from.t && ss.forward) || (to.t <= from.t && ss.backward)))
        relax(start, goal, std::abs(to.t - from.t) * ss_len);
      continue;
    }
    for (const RoadEdge& edge : graph_.edges(u)) relax(u, edge.to, edge.length);
    if (u == gs.a && gs.forward) relax(u, goal, to.t * gs_len);
    if (u == gs.b && gs.backward) relax(u, goal, (1.0 - to.t) * gs_len);
  }
  if (stamp_[goal] != search_ || parent_[goal] == kNone) return stats;

  stats.found = true;
  stats.length = g_[goal];
  for (std::uint32_t v = goal; v != kNone; v = parent_[v]) {
    Point2 p;
    xy(v, p.x, p.y);
    path.push_back(p);
    if (v == start) break;
  }
  std::reverse(path.begin(), path.end());
  return stats;
}

double path_length(std::span<const Point2> path) noexcept {
  double s = 0.0;
  for (std::size_t i = 1; i < path.size(); ++i) s += std::hypot(path[i].x - path[i - 1].x, path[i].y - path[i - 1].y);
  return s;
}

void subsample_path(std::span<const Point2> path, double spacing, std::vector<Point2>& out) {
  out.clear();
  if (path.empty()) return;
  out.push_back(path.front());
  double next = spacing;  // arc of the next subgoal
  double arc = 0.0;       // arc at path[i - 1]
  for (std::size_t i = 1; i < path.size(); ++i) {
    const double dx = path[i].x - path[i - 1].x, dy = path[i].y - path[i - 1].y;
    const double len = std::hypot(dx, dy);
    while (len > 0.0 && next <= arc + len) {
      const double t = (next - arc) / len;
      out.push_back({path[i - 1].x + t * dx, path[i - 1].y + t * dy});
      next += spacing;
    }
    arc += len;
  }
  const Point2& last = path.back();
  const Point2& prev = out.back();
  if (out.size() == 1 || std::hypot(last.x - prev.x, last.y - prev.y) > 1e-6) out.push_back(last);
}

}  // namespace trailnav::osm
