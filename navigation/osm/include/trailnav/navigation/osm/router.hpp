// Shortest paths on the road graph (thesis §8.1.1): A* with the straight-line
// distance as heuristic (admissible and consistent, since every edge costs
// its straight length), or Dijkstra (the same search without heuristic; the
// tests compare the two). Start and goal are positions projected onto their
// nearest segments, so a route may begin and end inside a way.
//
// A Router allocates its work arrays once, for its graph; route() then
// allocates nothing as long as `path` has capacity for vertex_count() + 2
// points (reserve_path does that), so the navigation thread can re-plan.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "trailnav/navigation/osm/road_graph.hpp"

namespace trailnav::osm {

struct Point2 {
  double x = 0.0, y = 0.0;
};

struct RouteStats {
  bool found = false;
  double length = 0.0;            // m
  std::uint64_t expanded = 0;     // vertices settled
};

class Router {
 public:
  explicit Router(const RoadGraph& graph);

  enum class Algorithm { astar, dijkstra };
  // The shortest path from `from` to `to` (both projections onto this
  // graph), as a polyline starting at from's point and ending at to's.
  // `path` is cleared first; empty when there is no path.
  RouteStats route(const RoadProjection& from, const RoadProjection& to, std::vector<Point2>& path,
                   Algorithm algorithm = Algorithm::astar);

  void reserve_path(std::vector<Point2>& path) const { path.reserve(graph_.vertex_count() + 2); }
  const RoadGraph& graph() const noexcept { return graph_; }

 private:
  struct QueueEntry {
    double f;
    std::uint32_t v;
  };
  const RoadGraph& graph_;
  std::vector<double> g_;
  std::vector<std::uint32_t> parent_;
  std::vector<std::uint32_t> stamp_;  // search number that last touched a vertex
  std::vector<QueueEntry> heap_;
  std::uint32_t search_ = 0;
};

// Points every `spacing` metres along `path` (arc length), starting with its
// first point and ending with its last: the subgoals g_0..g_n. `out` is
// cleared first; it allocates only beyond its capacity.
void subsample_path(std::span<const Point2> path, double spacing, std::vector<Point2>& out);

// Length of a polyline.
double path_length(std::span<const Point2> path) noexcept;

}  // namespace trailnav::osm
