#include "trailnav/perception/terrain_config.hpp"

#include <cstdio>
#include <filesystem>

namespace trailnav::perception {

namespace {
float number_f(const ConfigNode& n, std::string_view key, double lo, double hi, float fallback) {
  return static_cast<float>(n.number(key, lo, hi, static_cast<double>(fallback)));
}
}  // namespace

TerrainConfig parse_terrain_config(const ConfigNode& node) {
  TerrainConfig c;
  if (node.has("model")) {
    const std::string model = node.string("model");
    const std::filesystem::path p(model);
    c.model = p.is_absolute() || node.file().empty()
                  ? model
                  : (std::filesystem::path(node.file()).parent_path() / p).lexically_normal().string();
  }
  if (auto m = node.optional_map("map")) {
    const auto size = static_cast<std::int32_t>(m->integer("size", 16, 2000, c.map.size_x));
    c.map.size_x = c.map.size_y = size;
    c.map.resolution = m->number("resolution", 0.02, 2.0, c.map.resolution);
    m->reject_unknown_keys();
  }
  c.step_distance = node.number("step_distance", 0.01, 100.0, c.step_distance);
  c.max_step_interval = node.number("max_step_interval", 0.0, 3600.0, c.max_step_interval);
  c.min_points = static_cast<int>(node.integer("min_points", 3, 100000, c.min_points));
  c.min_range = number_f(node, "min_range", 0.0, 50.0, c.min_range);
  c.max_range = number_f(node, "max_range", 1.0, 300.0, c.max_range);
  c.min_likelihood = number_f(node, "min_likelihood", 1e-6, 0.2, c.min_likelihood);
  c.min_probability = number_f(node, "min_probability", 1e-9, 0.1, c.min_probability);
  if (auto f = node.optional_map("freeze")) {
    c.freeze_observations = static_cast<int>(f->integer("observations", 1, 65000, c.freeze_observations));
    c.freeze_probability = number_f(*f, "probability", 0.2, 1.0, c.freeze_probability);
    c.reopen_after = f->number("reopen_after", 0.0, 1e6, c.reopen_after);
    f->reject_unknown_keys();
  }
  if (auto k = node.optional_map("cost")) {
    for (int t = 0; t < kTerrainClasses; ++t) {
      const auto name = terrain_class_name(static_cast<TerrainClass>(t));
      c.cost[static_cast<std::size_t>(t)] = number_f(*k, name, 0.0, 1.0, c.cost[static_cast<std::size_t>(t)]);
    }
    c.unknown_cost = number_f(*k, "unknown", 0.0, 1.0, c.unknown_cost);
    k->reject_unknown_keys();
  }
  node.reject_unknown_keys();
  if (const std::string problem = check_terrain_config(c); !problem.empty()) node.fail("", problem);
  return c;
}

std::string check_terrain_config(const TerrainConfig& c) {
  if (c.min_range >= c.max_range) return "min_range must be below max_range";
  const double half = 0.5 * c.map.size_x * c.map.resolution;
  if (static_cast<double>(c.max_range) > 1.5 * half) {
    char text[160];
    std::snprintf(text, sizeof text, "max_range (%.1f m) reaches far beyond the map (%.1f m each way)",
                  static_cast<double>(c.max_range), half);
    return text;
  }
  if (c.step_distance >= half) return "step_distance must be well below the map's half size";
  return {};
}

FeatureSettings feature_settings_of(const TerrainConfig& c) noexcept {
  return {static_cast<float>(c.map.resolution), static_cast<std::uint32_t>(c.min_points), c.min_range, c.max_range};
}

std::string check_forest_settings(const RandomForest& forest, const TerrainConfig& config, const std::string& model_path) {
  const FeatureSettings& trained = forest.feature_settings();
  if (!trained.said()) return {};
  const FeatureSettings here = feature_settings_of(config);
  if (here == trained) return {};
  const auto describe = [](const FeatureSettings& s) {
    char text[160];
    std::snprintf(text, sizeof text, "cells of %g m with at least %u points, returns from %g to %g m",
                  static_cast<double>(s.resolution), s.min_points, static_cast<double>(s.min_range),
                  static_cast<double>(s.max_range));
    return std::string(text);
  };
  return model_path + ": the terrain model learnt the features of " + describe(trained) + "; this config makes " +
         describe(here) + ", whose features differ. Set terrain.map.resolution, terrain.min_points, terrain.min_range "
         "and terrain.max_range to the model's, or train a model with these (docs/terrain.md)";
}

void adopt_forest_settings(const RandomForest& forest, TerrainConfig& config) noexcept {
  const FeatureSettings& s = forest.feature_settings();
  if (!s.said()) return;
  config.map.resolution = static_cast<double>(s.resolution);
  config.min_points = static_cast<int>(s.min_points);
  config.min_range = s.min_range;
  config.max_range = s.max_range;
}

}  // namespace trailnav::perception
