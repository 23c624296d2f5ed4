// Parameters of the terrain analysis (thesis §7.2, §7.4, §8.1.2) with the
// thesis' defaults, and their YAML form (docs/terrain.md).
#pragma once

#include <array>
#include <optional>
#include <string>

#include "trailnav/perception/random_forest.hpp"
#include "trailnav/perception/terrain_class_map.hpp"
#include "trailnav/runtime/config.hpp"

namespace trailnav::perception {

struct TerrainConfig {
  TerrainMapShape map;              // 300 x 300 cells of 0.2 m
  double step_distance = 0.5;       // d, m driven between classification steps
  double max_step_interval = 2.0;   // s: a robot standing still still classifies this often (0: never)
  int min_points = 15;              // minPoints: fewer points in a cell give no feature (they keep accumulating)
  float min_range = 1.0f;           // m: nearer returns are the robot itself
  float max_range = 30.0f;          // m: farther returns are not registered (the map reaches 30 m each way)
  // Eq. 7.15 and the frozen cells of §7.2.3.
  float min_likelihood = 0.01f;     // the forest's P(t | f) is floored here before the Bayes update
  float min_probability = 1e-4f;    // a cell's class probabilities never fall below this
  int freeze_observations = 10;     // a cell seen more often than this ...
  float freeze_probability = 0.9f;  // ... whose best class is above this is classified (not updated)
  double reopen_after = 60.0;       // s: a classified cell is updated again after this (0: never)
  // Costs of the classes for the subgoal alignment (§8.1.2), indexed by TerrainClass.
  std::array<float, kTerrainClasses> cost{0.1f, 0.2f, 0.4f, 0.8f, 1.0f};
  float unknown_cost = 1.0f;        // cells not classified yet: like `other`
  std::string model;                // random-forest model file (trailnav terrain-train)
};

// Reads the `terrain:` mapping; ConfigError (file, line, key) on bad values.
// A relative model path is resolved against the config file's directory.
TerrainConfig parse_terrain_config(const ConfigNode& node);
std::string check_terrain_config(const TerrainConfig& config);

// The settings of `config` that shape a cell's features.
FeatureSettings feature_settings_of(const TerrainConfig& config) noexcept;
// Empty when `forest` learnt the features of cells as `config` makes them
// (or does not say how its cells were made); else the error to show,
// naming both.
std::string check_forest_settings(const RandomForest& forest, const TerrainConfig& config, const std::string& model_path);
// Takes the forest's settings into `config` where it says them (for the
// offline tools run without a config file).
void adopt_forest_settings(const RandomForest& forest, TerrainConfig& config) noexcept;

}  // namespace trailnav::perception
