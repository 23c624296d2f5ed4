// The road network of a scenario: true trail centrelines (splines through the
// control points), their junctions, the robot's route along them, and the
// OpenStreetMap view with the errors the thesis reports (§8.3.1).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "scenario.hpp"
#include "trailnav/runtime/status.hpp"

namespace trailnav::sim {

// World coordinates (x east, y north, metres from the scenario origin) <->
// WGS84, through the origin's UTM zone (GeographicLib).
class GeoFrame {
 public:
  explicit GeoFrame(double origin_lat, double origin_lon);
  void to_latlon(double x, double y, double& lat, double& lon) const;
  Vec2 from_latlon(double lat, double lon) const;
  int zone() const noexcept { return zone_; }
  bool north() const noexcept { return north_; }
  // Meridian convergence at the origin: the angle from true north to grid north (rad).
  double convergence() const noexcept { return convergence_; }

 private:
  int zone_ = 0;
  bool north_ = true;
  double easting0_ = 0.0;
  double northing0_ = 0.0;
  double convergence_ = 0.0;
};

struct Polyline {
  std::vector<Vec2> points;
  std::vector<double> s;  // arc length at each point

  explicit Polyline(std::vector<Vec2> pts = {});
  double length() const noexcept { return s.empty() ? 0.0 : s.back(); }
  Vec2 at(double arc) const noexcept;
  Vec2 tangent(double arc) const noexcept;  // unit
  Vec2 normal(double arc) const noexcept { const Vec2 t = tangent(arc); return {-t.y(), t.x()}; }  // left
  struct Projection {
    double arc = 0.0;
    double distance = 0.0;
    Vec2 point{0, 0};
  };
  Projection project(const Vec2& p) const noexcept;
};

struct TrailGeometry {
  const Trail* spec = nullptr;
  Polyline centre;
};

enum class JunctionKind : std::uint8_t { t, x, l };

struct Junction {
  int a = 0;  // trail indices
  int b = 0;
  double arc_a = 0.0;
  double arc_b = 0.0;
  Vec2 point{0, 0};
  JunctionKind kind = JunctionKind::x;
  Vec2 mapped{0, 0};  // where OpenStreetMap puts it (world frame)
};

struct OsmWay {
  int trail = 0;
  std::vector<std::int64_t> nodes;  // node ids
  std::vector<Vec2> points;         // their world positions
};

struct RoadNetwork {
  std::vector<TrailGeometry> trails;
  std::vector<Junction> junctions;
  Polyline route;            // the robot's path: true centrelines of the route legs
  std::vector<OsmWay> osm;   // the mapped view
};

struct RoadsResult {
  std::optional<RoadNetwork> roads;
  std::string error;
};

RoadsResult build_roads(const Scenario& scenario, std::uint64_t seed);

Status write_osm(const std::string& path, const RoadNetwork& roads, const Scenario& scenario, const GeoFrame& geo);

}  // namespace trailnav::sim
