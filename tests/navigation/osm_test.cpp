// The road graph and routing on the real OpenStreetMap extracts of
// ../shared/data/osm and on small hand-written maps for the tag rules.
#include <gtest/gtest.h>

#include <GeographicLib/Geodesic.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "../drivers/test_data.hpp"
#include "trailnav/navigation/osm/road_graph.hpp"
#include "trailnav/navigation/osm/router.hpp"

namespace trailnav::osm {
namespace {

std::string temp_file(const std::string& name, const std::string& text) {
  const auto dir = std::filesystem::temp_directory_path() / "trailnav_osm_test";
  std::filesystem::create_directories(dir);
  const std::string path = (dir / name).string();
  std::ofstream(path, std::ios::binary) << text;
  return path;
}

// A little map in XML: nodes (id, lat, lon, optional tags) and ways.
struct MiniNode {
  int id;
  double lat, lon;
  std::string tags;
};
struct MiniWay {
  int id;
  std::vector<int> nodes;
  std::string tags;
};
std::string mini_osm(const std::vector<MiniNode>& nodes, const std::vector<MiniWay>& ways) {
  std::string s = "<?xml version='1.0' encoding='UTF-8'?>\n<osm version='0.6' generator='test'>\n";
  char buf[256];
  for (const auto& n : nodes) {
    std::snprintf(buf, sizeof buf, "<node id='%d' version='1' lat='%.8f' lon='%.8f'>", n.id, n.lat, n.lon);
    s += buf + n.tags + "</node>\n";
  }
  for (const auto& w : ways) {
    s += "<way id='" + std::to_string(w.id) + "' version='1'>";
    for (int n : w.nodes) s += "<nd ref='" + std::to_string(n) + "'/>";
    s += w.tags + "</way>\n";
  }
  return s + "</osm>\n";
}
std::string tag(const std::string& k, const std::string& v) { return "<tag k='" + k + "' v='" + v + "'/>"; }

const RoadGraph& liechtenstein(const std::string& suffix) {
  static std::map<std::string, RoadGraph> cache;
  auto it = cache.find(suffix);
  if (it == cache.end()) {
    auto r = load_road_graph(test::shared_data("osm/osm2pgsql_liechtenstein-2013-08-03.osm" + suffix));
    EXPECT_TRUE(r.graph) << r.error;
    it = cache.emplace(suffix, std::move(*r.graph)).first;
  }
  return it->second;
}

TEST(RoadGraph, LiechtensteinXmlAndPbfGiveTheSameGraph) {
  const RoadGraph& xml = liechtenstein(".bz2");
  const RoadGraph& pbf = liechtenstein(".pbf");
  EXPECT_EQ(xml.zone(), 32);
  EXPECT_TRUE(xml.north());
  EXPECT_GT(xml.vertex_count(), 10000u);
  ASSERT_EQ(xml.vertex_count(), pbf.vertex_count());
  ASSERT_EQ(xml.edge_count(), pbf.edge_count());
  ASSERT_EQ(xml.segments().size(), pbf.segments().size());
  for (std::size_t i = 0; i < xml.vertex_count(); ++i) {
    ASSERT_EQ(xml.vertices()[i].osm_id, pbf.vertices()[i].osm_id);
    ASSERT_EQ(xml.vertices()[i].x, pbf.vertices()[i].x);
    ASSERT_EQ(xml.vertices()[i].y, pbf.vertices()[i].y);
  }
  // Liechtenstein lies around 47.1 N 9.5 E: UTM 32T, half a degree east of its central meridian.
  EXPECT_NEAR(xml.vertices()[0].x, 540000.0, 15000.0);
  EXPECT_NEAR(xml.vertices()[0].y, 5225000.0, 30000.0);
}

TEST(RoadGraph, LiechtensteinRoutesAgreeBetweenFormatsAndAStarMatchesDijkstra) {
  const RoadGraph& xml = liechtenstein(".bz2");
  const RoadGraph& pbf = liechtenstein(".pbf");
  Router rx(xml), rp(pbf);
  std::vector<Point2> px, pp, pd;
  std::mt19937_64 rng(7);
  std::uniform_int_distribution<std::size_t> pick(0, xml.vertex_count() - 1);
  int found = 0;
  std::uint64_t astar_expanded = 0, dijkstra_expanded = 0;
  for (int i = 0; i < 40; ++i) {
    const RoadVertex& a = xml.vertices()[pick(rng)];
    const RoadVertex& b = xml.vertices()[pick(rng)];
    // Query positions a few metres off the network, as a GPS fix would be.
    const auto fx = xml.project(a.x + 3.0, a.y - 2.0), tx = xml.project(b.x - 2.5, b.y + 4.0);
    const auto fp = pbf.project(a.x + 3.0, a.y - 2.0), tp = pbf.project(b.x - 2.5, b.y + 4.0);
    ASSERT_TRUE(fx && tx && fp && tp);
    const RouteStats sx = rx.route(*fx, *tx, px);
    const RouteStats sp = rp.route(*fp, *tp, pp);
    const RouteStats sd = rx.route(*fx, *tx, pd, Router::Algorithm::dijkstra);
    ASSERT_EQ(sx.found, sp.found);
    ASSERT_EQ(sx.found, sd.found);
    if (!sx.found) continue;
    ++found;
    EXPECT_DOUBLE_EQ(sx.length, sp.length);
    ASSERT_EQ(px.size(), pp.size());
    EXPECT_NEAR(sx.length, sd.length, 1e-6 * std::max(1.0, sd.length));
    EXPECT_NEAR(path_length(px), sx.length, 1e-6 * std::max(1.0, sx.length));
    astar_expanded += sx.expanded;
    dijkstra_expanded += sd.expanded;
  }
  EXPECT_GT(found, 20);  // most of the country is one network
  EXPECT_LT(astar_expanded, dijkstra_expanded / 2);
}

TEST(RoadGraph, ProjectionIsTheNearestSegment) {
  const RoadGraph& g = liechtenstein(".pbf");
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> off(-400.0, 400.0);
  std::uniform_int_distribution<std::size_t> pick(0, g.vertex_count() - 1);
  for (int i = 0; i < 200; ++i) {
    const RoadVertex& v = g.vertices()[pick(rng)];
    const double x = v.x + off(rng), y = v.y + off(rng);
    const auto p = g.project(x, y);
    ASSERT_TRUE(p);
    double best = 1e300;
    for (const RoadSegment& s : g.segments()) {
      const RoadVertex& a = g.vertices()[s.a];
      const RoadVertex& b = g.vertices()[s.b];
      const double dx = b.x - a.x, dy = b.y - a.y, l2 = dx * dx + dy * dy;
      const double t = l2 > 0 ? std::clamp(((x - a.x) * dx + (y - a.y) * dy) / l2, 0.0, 1.0) : 0.0;
      best = std::min(best, std::hypot(x - a.x - t * dx, y - a.y - t * dy));
    }
    ASSERT_NEAR(p->distance, best, 1e-9);
    EXPECT_NEAR(std::hypot(p->x - x, p->y - y), p->distance, 1e-9);
  }
  // Far outside the network too.
  const auto far = g.project(g.vertices()[0].x + 50000.0, g.vertices()[0].y);
  ASSERT_TRUE(far);
  EXPECT_GT(far->distance, 10000.0);
}

TEST(RoadGraph, ReadsEveryShippedFormat) {
  for (const char* name : {"graphhopper_Laufamholzstrasse.osm.xml", "graphhopper_hohe-warte.osm.gz",
                           "graphhopper_krautsand.osm.gz", "graphhopper_monaco.osm.gz"}) {
    double last_progress = -1.0;
    bool monotonic = true;
    const auto r = load_road_graph(test::shared_data(std::string("osm/") + name), {}, [&](double f) {
      monotonic = monotonic && f >= last_progress;
      last_progress = f;
    });
    ASSERT_TRUE(r.graph) << name << ": " << r.error;
    EXPECT_GT(r.graph->edge_count(), 10u) << name;
    EXPECT_GT(r.stats.routable_ways, 0u) << name;
    EXPECT_TRUE(monotonic) << name;
    EXPECT_EQ(last_progress, 1.0) << name;
  }
  // Monaco (7.4 E) is in zone 32, the Nuremberg street (11.1 E) too, Krautsand (9.4 E) as well.
  EXPECT_EQ(load_road_graph(test::shared_data("osm/graphhopper_monaco.osm.gz")).graph->zone(), 32);
}

// The loader's in-memory entry (what the fuzz target drives) reads the same
// graph as the file loader from the bytes of the real PBF extract and of a
// small XML map, and rejects what it cannot read with the given name.
TEST(RoadGraph, BytesInMemoryGiveTheSameGraphAsTheFile) {
  std::ifstream in(test::shared_data("osm/osm2pgsql_liechtenstein-2013-08-03.osm.pbf"), std::ios::binary);
  const std::vector<char> pbf((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GT(pbf.size(), 100'000u);
  const RoadGraphResult r = parse_road_graph(pbf, "liechtenstein.pbf");
  ASSERT_TRUE(r.graph) << r.error;
  const RoadGraph& file = liechtenstein(".pbf");
  ASSERT_EQ(r.graph->vertex_count(), file.vertex_count());
  ASSERT_EQ(r.graph->edge_count(), file.edge_count());
  for (std::size_t i = 0; i < file.vertex_count(); i += 97) {
    EXPECT_EQ(r.graph->vertices()[i].osm_id, file.vertices()[i].osm_id);
    EXPECT_EQ(r.graph->vertices()[i].x, file.vertices()[i].x);
  }

  const std::string xml = mini_osm({{1, 47.0, 9.0, ""}, {2, 47.001, 9.0, ""}}, {{10, {1, 2}, tag("highway", "track")}});
  const RoadGraphResult small = parse_road_graph(xml, "mini.osm");
  ASSERT_TRUE(small.graph) << small.error;
  EXPECT_EQ(small.graph->vertex_count(), 2u);

  const RoadGraphResult cut = parse_road_graph(std::span<const char>(pbf.data(), 5000), "cut.pbf");
  EXPECT_FALSE(cut.graph);
  EXPECT_EQ(cut.error.rfind("cut.pbf: not readable as OpenStreetMap data", 0), 0u) << cut.error;
  EXPECT_NE(parse_road_graph({}, "none").error.find("none: no data"), std::string::npos);
}

TEST(RoadGraph, BadInputGetsAClearError) {
  auto r = load_road_graph("/nonexistent/map.osm.pbf");
  EXPECT_FALSE(r.graph);
  EXPECT_NE(r.error.find("no such OpenStreetMap file"), std::string::npos) << r.error;

  r = load_road_graph(temp_file("empty.osm", ""));
  EXPECT_NE(r.error.find("empty"), std::string::npos) << r.error;

  const std::string good = mini_osm({{1, 47.0, 9.0, ""}, {2, 47.001, 9.0, ""}}, {{10, {1, 2}, tag("highway", "track")}});
  r = load_road_graph(temp_file("broken.osm", good.substr(0, good.size() / 2)));
  EXPECT_FALSE(r.graph);
  EXPECT_NE(r.error.find("not readable as OpenStreetMap data"), std::string::npos) << r.error;

  r = load_road_graph(temp_file("garbage.osm.pbf", std::string(300, '\x17')));
  EXPECT_FALSE(r.graph);
  EXPECT_NE(r.error.find("not readable"), std::string::npos) << r.error;

  r = load_road_graph(temp_file("buildings.osm",
                                mini_osm({{1, 47.0, 9.0, ""}, {2, 47.001, 9.0, ""}, {3, 47.001, 9.001, ""}},
                                         {{10, {1, 2, 3, 1}, tag("building", "yes")},
                                          {11, {1, 2}, tag("highway", "motorway")}})));
  EXPECT_FALSE(r.graph);
  EXPECT_NE(r.error.find("no routable way (2 ways read"), std::string::npos) << r.error;

  r = load_road_graph(temp_file("nothing.osm", "<?xml version='1.0'?><osm version='0.6'></osm>"));
  EXPECT_NE(r.error.find("no OpenStreetMap nodes or ways"), std::string::npos) << r.error;

  // Found by the fuzz target: a way whose references all name one node is no road.
  r = load_road_graph(temp_file("one-node.osm", mini_osm({{1, 47.0, 9.0, ""}}, {{10, {1, 1, 1}, tag("highway", "track")}})));
  EXPECT_FALSE(r.graph);
  EXPECT_NE(r.error.find("no routable way"), std::string::npos) << r.error;
  EXPECT_EQ(r.stats.repeated_nodes, 2u);

  RoutingProfile none;
  none.highways.clear();
  r = load_road_graph(temp_file("good.osm", good), none);
  EXPECT_NE(r.error.find("no highway types"), std::string::npos) << r.error;
}

// A square block: 1-2-3 along the south edge, 3-4 east, 4-5-6 north and
// 6-1 west; about 110 m a side.
std::vector<MiniNode> block_nodes(const std::string& tags_on_2 = "") {
  return {{1, 47.000, 9.0000, ""}, {2, 47.000, 9.0007, tags_on_2}, {3, 47.000, 9.0014, ""},
          {4, 47.001, 9.0014, ""}, {5, 47.001, 9.0007, ""},        {6, 47.001, 9.0000, ""}};
}

TEST(RoadGraph, OnewayBarrierAndAccessRules) {
  const std::string track = tag("highway", "track");
  auto route_len = [](const RoadGraph& g, int from_vertex, int to_vertex) {
    Router r(g);
    std::vector<Point2> path;
    const auto& vs = g.vertices();
    auto find = [&](int id) { for (const auto& v : vs) if (v.osm_id == id) return v; return RoadVertex{}; };
    const RoadVertex a = find(from_vertex), b = find(to_vertex);
    return r.route(*g.project(a.x, a.y), *g.project(b.x, b.y), path);
  };
  // Oneway south edge 1 -> 3: from 3 to 1 the robot goes round the block.
  auto r = load_road_graph(temp_file("oneway.osm", mini_osm(block_nodes(), {{10, {1, 2, 3}, track + tag("oneway", "yes")},
                                                                             {11, {3, 4, 5, 6, 1}, track}})));
  ASSERT_TRUE(r.graph) << r.error;
  EXPECT_EQ(r.stats.oneway_ways, 1u);
  const RouteStats fwd = route_len(*r.graph, 1, 3), back = route_len(*r.graph, 3, 1);
  ASSERT_TRUE(fwd.found && back.found);
  EXPECT_NEAR(fwd.length, 106.2, 1.0);
  EXPECT_GT(back.length, 3 * 100.0);
  // The same map for a robot that ignores oneway tags.
  RoutingProfile free_profile;
  free_profile.respect_oneway = false;
  r = load_road_graph(temp_file("oneway.osm", mini_osm(block_nodes(), {{10, {1, 2, 3}, track + tag("oneway", "yes")},
                                                                        {11, {3, 4, 5, 6, 1}, track}})),
                      free_profile);
  EXPECT_NEAR(route_len(*r.graph, 3, 1).length, 106.2, 1.0);

  // A fence at node 2 closes the south edge there.
  r = load_road_graph(temp_file("fence.osm", mini_osm(block_nodes(tag("barrier", "fence")),
                                                      {{10, {1, 2, 3}, track}, {11, {3, 4, 5, 6, 1}, track}})));
  ASSERT_TRUE(r.graph);
  EXPECT_EQ(r.stats.blocked_nodes, 1u);
  EXPECT_GT(route_len(*r.graph, 1, 3).length, 300.0);
  // A gate does not.
  r = load_road_graph(temp_file("gate.osm", mini_osm(block_nodes(tag("barrier", "gate")),
                                                     {{10, {1, 2, 3}, track}, {11, {3, 4, 5, 6, 1}, track}})));
  EXPECT_NEAR(route_len(*r.graph, 1, 3).length, 106.2, 1.0);
  // A private south edge is not routable at all.
  r = load_road_graph(temp_file("private.osm", mini_osm(block_nodes(), {{10, {1, 2, 3}, track + tag("access", "private")},
                                                                          {11, {3, 4, 5, 6, 1}, track}})));
  EXPECT_EQ(r.stats.closed_ways, 1u);
  EXPECT_GT(route_len(*r.graph, 1, 3).length, 300.0);
  // A way whose node is missing from the file is cut there.
  r = load_road_graph(temp_file("missing.osm", mini_osm(block_nodes(), {{10, {1, 2, 99, 3}, track},
                                                                          {11, {3, 4, 5, 6, 1}, track}})));
  EXPECT_EQ(r.stats.missing_nodes, 1u);
  EXPECT_GT(route_len(*r.graph, 1, 3).length, 300.0);
}

TEST(RoadGraph, StartAndGoalInsideOneWay) {
  auto r = load_road_graph(temp_file("line.osm", mini_osm({{1, 47.0, 9.0, ""}, {2, 47.0, 9.002, ""}},
                                                           {{10, {1, 2}, tag("highway", "path")}})));
  ASSERT_TRUE(r.graph);
  const RoadGraph& g = *r.graph;
  const RoadVertex a = g.vertices()[0], b = g.vertices()[1];
  Router router(g);
  std::vector<Point2> path;
  const auto from = g.project(a.x + 0.25 * (b.x - a.x), a.y + 5.0);
  const auto to = g.project(a.x + 0.75 * (b.x - a.x), a.y - 5.0);
  const RouteStats s = router.route(*from, *to, path);
  ASSERT_TRUE(s.found);
  ASSERT_EQ(path.size(), 2u);
  EXPECT_NEAR(s.length, (to->t - from->t) * std::hypot(b.x - a.x, b.y - a.y), 1e-9);
  EXPECT_NEAR(to->t - from->t, 0.5, 0.01);
  std::vector<Point2> goals;
  subsample_path(path, 4.0, goals);
  EXPECT_EQ(goals.size(), static_cast<std::size_t>(std::floor(s.length / 4.0)) + 2);
  for (std::size_t i = 1; i + 1 < goals.size(); ++i)
    EXPECT_NEAR(std::hypot(goals[i].x - goals[i - 1].x, goals[i].y - goals[i - 1].y), 4.0, 1e-9);
  EXPECT_EQ(goals.back().x, path.back().x);
}

TEST(RoadGraph, ZoneBoundaryKeepsOneMetricPlane) {
  // A track across 12 E, the border of zones 32 and 33, mostly in 33.
  auto r = load_road_graph(temp_file("zones.osm", mini_osm({{1, 48.0, 11.999, ""}, {2, 48.0, 12.004, ""}, {3, 48.0, 12.009, ""}},
                                                            {{10, {1, 2, 3}, tag("highway", "track")}})));
  ASSERT_TRUE(r.graph);
  const RoadGraph& g = *r.graph;
  EXPECT_EQ(g.zone(), 33);
  const auto& geod = GeographicLib::Geodesic::WGS84();
  double s12 = 0.0;
  geod.Inverse(48.0, 11.999, 48.0, 12.004, s12);
  const RoadVertex& a = g.vertices()[0];
  const RoadVertex& b = g.vertices()[1];
  // UTM's scale error near the zone edge is below 0.1 %.
  EXPECT_NEAR(std::hypot(b.x - a.x, b.y - a.y), s12, 1e-3 * s12);
  double lat = 0, lon = 0;
  ASSERT_TRUE(g.to_latlon(a.x, a.y, lat, lon));
  EXPECT_NEAR(lat, 48.0, 1e-9);
  EXPECT_NEAR(lon, 11.999, 1e-9);
  // Forced into zone 32 the same track still measures right.
  r = load_road_graph(temp_file("zones.osm", mini_osm({{1, 48.0, 11.999, ""}, {2, 48.0, 12.004, ""}, {3, 48.0, 12.009, ""}},
                                                       {{10, {1, 2, 3}, tag("highway", "track")}})),
                      {}, {}, 32);
  EXPECT_EQ(r.graph->zone(), 32);
  EXPECT_NEAR(std::hypot(r.graph->vertices()[1].x - r.graph->vertices()[0].x,
                         r.graph->vertices()[1].y - r.graph->vertices()[0].y), s12, 1e-3 * s12);
}

}  // namespace
}  // namespace trailnav::osm
