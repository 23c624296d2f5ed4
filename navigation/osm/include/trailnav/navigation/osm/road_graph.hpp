// The routable road network of an OpenStreetMap extract (thesis §8.1.1), in
// UTM metres.
//
// Every node of a routable way becomes a vertex; consecutive nodes of a way
// are joined by an edge per allowed direction whose cost is its length. Which
// ways count is the robot's RoutingProfile: highway types, access values that
// close a way, barrier values that close a node, and whether oneway tags
// bind the robot. Coordinates are in one UTM zone chosen from the data (the
// zone of the centre of the routable nodes' bounding box); nodes beyond the
// zone's edge are projected into it as well, so a network across a zone
// boundary stays one metric plane.
//
// Loading (load_road_graph) reads .osm, .osm.gz, .osm.bz2 and .osm.pbf with
// libosmium, reports progress in bytes read, and returns a clear error for a
// missing, broken, empty or non-routable file. The graph is immutable after
// loading; routing (router.hpp) keeps its own preallocated work arrays.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace trailnav::osm {

struct RoutingProfile {
  // Values of the highway tag the robot may drive on.
  std::vector<std::string> highways{"track", "path", "unclassified", "residential", "service",
                                    "living_street", "tertiary", "secondary", "cycleway", "bridleway", "footway"};
  // access / vehicle values that close a way or node to the robot.
  std::vector<std::string> closed_access{"no", "private"};
  // barrier values the robot cannot pass (a node carrying one closes the way there).
  std::vector<std::string> blocking_barriers{"wall", "fence", "hedge", "retaining_wall", "city_wall", "ditch",
                                              "block", "jersey_barrier", "log", "debris"};
  bool respect_oneway = true;
};

struct RoadVertex {
  double x = 0.0, y = 0.0;  // UTM easting, northing
  std::int64_t osm_id = 0;
};

struct RoadEdge {
  std::uint32_t to = 0;
  std::uint32_t way = 0;  // index into RoadGraph::ways()
  double length = 0.0;    // m
};

struct RoadWay {
  std::int64_t osm_id = 0;
  std::string highway;
  std::string name;
};

// An undirected piece of a way between two consecutive vertices; the
// projection of a position onto the network (§8.1.1) is onto these.
struct RoadSegment {
  std::uint32_t a = 0, b = 0;
  std::uint32_t way = 0;
  bool forward = true;   // a -> b allowed
  bool backward = true;  // b -> a allowed
};

// A position projected orthogonally onto the nearest segment.
struct RoadProjection {
  std::uint32_t segment = 0;
  double t = 0.0;         // 0 at a, 1 at b
  double x = 0.0, y = 0.0;
  double distance = 0.0;  // m from the queried position
};

class RoadGraph {
 public:
  int zone() const noexcept { return zone_; }
  bool north() const noexcept { return north_; }
  std::size_t vertex_count() const noexcept { return vertices_.size(); }
  std::size_t edge_count() const noexcept { return edges_.size(); }
  std::span<const RoadVertex> vertices() const noexcept { return vertices_; }
  std::span<const RoadSegment> segments() const noexcept { return segments_; }
  std::span<const RoadWay> ways() const noexcept { return ways_; }
  // Edges leaving vertex v.
  std::span<const RoadEdge> edges(std::uint32_t v) const noexcept {
    return {edges_.data() + edge_begin_[v], edges_.data() + edge_begin_[v + 1]};
  }
  double segment_length(std::uint32_t s) const noexcept;

  // WGS84 <-> this graph's UTM zone (GeographicLib; any point, projected into
  // the graph's zone). False for a latitude beyond +-84 degrees or NaN.
  bool to_utm(double lat, double lon, double& x, double& y) const noexcept;
  bool to_latlon(double x, double y, double& lat, double& lon) const noexcept;

  // The orthogonal projection of (x, y) onto the nearest segment; none for
  // a non-finite position or an empty graph. A grid index over the segments
  // makes it independent of the network's size.
  std::optional<RoadProjection> project(double x, double y) const noexcept;

  // Builds the graph from ways given as vertex sequences (the loader and the
  // tests use it). `way_vertices[i]` belongs to `ways[i]`; `oneway[i]` is +1
  // (forward only), -1 (backward only) or 0.
  static RoadGraph build(int zone, bool north, std::vector<RoadVertex> vertices, std::vector<RoadWay> ways,
                         const std::vector<std::vector<std::uint32_t>>& way_vertices, const std::vector<int>& oneway);

 private:
  int zone_ = 0;
  bool north_ = true;
  std::vector<RoadVertex> vertices_;
  std::vector<RoadWay> ways_;
  std::vector<RoadSegment> segments_;
  std::vector<std::uint32_t> edge_begin_;  // vertex_count + 1
  std::vector<RoadEdge> edges_;
  // Segment grid: cells of `cell_` m from (grid_x0_, grid_y0_).
  double cell_ = 50.0, grid_x0_ = 0.0, grid_y0_ = 0.0;
  std::int32_t grid_nx_ = 0, grid_ny_ = 0;
  std::vector<std::uint32_t> grid_begin_;
  std::vector<std::uint32_t> grid_segments_;
};

struct RoadGraphStats {
  std::uint64_t nodes_read = 0, ways_read = 0;
  std::uint64_t routable_ways = 0;
  std::uint64_t closed_ways = 0;       // highway type matched but access closed
  std::uint64_t blocked_nodes = 0;     // barriers and closed nodes on routable ways
  std::uint64_t missing_nodes = 0;     // way references to nodes not in the file
  std::uint64_t repeated_nodes = 0;    // way references repeating the node before them (dropped)
  std::uint64_t oneway_ways = 0;
};

struct RoadGraphResult {
  std::optional<RoadGraph> graph;
  RoadGraphStats stats;
  std::string error;
};

// Reads an OpenStreetMap file (format from its name: .osm, .osm.xml, .osm.gz,
// .osm.bz2, .osm.pbf, .pbf). `progress` receives the fraction of the file
// read. `zone`: 0 chooses it from the data.
RoadGraphResult load_road_graph(const std::string& path, const RoutingProfile& profile = {},
                                const std::function<void(double)>& progress = {}, int zone = 0);
// The same from bytes in memory: OSM XML when they start with '<', PBF
// otherwise; `name` prefixes the messages (the fuzz target uses it).
RoadGraphResult parse_road_graph(std::span<const char> data, const std::string& name, const RoutingProfile& profile = {},
                                 int zone = 0);

// The UTM zone a position belongs to (GeographicLib's standard zone, with the
// Norway and Svalbard exceptions); 0 beyond the UTM latitudes or for NaN.
int standard_utm_zone(double lat, double lon) noexcept;

// WGS84 to UTM in the given zone and hemisphere, for points inside or
// beyond the zone (transverse Mercator about its central meridian).
bool utm_in_zone(int zone, bool north, double lat, double lon, double& x, double& y) noexcept;

// The oneway direction of a way's tags: +1, -1 or 0 (the values of the OSM
// wiki: yes/true/1, -1/reverse; a roundabout is one way).
int oneway_direction(std::string_view oneway, std::string_view junction) noexcept;

}  // namespace trailnav::osm
