// Fuzzes the OpenStreetMap loader (parse_road_graph: XML when the bytes start
// with '<', PBF otherwise): any bytes give a road graph or a message, never a
// crash. A graph that loads is checked for what the router relies on: every
// segment joins two existing vertices of an existing way, every coordinate is
// finite, edges stay inside their tables; and one route is planned on it.
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "check.hpp"

#include "trailnav/navigation/osm/road_graph.hpp"
#include "trailnav/navigation/osm/router.hpp"

using namespace trailnav;
using namespace trailnav::osm;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  RoutingProfile profile;
  const RoadGraphResult r =
      parse_road_graph(std::span<const char>(reinterpret_cast<const char*>(data), size), "fuzz.osm", profile);
  check(r.graph.has_value() != !r.error.empty());
  if (!r.graph) return 0;
  const RoadGraph& g = *r.graph;
  check(g.vertex_count() > 1 && !g.segments().empty());
  for (const RoadVertex& v : g.vertices()) check(std::isfinite(v.x) && std::isfinite(v.y));
  for (const RoadSegment& s : g.segments()) {
    check(s.a < g.vertex_count() && s.b < g.vertex_count() && s.way < g.ways().size());
    check(std::isfinite(g.segment_length(static_cast<std::uint32_t>(&s - g.segments().data()))));
  }
  std::size_t edges = 0;
  for (std::uint32_t v = 0; v < g.vertex_count(); ++v) edges += g.edges(v).size();
  check(edges == g.edge_count());
  // From the first vertex to the last, through the projections the router uses.
  const RoadVertex& a = g.vertices().front();
  const RoadVertex& b = g.vertices().back();
  const auto from = g.project(a.x + 3.0, a.y - 2.0);
  const auto to = g.project(b.x - 1.0, b.y + 4.0);
  check(from.has_value() && to.has_value());
  Router router(g);
  std::vector<Point2> path;
  const RouteStats st = router.route(*from, *to, path);
  check(st.found == !path.empty());
  if (st.found) check(std::isfinite(st.length) && st.length >= 0.0);
  return 0;
}
