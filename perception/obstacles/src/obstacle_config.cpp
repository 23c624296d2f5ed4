#include "trailnav/perception/obstacle_config.hpp"

#include <cctype>
#include <cstdio>

namespace trailnav::perception {

std::string_view fusion_model_name(FusionModel m) noexcept {
  switch (m) {
    case FusionModel::pw: return "PW";
    case FusionModel::ps: return "PS";
    case FusionModel::pc: return "PC";
  }
  return "?";
}

std::optional<FusionModel> parse_fusion_model(std::string_view name) noexcept {
  if (name.size() != 2 || std::toupper(static_cast<unsigned char>(name[0])) != 'P') return std::nullopt;
  switch (std::toupper(static_cast<unsigned char>(name[1]))) {
    case 'W': return FusionModel::pw;
    case 'S': return FusionModel::ps;
    case 'C': return FusionModel::pc;
    default: return std::nullopt;
  }
}

std::array<ClassParams, kTerrainClasses> default_class_params() noexcept {
  std::array<ClassParams, kTerrainClasses> p{};
  p[static_cast<int>(TerrainClass::street)] = {0.05f, 20.5f, 25.0f, 1.2f, std::nullopt};
  p[static_cast<int>(TerrainClass::dirt)] = {0.25f, 20.5f, 3.0f, 1.2f, std::nullopt};
  p[static_cast<int>(TerrainClass::grass)] = {0.50f, 20.5f, 10.0f, 1.2f, std::nullopt};
  p[static_cast<int>(TerrainClass::vegetation)] = {0.05f, 20.5f, 25.0f, 1.2f, std::nullopt};
  // Solid objects (boxes, cars, walls) are `other`: a flat top at their
  // height says nothing about whether the face below it is still there.
  p[static_cast<int>(TerrainClass::other)] = {0.05f, 20.5f, 25.0f, 1.2f, kTopHoldForever};
  return p;
}

namespace {

float number_f(const ConfigNode& n, std::string_view key, double lo, double hi, float fallback) {
  return static_cast<float>(n.number(key, lo, hi, static_cast<double>(fallback)));
}

TerrainClass class_choice(const ConfigNode& n, std::string_view key, TerrainClass fallback) {
  const std::string name = n.choice(key, {"street", "dirt", "grass", "vegetation", "other"},
                                    std::string(terrain_class_name(fallback)));
  return *parse_terrain_class(name);
}

// An optional list of exactly three numbers, e.g. [x, y, z].
void triple(const ConfigNode& n, std::string_view key, double lo, double hi, const char* meaning,
            std::array<double, 3>& out) {
  if (!n.has(key)) return;
  const auto v = n.number_list(key, lo, hi);
  if (v.size() != 3) n.fail(key, std::string("needs three numbers ") + meaning);
  out = {v[0], v[1], v[2]};
}

}  // namespace

ObstacleConfig parse_obstacle_config(const ConfigNode& node) {
  ObstacleConfig c;
  c.model = *parse_fusion_model(node.choice("model", {"PW", "PS", "PC"}, "PC"));
  if (node.has("terrain")) {
    const std::string t = node.choice("terrain", {"adaptive", "street", "dirt", "grass", "vegetation", "other"});
    if (t != "adaptive") c.fixed_class = parse_terrain_class(t);
  }
  c.unknown_class = class_choice(node, "unknown_terrain", c.unknown_class);
  c.compare_models = node.boolean("compare_models", c.compare_models);
  c.streaming = node.boolean("streaming", c.streaming);

  if (auto f = node.optional_map("features")) {
    FeatureParams& p = c.features;
    p.ring_neighbours = static_cast<int>(f->integer("ring_neighbours", 1, 32, p.ring_neighbours));
    p.cross_neighbours = static_cast<int>(f->integer("cross_neighbours", 1, 8, p.cross_neighbours));
    p.min_distance = number_f(*f, "min_distance", 0.001, 2.0, p.min_distance);
    p.smoothing_half_window = static_cast<int>(f->integer("smoothing_half_window", 0, 32, p.smoothing_half_window));
    p.smoothing_max_jump = number_f(*f, "smoothing_max_jump", 0.001, 10.0, p.smoothing_max_jump);
    p.min_range = number_f(*f, "min_range", 0.0, 50.0, p.min_range);
    p.max_range = number_f(*f, "max_range", 1.0, 300.0, p.max_range);
    p.neighbour_reach = number_f(*f, "neighbour_reach", 0.01, 1000.0, p.neighbour_reach);
    if (f->has("self_box")) {
      const std::vector<double> b = f->number_list("self_box", -50.0, 50.0);
      if (b.size() != 6) f->fail("self_box", "needs six numbers: [x_from, x_to, y_from, y_to, z_from, z_to] in metres");
      if (!(b[0] < b[1] && b[2] < b[3] && b[4] < b[5])) f->fail("self_box", "each range must go from a lower to a higher value");
      p.self_box = std::array<float, 6>{};
      for (std::size_t i = 0; i < 6; ++i) (*p.self_box)[i] = static_cast<float>(b[i]);
    }
    f->reject_unknown_keys();
  }
  if (auto g = node.optional_map("ground")) {
    GroundParams& p = c.ground;
    p.enabled = g->boolean("enabled", true);
    p.cell = number_f(*g, "cell", 0.05, 5.0, p.cell);
    p.radius = number_f(*g, "radius", 0.0, 20.0, p.radius);
    p.max_slope = number_f(*g, "max_slope", 0.0, 2.0, p.max_slope);
    p.height = number_f(*g, "height", 0.01, 10.0, p.height);
    p.raise = g->boolean("raise", p.raise);
    p.cut = g->boolean("cut", p.cut);
    if (p.radius < p.cell && p.radius > 0.0f) g->fail("radius", "must be 0 or at least one cell");
    g->reject_unknown_keys();
  }
  if (auto m = node.optional_map("map")) {
    MapParams& p = c.map;
    p.size = static_cast<int>(m->integer("size", 16, 4000, p.size));
    p.resolution = m->number("resolution", 0.01, 2.0, p.resolution);
    p.prior = number_f(*m, "prior", 0.01, 0.99, p.prior);
    p.measurement_min = number_f(*m, "measurement_min", 0.001, 0.999, p.measurement_min);
    p.measurement_max = number_f(*m, "measurement_max", 0.001, 0.999, p.measurement_max);
    p.logit_min = number_f(*m, "logit_min", -20.0, 0.0, p.logit_min);
    p.logit_max = number_f(*m, "logit_max", 0.0, 20.0, p.logit_max);
    p.dirac_hold_s = number_f(*m, "dirac_hold", 0.0, 3600.0, p.dirac_hold_s);
    p.dirac_clear_depth = number_f(*m, "dirac_clear_depth", -100.0, 100.0, p.dirac_clear_depth);
    p.dirac_top_hold_s = number_f(*m, "dirac_top_hold", 0.0, 3600.0, p.dirac_top_hold_s);
    p.occupied = number_f(*m, "occupied", 0.01, 0.99, p.occupied);
    m->reject_unknown_keys();
  }
  if (auto m = node.optional_map("mount")) {
    MountParams& p = c.mount;
    triple(*m, "translation", -10.0, 10.0, "[x, y, z] in metres", p.translation);
    triple(*m, "rotation", -180.0, 180.0, "[roll, pitch, yaw] in degrees", p.rotation_deg);
    p.fixed_roll_deg = m->number("fixed_roll", -45.0, 45.0, p.fixed_roll_deg);
    p.fixed_pitch_deg = m->number("fixed_pitch", -45.0, 45.0, p.fixed_pitch_deg);
    m->reject_unknown_keys();
  }
  if (auto cls = node.optional_map("classes")) {
    for (int t = 0; t < kTerrainClasses; ++t) {
      const auto name = terrain_class_name(static_cast<TerrainClass>(t));
      if (auto e = cls->optional_map(name)) {
        ClassParams& p = c.classes[static_cast<std::size_t>(t)];
        p.max_step_height = number_f(*e, "max_step_height", 0.0, 10.0, p.max_step_height);
        p.max_incline_deg = number_f(*e, "max_incline", 0.0, 90.0, p.max_incline_deg);
        p.alpha = number_f(*e, "alpha", 0.0, 1000.0, p.alpha);
        p.beta = number_f(*e, "beta", 0.0, 1000.0, p.beta);
        if (e->has("top_hold")) p.top_hold_s = number_f(*e, "top_hold", 0.0, kTopHoldForever, 0.0f);
        e->reject_unknown_keys();
      }
    }
    cls->reject_unknown_keys();
  }
  node.reject_unknown_keys();
  if (const std::string problem = check_obstacle_config(c); !problem.empty()) node.fail("", problem);
  return c;
}

std::string check_obstacle_config(const ObstacleConfig& c) {
  if (c.map.measurement_min >= c.map.measurement_max) return "map.measurement_min must be below map.measurement_max";
  if (c.features.min_range >= c.features.max_range) return "features.min_range must be below features.max_range";
  if (static_cast<double>(c.features.max_range) > 0.5 * c.map.size * c.map.resolution * 1.5) {
    // Points beyond the map are only counted, but a range far beyond it is a misconfiguration.
    char text[160];
    std::snprintf(text, sizeof text, "features.max_range (%.1f m) reaches far beyond the map (%.1f m each way)",
                  static_cast<double>(c.features.max_range), 0.5 * c.map.size * c.map.resolution);
    return text;
  }
  return {};
}

ObstacleConfigResult load_obstacle_config(const std::string& path) {
  try {
    const ConfigNode root = ConfigNode::load_file(path);
    ObstacleConfig c = parse_obstacle_config(root.map("obstacles"));
    return {std::move(c), {}};
  } catch (const ConfigError& e) {
    return {std::nullopt, e.what()};
  }
}

}  // namespace trailnav::perception
