#include "scenario.hpp"

#include <cmath>
#include <ctime>
#include <fstream>
#include <numbers>
#include <sstream>

#include "sim_builtin.hpp"
#include "trailnav/runtime/config.hpp"

namespace trailnav::sim {
namespace {

constexpr double kBig = 1e6;
constexpr double kDeg = std::numbers::pi / 180.0;

std::vector<Vec2> read_points(const ConfigNode& node, std::string_view key, std::size_t min_points) {
  std::vector<Vec2> out;
  for (const auto& row : node.number_rows(key, 2, -kBig, kBig)) out.emplace_back(row[0], row[1]);
  if (out.size() < min_points) {
    node.fail(key, "needs at least " + std::to_string(min_points) + " points, has " + std::to_string(out.size()));
  }
  return out;
}

Vec2 read_point(const ConfigNode& node, std::string_view key) {
  const auto v = node.number_list(key, -kBig, kBig);
  if (v.size() != 2) node.fail(key, "expected [x, y] in metres");
  return {v[0], v[1]};
}

TerrainClass read_class(const ConfigNode& node, std::string_view key, const std::string& fallback) {
  const std::string name = node.choice(key, {"street", "dirt", "grass", "vegetation", "other"}, fallback);
  return *parse_terrain_class(name);
}

Medium read_medium(const ConfigNode& node, const Medium& fallback) {
  Medium m = fallback;
  if (node.has("height")) {
    const auto h = node.number_list("height", 0.0, 5.0);
    if (h.size() != 2 || h[0] > h[1]) node.fail("height", "expected [min, max] in metres, min <= max");
    m.height_min = h[0];
    m.height_max = h[1];
  }
  m.density = node.number("density", 0.0, 200.0, m.density);
  m.clump_size = node.number("clump_size", 0.05, 50.0, m.clump_size);
  m.cover = node.number("cover", 0.0, 1.0, m.cover);
  return m;
}

// Grass and bushes get a medium unless the scenario says otherwise.
Medium default_medium(TerrainClass c) {
  Medium m;
  if (c == TerrainClass::grass) {
    m.height_min = 0.05;
    m.height_max = 0.3;
    m.density = 12.0;
    m.clump_size = 0.7;
    m.cover = 0.9;
  } else if (c == TerrainClass::vegetation) {
    m.height_min = 0.6;
    m.height_max = 1.6;
    m.density = 10.0;
    m.clump_size = 1.5;
    m.cover = 0.95;
  }
  return m;
}

std::array<Material, kTerrainClasses> default_materials() {
  // Remission overlaps as the thesis reports (§7.2.4): dirt and grass are
  // close, streets are bright but often carry dirt.
  std::array<Material, kTerrainClasses> m{};
  m[0] = {52.0, 9.0, 0.004};   // street
  m[1] = {34.0, 9.0, 0.02};    // dirt
  m[2] = {28.0, 10.0, 0.025};  // grass (ground under the blades; blades drawn the same)
  m[3] = {20.0, 9.0, 0.03};    // vegetation
  m[4] = {40.0, 14.0, 0.015};  // other
  return m;
}

void read_obstacle(const ConfigNode& o, Scenario& s) {
  Obstacle ob;
  const std::string type = o.choice("type", {"box", "pole", "wall", "tree", "bush", "ditch"});
  ob.name = o.string("name", "");
  ob.remission = o.number("remission", 0.0, 255.0, 40.0);
  if (type == "box") {
    ob.type = ObstacleType::box;
    ob.center = read_point(o, "center");
    const auto size = o.number_list("size", 0.01, 100.0);
    if (size.size() != 3) o.fail("size", "expected [length, width, height] in metres");
    ob.size = {size[0], size[1], size[2]};
    ob.yaw = o.number("yaw", -360.0, 360.0, 0.0) * kDeg;
  } else if (type == "pole") {
    ob.type = ObstacleType::pole;
    ob.center = read_point(o, "center");
    ob.radius = o.number("radius", 0.01, 5.0, 0.05);
    ob.height = o.number("height", 0.1, 50.0, 3.0);
  } else if (type == "wall") {
    ob.type = ObstacleType::wall;
    ob.points = {read_point(o, "from"), read_point(o, "to")};
    if ((ob.points[1] - ob.points[0]).norm() < 0.05) o.fail("to", "a wall needs two distinct end points");
    ob.thickness = o.number("thickness", 0.02, 10.0, 0.2);
    ob.height = o.number("height", 0.1, 20.0, 2.0);
  } else if (type == "tree") {
    ob.type = ObstacleType::tree;
    ob.center = read_point(o, "center");
    ob.radius = o.number("trunk_radius", 0.02, 3.0, 0.2);
    ob.height = o.number("height", 1.0, 60.0, 10.0);
    ob.canopy_radius = o.number("canopy_radius", 0.0, 20.0, 3.0);
    ob.canopy_base = o.number("canopy_base", 0.0, 50.0, 3.0);
    if (ob.canopy_base >= ob.height) o.fail("canopy_base", "must be below the tree's height");
    ob.remission = o.number("remission", 0.0, 255.0, 25.0);
  } else if (type == "bush") {
    ob.type = ObstacleType::bush;
    ob.center = read_point(o, "center");
    ob.radius = o.number("radius", 0.1, 20.0, 1.0);
    ob.height = o.number("height", 0.1, 10.0, 1.2);
    ob.remission = o.number("remission", 0.0, 255.0, 20.0);
  } else {
    ob.type = ObstacleType::ditch;
    ob.points = read_points(o, "points", 2);
    ob.width = o.number("width", 0.1, 20.0, 1.0);
    ob.depth = o.number("depth", 0.02, 5.0, 0.4);
  }
  o.reject_unknown_keys();
  s.obstacles.push_back(std::move(ob));
}

Scenario read(const ConfigNode& root, const std::string& text, const std::string& source) {
  Scenario s;
  s.source = source;
  s.text = text;
  s.materials = default_materials();
  if (root.string("format") != "trailnav-scenario") root.fail("format", "must be 'trailnav-scenario'");
  root.integer("version", 1, 1);
  s.name = root.string("name");
  s.description = root.string("description", "");
  const ConfigNode origin = root.map("origin");
  s.origin_lat = origin.number("lat", -80.0, 84.0);
  s.origin_lon = origin.number("lon", -180.0, 180.0);
  s.origin_alt = origin.number("alt", -500.0, 9000.0, 300.0);
  origin.reject_unknown_keys();
  const std::string start = root.string("start_utc", "2026-06-21T10:00:00Z");
  const auto start_ns = parse_utc(start);
  if (!start_ns) root.fail("start_utc", "expected a UTC time like 2026-06-21T10:00:00Z");
  s.start_utc_ns = *start_ns;
  s.duration = root.number("duration", 0.0, 36000.0, 0.0);
  if (root.has("estop")) {
    for (const ConfigNode& e : root.map_list("estop")) {
      EstopPress p;
      p.at = e.number("at", 0.0, 36000.0);
      p.hold = e.number("hold", 0.01, 600.0, p.hold);
      if (!s.estop.empty() && p.at <= s.estop.back().at + s.estop.back().hold + 0.05) {
        e.fail("at", "presses must come in time order, at least 50 ms after the previous release");
      }
      e.reject_unknown_keys();
      s.estop.push_back(p);
    }
  }

  const ConfigNode world = root.map("world");
  const auto extent = world.number_list("extent", -kBig, kBig);
  if (extent.size() != 4 || extent[0] >= extent[2] || extent[1] >= extent[3]) {
    world.fail("extent", "expected [xmin, ymin, xmax, ymax] in metres with min < max");
  }
  s.world.xmin = extent[0];
  s.world.ymin = extent[1];
  s.world.xmax = extent[2];
  s.world.ymax = extent[3];
  s.world.resolution = world.number("resolution", 0.02, 1.0, 0.1);
  const double cells = (s.world.xmax - s.world.xmin) * (s.world.ymax - s.world.ymin) /
                       (s.world.resolution * s.world.resolution);
  if (cells > 40e6) world.fail("extent", "the world has " + std::to_string(static_cast<long>(cells)) +
                                             " cells at this resolution; at most 40 million are allowed");
  s.world.background = read_class(world, "background", "grass");
  s.world.background_medium = default_medium(s.world.background);
  if (auto m = world.optional_map("background_medium")) {
    s.world.background_medium = read_medium(*m, s.world.background_medium);
    m->reject_unknown_keys();
  }
  if (world.has("slope")) {
    const auto slope = world.number_list("slope", -1.0, 1.0);
    if (slope.size() != 2) world.fail("slope", "expected [east, north] rise per metre");
    s.world.slope = {slope[0], slope[1]};
  }
  s.world.hill_amplitude = world.number("hill_amplitude", 0.0, 50.0, 0.0);
  s.world.hill_wavelength = world.number("hill_wavelength", 2.0, 5000.0, 40.0);
  s.world.street_dirt = world.number("street_dirt", 0.0, 1.0, 0.1);
  world.reject_unknown_keys();

  if (auto materials = root.optional_map("materials")) {
    for (int c = 0; c < kTerrainClasses; ++c) {
      const char* name = terrain_class_name(static_cast<TerrainClass>(c));
      if (auto m = materials->optional_map(name)) {
        Material& mat = s.materials[static_cast<std::size_t>(c)];
        mat.remission_mean = m->number("remission_mean", 0.0, 255.0, mat.remission_mean);
        mat.remission_std = m->number("remission_std", 0.0, 100.0, mat.remission_std);
        mat.roughness = m->number("roughness", 0.0, 0.5, mat.roughness);
        m->reject_unknown_keys();
      }
    }
    materials->reject_unknown_keys();
  }

  for (const ConfigNode& r : root.optional_map_list("regions")) {
    Region region;
    region.terrain = read_class(r, "class", "grass");
    region.polygon = read_points(r, "polygon", 3);
    region.medium = read_medium(r, default_medium(region.terrain));
    r.reject_unknown_keys();
    s.regions.push_back(std::move(region));
  }

  for (const ConfigNode& t : root.map_list("trails")) {
    Trail trail;
    trail.line = t.line();
    trail.name = t.string("name");
    if (s.trail(trail.name)) t.fail("name", "trail '" + trail.name + "' is defined twice");
    trail.terrain = read_class(t, "class", "dirt");
    trail.width = t.number("width", 0.5, 30.0, 3.0);
    trail.curb = t.number("curb", 0.0, 0.5, 0.0);
    trail.points = read_points(t, "points", 2);
    if (auto m = t.optional_map("medium")) {
      trail.medium = read_medium(*m, Medium{});
      m->reject_unknown_keys();
    }
    if (auto osm = t.optional_map("osm")) {
      trail.osm.highway = osm->choice("highway", {"track", "path", "unclassified", "residential", "service",
                                                  "footway", "cycleway", "tertiary"}, "track");
      trail.osm.surface = osm->string("surface", "");
      trail.osm.tracktype = osm->choice("tracktype", {"", "grade1", "grade2", "grade3", "grade4", "grade5"}, "");
      trail.osm.name = osm->string("name", "");
      if (osm->has("offset")) {
        const auto off = osm->number_list("offset", -100.0, 100.0);
        if (off.size() != 2) osm->fail("offset", "expected [at start, at end] in metres (left of the trail positive)");
        trail.osm.offset_start = off[0];
        trail.osm.offset_end = off[1];
      }
      trail.osm.wander = osm->number("wander", 0.0, 20.0, 0.5);
      trail.osm.spacing = osm->number("spacing", 1.0, 500.0, 25.0);
      osm->reject_unknown_keys();
    }
    t.reject_unknown_keys();
    s.trails.push_back(std::move(trail));
  }

  for (const ConfigNode& o : root.optional_map_list("obstacles")) read_obstacle(o, s);

  if (auto osm = root.optional_map("osm")) {
    if (osm->has("offset")) s.osm_offset = read_point(*osm, "offset");
    for (const ConfigNode& j : osm->optional_map_list("junctions")) {
      JunctionError e;
      e.a = j.string("along");
      e.b = j.string("branch");
      if (!s.trail(e.a)) j.fail("along", "no trail named '" + e.a + "'");
      if (!s.trail(e.b)) j.fail("branch", "no trail named '" + e.b + "'");
      e.shift = j.number("shift", -100.0, 100.0);
      j.reject_unknown_keys();
      s.junction_errors.push_back(e);
    }
    osm->reject_unknown_keys();
  }

  for (const ConfigNode& leg : root.map_list("route")) {
    RouteLeg l;
    l.trail = leg.string("trail");
    if (!s.trail(l.trail)) leg.fail("trail", "no trail named '" + l.trail + "'");
    l.reverse = leg.boolean("reverse", false);
    leg.reject_unknown_keys();
    s.route.push_back(l);
  }
  if (s.route.empty()) root.fail("route", "the route needs at least one leg");

  if (auto robot = root.optional_map("robot")) {
    RobotSpec& r = s.robot;
    r.max_speed = robot->number("max_speed", 0.1, 1.2, r.max_speed);
    r.acceleration = robot->number("acceleration", 0.05, 3.0, r.acceleration);
    r.lateral_acceleration = robot->number("lateral_acceleration", 0.05, 3.0, r.lateral_acceleration);
    r.wheelbase = robot->number("wheelbase", 0.2, 5.0, r.wheelbase);
    r.track = robot->number("track", 0.2, 3.0, r.track);
    r.lookahead = robot->number("lookahead", 0.5, 10.0, r.lookahead);
    r.start_offset = robot->number("start_offset", 0.0, 10000.0, r.start_offset);
    auto vec3 = [&](std::string_view key, Vec3& v) {
      if (!robot->has(key)) return;
      const auto x = robot->number_list(key, -10.0, 10.0);
      if (x.size() != 3) robot->fail(key, "expected [x, y, z] in metres in the robot frame");
      v = {x[0], x[1], x[2]};
    };
    vec3("lidar_mount", r.lidar_mount);
    vec3("gps_antenna", r.gps_antenna);
    robot->reject_unknown_keys();
  }
  if (auto sensors = root.optional_map("sensors")) {
    if (auto l = sensors->optional_map("lidar")) {
      s.lidar.model = l->string("model", s.lidar.model);
      s.lidar.calibration = l->string("calibration", "");
      s.lidar.rpm = l->number("rpm", 300.0, 1200.0, s.lidar.rpm);
      s.lidar.range_noise = l->number("range_noise", 0.0, 1.0, s.lidar.range_noise);
      s.lidar.dropout = l->number("dropout", 0.0, 0.9, s.lidar.dropout);
      s.lidar.max_range = l->number("max_range", 5.0, 200.0, s.lidar.max_range);
      l->reject_unknown_keys();
    }
    if (auto g = sensors->optional_map("gps")) {
      s.gps.rate = g->number("rate", 0.2, 20.0, s.gps.rate);
      s.gps.noise = g->number("noise", 0.0, 50.0, s.gps.noise);
      s.gps.bias_sigma = g->number("bias_sigma", 0.0, 50.0, s.gps.bias_sigma);
      s.gps.bias_time = g->number("bias_time", 1.0, 100000.0, s.gps.bias_time);
      s.gps.baud = static_cast<int>(g->integer("baud", 4800, 921600, s.gps.baud));
      g->reject_unknown_keys();
    }
    if (auto i = sensors->optional_map("imu")) {
      s.imu.rate = i->number("rate", 10.0, 400.0, s.imu.rate);
      s.imu.gyro_noise = i->number("gyro_noise", 0.0, 1.0, s.imu.gyro_noise);
      s.imu.gyro_bias = i->number("gyro_bias", 0.0, 1.0, s.imu.gyro_bias);
      s.imu.accel_noise = i->number("accel_noise", 0.0, 10.0, s.imu.accel_noise);
      s.imu.accel_bias = i->number("accel_bias", 0.0, 10.0, s.imu.accel_bias);
      s.imu.yaw_error = i->number("yaw_error", 0.0, 1.0, s.imu.yaw_error);
      i->reject_unknown_keys();
    }
    if (auto w = sensors->optional_map("wheels")) {
      s.wheels.rate = w->number("rate", 5.0, 500.0, s.wheels.rate);
      s.wheels.scale_left = w->number("scale_left", 0.5, 1.5, s.wheels.scale_left);
      s.wheels.scale_right = w->number("scale_right", 0.5, 1.5, s.wheels.scale_right);
      s.wheels.slip = w->number("slip", 0.0, 0.5, s.wheels.slip);
      s.wheels.ticks_per_metre = w->number("ticks_per_metre", 1.0, 1e6, s.wheels.ticks_per_metre);
      w->reject_unknown_keys();
    }
    sensors->reject_unknown_keys();
  }
  root.reject_unknown_keys();
  return s;
}

}  // namespace

const char* terrain_class_name(TerrainClass c) noexcept {
  switch (c) {
    case TerrainClass::street: return "street";
    case TerrainClass::dirt: return "dirt";
    case TerrainClass::grass: return "grass";
    case TerrainClass::vegetation: return "vegetation";
    case TerrainClass::other: return "other";
  }
  return "?";
}

std::optional<TerrainClass> parse_terrain_class(std::string_view text) noexcept {
  for (int c = 0; c < kTerrainClasses; ++c) {
    if (text == terrain_class_name(static_cast<TerrainClass>(c))) return static_cast<TerrainClass>(c);
  }
  return std::nullopt;
}

const Trail* Scenario::trail(std::string_view trail_name) const noexcept {
  for (const Trail& t : trails) {
    if (t.name == trail_name) return &t;
  }
  return nullptr;
}

std::optional<std::int64_t> parse_utc(std::string_view text) noexcept {
  int y = 0, mo = 0, d = 0, h = 0, mi = 0, sec = 0;
  char z = 0;
  const std::string s(text);
  if (std::sscanf(s.c_str(), "%4d-%2d-%2dT%2d:%2d:%2d%c", &y, &mo, &d, &h, &mi, &sec, &z) != 7 || z != 'Z') {
    return std::nullopt;
  }
  if (y < 1970 || y > 2100 || mo < 1 || mo > 12 || d < 1 || d > 31 || h > 23 || mi > 59 || sec > 60) return std::nullopt;
  std::tm tm{};
  tm.tm_year = y - 1900;
  tm.tm_mon = mo - 1;
  tm.tm_mday = d;
  tm.tm_hour = h;
  tm.tm_min = mi;
  tm.tm_sec = sec;
  const std::time_t t = timegm(&tm);
  return static_cast<std::int64_t>(t) * 1'000'000'000;
}

std::vector<std::string> builtin_scenario_names() {
  std::vector<std::string> names;
  for (const auto& b : kBuiltinScenarios) names.emplace_back(b.name);
  return names;
}

ScenarioResult parse_scenario(const std::string& text, const std::string& source) {
  ScenarioResult result;
  try {
    const ConfigNode root = ConfigNode::parse(text, source);
    result.scenario = read(root, text, source);
  } catch (const ConfigError& e) {
    result.error = e.what();
  }
  return result;
}

ScenarioResult load_scenario(const std::string& name_or_path) {
  for (const auto& b : kBuiltinScenarios) {
    if (name_or_path == b.name) {
      return parse_scenario(b.text, std::string("(built-in board/sim/scenarios/") + b.name + ".yaml)");
    }
  }
  std::ifstream in(name_or_path);
  if (!in) {
    std::string names;
    for (const auto& n : builtin_scenario_names()) names += (names.empty() ? "" : ", ") + n;
    return {std::nullopt, "scenario '" + name_or_path + "' is neither a built-in scenario (" + names +
                              ") nor a readable file"};
  }
  std::stringstream buffer;
  buffer << in.rdbuf();
  return parse_scenario(buffer.str(), name_or_path);
}

}  // namespace trailnav::sim
