#include "trailnav/navigation/osm/road_graph.hpp"

#include <GeographicLib/TransverseMercator.hpp>
#include <GeographicLib/UTMUPS.hpp>
#include <algorithm>
#include <cmath>
#include <limits>

namespace trailnav::osm {
namespace {

constexpr double kFalseEasting = 500000.0;
constexpr double kFalseNorthingSouth = 10000000.0;

double central_meridian(int zone) noexcept { return 6.0 * zone - 183.0; }

struct Closest {
  double t = 0.0, x = 0.0, y = 0.0, d2 = 0.0;
};

Closest closest_on_segment(double px, double py, const RoadVertex& a, const RoadVertex& b) noexcept {
  const double dx = b.x - a.x, dy = b.y - a.y;
  const double len2 = dx * dx + dy * dy;
  double t = len2 > 0.0 ? ((px - a.x) * dx + (py - a.y) * dy) / len2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  Closest c;
  c.t = t;
  c.x = a.x + t * dx;
  c.y = a.y + t * dy;
  c.d2 = (px - c.x) * (px - c.x) + (py - c.y) * (py - c.y);
  return c;
}

}  // namespace

int oneway_direction(std::string_view oneway, std::string_view junction) noexcept {
  if (oneway == "yes" || oneway == "true" || oneway == "1") return 1;
  if (oneway == "-1" || oneway == "reverse") return -1;
  if (oneway == "no" || oneway == "false" || oneway == "0") return 0;
  if (junction == "roundabout" || junction == "circular") return 1;
  return 0;
}

double RoadGraph::segment_length(std::uint32_t s) const noexcept {
  const RoadVertex& a = vertices_[segments_[s].a];
  const RoadVertex& b = vertices_[segments_[s].b];
  return std::hypot(b.x - a.x, b.y - a.y);
}

int standard_utm_zone(double lat, double lon) noexcept {
  if (!std::isfinite(lat) || !std::isfinite(lon) || std::abs(lat) > 84.0 || std::abs(lon) > 180.0) return 0;
  try {
    return GeographicLib::UTMUPS::StandardZone(lat, lon);
  } catch (...) {
    return 0;
  }
}

bool utm_in_zone(int zone, bool north, double lat, double lon, double& x, double& y) noexcept {
  if (!(std::abs(lat) <= 84.0) || !std::isfinite(lon)) return false;
  double e = 0.0, n = 0.0;
  GeographicLib::TransverseMercator::UTM().Forward(central_meridian(zone), lat, lon, e, n);
  x = e + kFalseEasting;
  y = n + (north ? 0.0 : kFalseNorthingSouth);
  return std::isfinite(x) && std::isfinite(y);
}

bool RoadGraph::to_utm(double lat, double lon, double& x, double& y) const noexcept {
  return utm_in_zone(zone_, north_, lat, lon, x, y);
}

bool RoadGraph::to_latlon(double x, double y, double& lat, double& lon) const noexcept {
  if (!std::isfinite(x) || !std::isfinite(y)) return false;
  GeographicLib::TransverseMercator::UTM().Reverse(central_meridian(zone_), x - kFalseEasting,
                                                   y - (north_ ? 0.0 : kFalseNorthingSouth), lat, lon);
  return std::isfinite(lat) && std::isfinite(lon);
}

RoadGraph RoadGraph::build(int zone, bool north, std::vector<RoadVertex> vertices, std::vector<RoadWay> ways,
                           const std::vector<std::vector<std::uint32_t>>& way_vertices,
                           const std::vector<int>& oneway) {
  RoadGraph g;
  g.zone_ = zone;
  g.north_ = north;
  g.vertices_ = std::move(vertices);
  g.ways_ = std::move(ways);
  const auto n = static_cast<std::uint32_t>(g.vertices_.size());

  // Segments, then the directed edges in CSR form.
  std::vector<std::uint32_t> out_degree(n + 1, 0);
  for (std::size_t w = 0; w < way_vertices.size(); ++w) {
    const auto& vs = way_vertices[w];
    const int dir = w < oneway.size() ? oneway[w] : 0;
    for (std::size_t i = 1; i < vs.size(); ++i) {
      if (vs[i] == vs[i - 1]) continue;
      RoadSegment s{vs[i - 1], vs[i], static_cast<std::uint32_t>(w), dir >= 0, dir <= 0};
      g.segments_.push_back(s);
      if (s.forward) ++out_degree[s.a];
      if (s.backward) ++out_degree[s.b];
    }
  }
  g.edge_begin_.assign(n + 1, 0);
  for (std::uint32_t v = 0; v < n; ++v) g.edge_begin_[v + 1] = g.edge_begin_[v] + out_degree[v];
  g.edges_.resize(g.edge_begin_[n]);
  std::vector<std::uint32_t> fill(g.edge_begin_.begin(), g.edge_begin_.end() - 1);
  for (std::uint32_t s = 0; s < g.segments_.size(); ++s) {
    const RoadSegment& seg = g.segments_[s];
    const double len = g.segment_length(s);
    if (seg.forward) g.edges_[fill[seg.a]++] = RoadEdge{seg.b, seg.way, len};
    if (seg.backward) g.edges_[fill[seg.b]++] = RoadEdge{seg.a, seg.way, len};
  }

  // The segment grid.
  if (!g.vertices_.empty()) {
    double x0 = std::numeric_limits<double>::max(), y0 = x0, x1 = -x0, y1 = -x0;
    for (const RoadVertex& v : g.vertices_) {
      x0 = std::min(x0, v.x); y0 = std::min(y0, v.y);
      x1 = std::max(x1, v.x); y1 = std::max(y1, v.y);
    }
    // About one segment per cell on average, no finer than 10 m.
    const double area = std::max(1.0, (x1 - x0) * (y1 - y0));
    g.cell_ = std::max(10.0, std::sqrt(area / std::max<double>(1.0, static_cast<double>(g.segments_.size()))));
    g.grid_x0_ = x0;
    g.grid_y0_ = y0;
    g.grid_nx_ = static_cast<std::int32_t>((x1 - x0) / g.cell_) + 1;
    g.grid_ny_ = static_cast<std::int32_t>((y1 - y0) / g.cell_) + 1;
    const auto cells = static_cast<std::size_t>(g.grid_nx_) * static_cast<std::size_t>(g.grid_ny_);
    std::vector<std::uint32_t> count(cells + 1, 0);
    auto for_cells = [&](const RoadSegment& s, auto&& f) {
      const RoadVertex& a = g.vertices_[s.a];
      const RoadVertex& b = g.vertices_[s.b];
      const auto cx0 = static_cast<std::int32_t>((std::min(a.x, b.x) - x0) / g.cell_);
      const auto cx1 = static_cast<std::int32_t>((std::max(a.x, b.x) - x0) / g.cell_);
      const auto cy0 = static_cast<std::int32_t>((std::min(a.y, b.y) - y0) / g.cell_);
      const auto cy1 = static_cast<std::int32_t>((std::max(a.y, b.y) - y0) / g.cell_);
      for (std::int32_t cy = cy0; cy <= cy1; ++cy)
        for (std::int32_t cx = cx0; cx <= cx1; ++cx)
          f(static_cast<std::size_t>(cy) * static_cast<std::size_t>(g.grid_nx_) + static_cast<std::size_t>(cx));
    };
    for (const RoadSegment& s : g.segments_) for_cells(s, [&](std::size_t c) { ++count[c + 1]; });
    for (std::size_t c = 0; c < cells; ++c) count[c + 1] += count[c];
    g.grid_begin_ = count;
    g.grid_segments_.resize(count[cells]);
    for (std::uint32_t i = 0; i < g.segments_.size(); ++i)
      for_cells(g.segments_[i], [&](std::size_t c) { g.grid_segments_[count[c]++] = i; });
  }
  return g;
}

std::optional<RoadProjection> RoadGraph::project(double x, double y) const noexcept {
  // Not a position (the orders fuzzer found a NaN pose reaching the grid lookup).
  if (segments_.empty() || !std::isfinite(x) || !std::isfinite(y)) return std::nullopt;
  RoadProjection best;
  double best_d2 = std::numeric_limits<double>::max();
  auto consider = [&](std::uint32_t s) {
    const Closest c = closest_on_segment(x, y, vertices_[segments_[s].a], vertices_[segments_[s].b]);
    if (c.d2 < best_d2 || (c.d2 == best_d2 && s < best.segment)) {
      best_d2 = c.d2;
      best = RoadProjection{s, c.t, c.x, c.y, 0.0};
    }
  };
  const double fx = (x - grid_x0_) / cell_, fy = (y - grid_y0_) / cell_;
  if (fx < 0.0 || fy < 0.0 || fx >= grid_nx_ || fy >= grid_ny_) {
    // Outside the network's bounding box: every segment (rare, and exact).
    for (std::uint32_t s = 0; s < segments_.size(); ++s) consider(s);
  } else {
    const auto cx = static_cast<std::int32_t>(fx), cy = static_cast<std::int32_t>(fy);
    const std::int32_t max_ring = std::max(grid_nx_, grid_ny_);
    for (std::int32_t r = 0; r <= max_ring; ++r) {
      // A segment not seen yet lies wholly outside rings 0..r-1, so at least
      // (r - 1) cells from the query: stop once the best is nearer than that.
      if (r > 0 && best_d2 <= std::pow((r - 1) * cell_, 2)) break;
      for (std::int32_t yy = cy - r; yy <= cy + r; ++yy) {
        if (yy < 0 || yy >= grid_ny_) continue;
        const bool edge_row = yy == cy - r || yy == cy + r;
        for (std::int32_t xx = cx - r; xx <= cx + r; xx += edge_row ? 1 : 2 * std::max(r, 1)) {
          if (xx < 0 || xx >= grid_nx_) continue;
          const std::size_t c = static_cast<std::size_t>(yy) * static_cast<std::size_t>(grid_nx_) + static_cast<std::size_t>(xx);
          for (std::uint32_t k = grid_begin_[c]; k < grid_begin_[c + 1]; ++k) consider(grid_segments_[k]);
        }
      }
    }
  }
  best.distance = std::sqrt(best_d2);
  return best;
}

}  // namespace trailnav::osm
