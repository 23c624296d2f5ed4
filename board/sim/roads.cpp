#include "roads.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <numbers>

#include <GeographicLib/UTMUPS.hpp>

#include "random.hpp"

namespace trailnav::sim {
namespace {

constexpr double kSplineStep = 0.2;  // m between centreline samples

// Centripetal Catmull-Rom spline through the control points (no cusps or
// self-intersections within a segment), sampled about every kSplineStep.
std::vector<Vec2> spline(const std::vector<Vec2>& c) {
  std::vector<Vec2> out;
  if (c.size() == 2) {
    const double len = (c[1] - c[0]).norm();
    const int n = std::max(1, static_cast<int>(std::ceil(len / kSplineStep)));
    for (int i = 0; i <= n; ++i) out.push_back(c[0] + (c[1] - c[0]) * (static_cast<double>(i) / n));
    return out;
  }
  auto knot = [](double t, const Vec2& a, const Vec2& b) { return t + std::sqrt(std::max((b - a).norm(), 1e-6)); };
  for (std::size_t i = 0; i + 1 < c.size(); ++i) {
    const Vec2 p1 = c[i];
    const Vec2 p2 = c[i + 1];
    const Vec2 p0 = i == 0 ? p1 + (p1 - p2) : c[i - 1];
    const Vec2 p3 = i + 2 >= c.size() ? p2 + (p2 - p1) : c[i + 2];
    const double t0 = 0.0;
    const double t1 = knot(t0, p0, p1);
    const double t2 = knot(t1, p1, p2);
    const double t3 = knot(t2, p2, p3);
    const double len = (p2 - p1).norm();
    const int n = std::max(1, static_cast<int>(std::ceil(len / kSplineStep)));
    for (int k = (i == 0 ? 0 : 1); k <= n; ++k) {
      const double t = t1 + (t2 - t1) * static_cast<double>(k) / n;
      const Vec2 a1 = (t1 - t) / (t1 - t0) * p0 + (t - t0) / (t1 - t0) * p1;
      const Vec2 a2 = (t2 - t) / (t2 - t1) * p1 + (t - t1) / (t2 - t1) * p2;
      const Vec2 a3 = (t3 - t) / (t3 - t2) * p2 + (t - t2) / (t3 - t2) * p3;
      const Vec2 b1 = (t2 - t) / (t2 - t0) * a1 + (t - t0) / (t2 - t0) * a2;
      const Vec2 b2 = (t3 - t) / (t3 - t1) * a2 + (t - t1) / (t3 - t1) * a3;
      out.push_back((t2 - t) / (t2 - t1) * b1 + (t - t1) / (t2 - t1) * b2);
    }
  }
  return out;
}

// Proper intersection of segments p1p2 and q1q2: the parameters along each.
bool intersect(const Vec2& p1, const Vec2& p2, const Vec2& q1, const Vec2& q2, double& u, double& v) {
  const Vec2 r = p2 - p1;
  const Vec2 s = q2 - q1;
  const double den = r.x() * s.y() - r.y() * s.x();
  if (std::abs(den) < 1e-12) return false;
  const Vec2 d = q1 - p1;
  u = (d.x() * s.y() - d.y() * s.x()) / den;
  v = (d.x() * r.y() - d.y() * r.x()) / den;
  return u >= 0.0 && u <= 1.0 && v >= 0.0 && v <= 1.0;
}

void find_junctions(RoadNetwork& net) {
  const auto n = static_cast<int>(net.trails.size());
  for (int a = 0; a < n; ++a) {
    for (int b = a + 1; b < n; ++b) {
      const Polyline& pa = net.trails[static_cast<std::size_t>(a)].centre;
      const Polyline& pb = net.trails[static_cast<std::size_t>(b)].centre;
      std::vector<Junction> found;
      auto add = [&](double arc_a, double arc_b, JunctionKind kind) {
        const Vec2 p = pa.at(arc_a);
        for (const Junction& j : found) {
          if ((j.point - p).norm() < 3.0) return;
        }
        found.push_back({a, b, arc_a, arc_b, p, kind, p});
      };
      // Crossings.
      for (std::size_t i = 0; i + 1 < pa.points.size(); ++i) {
        const Vec2 lo = pa.points[i].cwiseMin(pa.points[i + 1]);
        const Vec2 hi = pa.points[i].cwiseMax(pa.points[i + 1]);
        for (std::size_t k = 0; k + 1 < pb.points.size(); ++k) {
          const Vec2 lo2 = pb.points[k].cwiseMin(pb.points[k + 1]);
          const Vec2 hi2 = pb.points[k].cwiseMax(pb.points[k + 1]);
          if (lo2.x() > hi.x() || hi2.x() < lo.x() || lo2.y() > hi.y() || hi2.y() < lo.y()) continue;
          double u = 0, v = 0;
          if (!intersect(pa.points[i], pa.points[i + 1], pb.points[k], pb.points[k + 1], u, v)) continue;
          const double arc_a = pa.s[i] + u * (pa.s[i + 1] - pa.s[i]);
          const double arc_b = pb.s[k] + v * (pb.s[k + 1] - pb.s[k]);
          const bool end_a = arc_a < 1.0 || arc_a > pa.length() - 1.0;
          const bool end_b = arc_b < 1.0 || arc_b > pb.length() - 1.0;
          add(arc_a, arc_b, end_a && end_b ? JunctionKind::l : (end_a || end_b) ? JunctionKind::t : JunctionKind::x);
        }
      }
      // Ends that touch the other trail without crossing it.
      auto touch = [&](const Polyline& from, const Polyline& onto, bool from_is_a) {
        for (double arc_end : {0.0, from.length()}) {
          const Vec2 e = from.at(arc_end);
          const auto pr = onto.project(e);
          if (pr.distance > 1.0) continue;
          const bool end_onto = pr.arc < 1.0 || pr.arc > onto.length() - 1.0;
          const JunctionKind kind = end_onto ? JunctionKind::l : JunctionKind::t;
          if (from_is_a) add(arc_end, pr.arc, kind);
          else add(pr.arc, arc_end, kind);
        }
      };
      touch(pa, pb, true);
      touch(pb, pa, false);
      for (Junction& j : found) net.junctions.push_back(j);
    }
  }
}

const Junction* junction_between(const RoadNetwork& net, int a, int b) {
  for (const Junction& j : net.junctions) {
    if ((j.a == a && j.b == b) || (j.a == b && j.b == a)) return &j;
  }
  return nullptr;
}

double arc_on(const Junction& j, int trail) { return j.a == trail ? j.arc_a : j.arc_b; }

int trail_index(const Scenario& s, const std::string& name) {
  for (std::size_t i = 0; i < s.trails.size(); ++i) {
    if (s.trails[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

void append_piece(std::vector<Vec2>& out, const Polyline& line, double from, double to) {
  const double step = 0.2;
  const double len = std::abs(to - from);
  const int n = std::max(1, static_cast<int>(std::ceil(len / step)));
  for (int i = out.empty() ? 0 : 1; i <= n; ++i) out.push_back(line.at(from + (to - from) * static_cast<double>(i) / n));
}

// Lateral map error of trail `t` at arc length `arc` (metres, left positive).
double osm_offset(const TrailGeometry& t, double arc, std::uint64_t key) {
  const TrailOsm& o = t.spec->osm;
  const double f = t.centre.length() > 0 ? arc / t.centre.length() : 0.0;
  return o.offset_start + (o.offset_end - o.offset_start) * f + o.wander * value_noise(key, arc, 0.0, 40.0);
}

void build_osm(RoadNetwork& net, const Scenario& s, std::uint64_t seed) {
  // Mapped junction positions.
  for (Junction& j : net.junctions) {
    const std::string& name_a = net.trails[static_cast<std::size_t>(j.a)].spec->name;
    const std::string& name_b = net.trails[static_cast<std::size_t>(j.b)].spec->name;
    int along = j.a;
    double shift = 0.0;
    for (const JunctionError& e : s.junction_errors) {
      if ((e.a == name_a && e.b == name_b) || (e.a == name_b && e.b == name_a)) {
        along = e.a == name_a ? j.a : j.b;
        shift = e.shift;
      }
    }
    const TrailGeometry& t = net.trails[static_cast<std::size_t>(along)];
    const double arc = std::clamp(arc_on(j, along) + shift, 0.0, t.centre.length());
    const std::uint64_t key = hash(seed, 0x05A1, static_cast<std::uint64_t>(along));
    j.mapped = t.centre.at(arc) + t.centre.normal(arc) * osm_offset(t, arc, key) + s.osm_offset;
  }
  std::int64_t next_node = 1;
  std::vector<std::int64_t> junction_node(net.junctions.size(), 0);
  for (std::size_t ti = 0; ti < net.trails.size(); ++ti) {
    const TrailGeometry& t = net.trails[ti];
    const double len = t.centre.length();
    const std::uint64_t key = hash(seed, 0x05A1, ti);
    // Stations: regular sparse nodes, and the junctions on this trail.
    std::vector<std::pair<double, int>> stations;  // arc, junction index or -1
    for (std::size_t j = 0; j < net.junctions.size(); ++j) {
      const Junction& jn = net.junctions[j];
      if (jn.a == static_cast<int>(ti) || jn.b == static_cast<int>(ti)) {
        stations.emplace_back(arc_on(jn, static_cast<int>(ti)), static_cast<int>(j));
      }
    }
    const double spacing = t.spec->osm.spacing;
    const int n = std::max(1, static_cast<int>(std::round(len / spacing)));
    for (int k = 0; k <= n; ++k) {
      const double arc = len * k / n;
      bool near_junction = false;
      for (const auto& [a, j] : stations) {
        if (j >= 0 && std::abs(a - arc) < 0.35 * spacing) near_junction = true;
      }
      if (!near_junction) stations.emplace_back(arc, -1);
    }
    std::sort(stations.begin(), stations.end());
    OsmWay way;
    way.trail = static_cast<int>(ti);
    for (const auto& [arc, j] : stations) {
      if (j >= 0) {
        auto& id = junction_node[static_cast<std::size_t>(j)];
        if (id == 0) id = next_node++;
        way.nodes.push_back(id);
        way.points.push_back(net.junctions[static_cast<std::size_t>(j)].mapped);
        continue;
      }
      // Digitising noise on top of the systematic offset.
      const Vec2 jitter{0.3 * gaussian(hash(key, 1, static_cast<std::uint64_t>(next_node))),
                        0.3 * gaussian(hash(key, 2, static_cast<std::uint64_t>(next_node)))};
      way.nodes.push_back(next_node++);
      way.points.push_back(t.centre.at(arc) + t.centre.normal(arc) * osm_offset(t, arc, key) + s.osm_offset + jitter);
    }
    net.osm.push_back(std::move(way));
  }
}

}  // namespace

GeoFrame::GeoFrame(double origin_lat, double origin_lon) {
  double k = 0.0;
  GeographicLib::UTMUPS::Forward(origin_lat, origin_lon, zone_, north_, easting0_, northing0_, convergence_, k);
  convergence_ *= std::numbers::pi / 180.0;
}

void GeoFrame::to_latlon(double x, double y, double& lat, double& lon) const {
  GeographicLib::UTMUPS::Reverse(zone_, north_, easting0_ + x, northing0_ + y, lat, lon);
}

Vec2 GeoFrame::from_latlon(double lat, double lon) const {
  int zone = 0;
  bool north = true;
  double e = 0, n = 0;
  GeographicLib::UTMUPS::Forward(lat, lon, zone, north, e, n, zone_);
  return {e - easting0_, n - northing0_};
}

Polyline::Polyline(std::vector<Vec2> pts) : points(std::move(pts)) {
  s.resize(points.size(), 0.0);
  for (std::size_t i = 1; i < points.size(); ++i) s[i] = s[i - 1] + (points[i] - points[i - 1]).norm();
}

Vec2 Polyline::at(double arc) const noexcept {
  if (points.empty()) return {0, 0};
  if (arc <= 0.0) return points.front();
  if (arc >= length()) return points.back();
  const auto it = std::upper_bound(s.begin(), s.end(), arc);
  const auto i = static_cast<std::size_t>(it - s.begin());
  const double seg = s[i] - s[i - 1];
  const double f = seg > 0 ? (arc - s[i - 1]) / seg : 0.0;
  return points[i - 1] + (points[i] - points[i - 1]) * f;
}

Vec2 Polyline::tangent(double arc) const noexcept {
  if (points.size() < 2) return {1, 0};
  const double a = std::clamp(arc, 0.0, length());
  auto it = std::upper_bound(s.begin(), s.end(), a);
  auto i = static_cast<std::size_t>(it - s.begin());
  i = std::clamp<std::size_t>(i, 1, points.size() - 1);
  const Vec2 d = points[i] - points[i - 1];
  const double n = d.norm();
  return n > 0 ? Vec2(d / n) : Vec2(1, 0);
}

Polyline::Projection Polyline::project(const Vec2& p) const noexcept {
  Projection best;
  best.distance = 1e300;
  for (std::size_t i = 0; i + 1 < points.size(); ++i) {
    const Vec2 d = points[i + 1] - points[i];
    const double l2 = d.squaredNorm();
    const double u = l2 > 0 ? std::clamp((p - points[i]).dot(d) / l2, 0.0, 1.0) : 0.0;
    const Vec2 q = points[i] + d * u;
    const double dist = (p - q).norm();
    if (dist < best.distance) best = {s[i] + u * (s[i + 1] - s[i]), dist, q};
  }
  if (points.size() == 1) best = {0.0, (p - points[0]).norm(), points[0]};
  return best;
}

RoadsResult build_roads(const Scenario& s, std::uint64_t seed) {
  RoadNetwork net;
  for (const Trail& t : s.trails) net.trails.push_back({&t, Polyline(spline(t.points))});
  find_junctions(net);

  // The route: each leg's trail from where the previous leg left it to where
  // the next leg joins it.
  std::vector<Vec2> path;
  for (std::size_t i = 0; i < s.route.size(); ++i) {
    const int ti = trail_index(s, s.route[i].trail);
    const Polyline& line = net.trails[static_cast<std::size_t>(ti)].centre;
    double from = s.route[i].reverse ? line.length() : 0.0;
    double to = s.route[i].reverse ? 0.0 : line.length();
    if (i > 0) {
      const int prev = trail_index(s, s.route[i - 1].trail);
      const Junction* j = junction_between(net, prev, ti);
      if (!j) return {std::nullopt, s.source + ": route: trails '" + s.route[i - 1].trail + "' and '" + s.route[i].trail +
                                        "' do not meet, so the route cannot turn from one to the other"};
      from = arc_on(*j, ti);
    }
    if (i + 1 < s.route.size()) {
      const int next = trail_index(s, s.route[i + 1].trail);
      const Junction* j = junction_between(net, ti, next);
      if (!j) return {std::nullopt, s.source + ": route: trails '" + s.route[i].trail + "' and '" + s.route[i + 1].trail +
                                        "' do not meet, so the route cannot turn from one to the other"};
      // Towards the junction (the first leg from the end `reverse` names).
      to = arc_on(*j, ti);
    } else if (i > 0) {
      // Last leg: away from the junction, towards the end given by `reverse`
      // (default: the farther end).
      if (!s.route[i].reverse && from > line.length() - 1.0) to = 0.0;
    }
    append_piece(path, line, from, to);
  }
  net.route = Polyline(std::move(path));
  if (net.route.length() < 2.0) return {std::nullopt, s.source + ": route: the route is shorter than 2 m"};
  build_osm(net, s, seed);
  return {std::move(net), ""};
}

Status write_osm(const std::string& path, const RoadNetwork& roads, const Scenario& s, const GeoFrame& geo) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) return Status::error("cannot write " + path);
  double minlat = 90, maxlat = -90, minlon = 180, maxlon = -180;
  std::map<std::int64_t, std::pair<double, double>> nodes;
  for (const OsmWay& w : roads.osm) {
    for (std::size_t i = 0; i < w.nodes.size(); ++i) {
      double lat = 0, lon = 0;
      geo.to_latlon(w.points[i].x(), w.points[i].y(), lat, lon);
      nodes[w.nodes[i]] = {lat, lon};
      minlat = std::min(minlat, lat);
      maxlat = std::max(maxlat, lat);
      minlon = std::min(minlon, lon);
      maxlon = std::max(maxlon, lon);
    }
  }
  std::fprintf(f, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
  std::fprintf(f, "<osm version=\"0.6\" generator=\"trailnav sim (scenario %s)\">\n", s.name.c_str());
  std::fprintf(f, "  <bounds minlat=\"%.7f\" minlon=\"%.7f\" maxlat=\"%.7f\" maxlon=\"%.7f\"/>\n", minlat, minlon, maxlat,
               maxlon);
  for (const auto& [id, ll] : nodes) {
    std::fprintf(f, "  <node id=\"%lld\" version=\"1\" timestamp=\"2026-01-01T00:00:00Z\" lat=\"%.7f\" lon=\"%.7f\"/>\n",
                 static_cast<long long>(id), ll.first, ll.second);
  }
  std::int64_t way_id = 1;
  for (const OsmWay& w : roads.osm) {
    const TrailOsm& o = roads.trails[static_cast<std::size_t>(w.trail)].spec->osm;
    std::fprintf(f, "  <way id=\"%lld\" version=\"1\" timestamp=\"2026-01-01T00:00:00Z\">\n", static_cast<long long>(way_id++));
    for (std::int64_t id : w.nodes) std::fprintf(f, "    <nd ref=\"%lld\"/>\n", static_cast<long long>(id));
    std::fprintf(f, "    <tag k=\"highway\" v=\"%s\"/>\n", o.highway.c_str());
    if (!o.surface.empty()) std::fprintf(f, "    <tag k=\"surface\" v=\"%s\"/>\n", o.surface.c_str());
    if (!o.tracktype.empty()) std::fprintf(f, "    <tag k=\"tracktype\" v=\"%s\"/>\n", o.tracktype.c_str());
    if (!o.name.empty()) std::fprintf(f, "    <tag k=\"name\" v=\"%s\"/>\n", o.name.c_str());
    std::fprintf(f, "  </way>\n");
  }
  std::fprintf(f, "</osm>\n");
  if (std::fclose(f) != 0) return Status::error("cannot write " + path);
  return Status::ok();
}

}  // namespace trailnav::sim
