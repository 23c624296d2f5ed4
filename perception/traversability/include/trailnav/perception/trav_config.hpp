// The robot config's `traversability:` section (docs/trailnavd.md): the
// learnt model the terrain thread classifies with, and the demonstration
// mode that trains it while a person drives.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "trailnav/perception/trav_learner.hpp"
#include "trailnav/perception/trav_recorder.hpp"
#include "trailnav/perception/trav_vocabulary.hpp"
#include "trailnav/runtime/config.hpp"

namespace trailnav::perception::trav {

struct TraversabilityConfig {
  std::string model;                 // .tntrav; relative paths from the config file's directory
  Method method = Method::pnb;
  // The model file's feature set the layer classifies with: `full` (six
  // dimensions, the height above the ground included) or `thesis` (its five).
  FeatureSet features = FeatureSet::full;
  double local_map_distance = 20.0;  // d_M, m: the layer's evidence restarts per local map
  double max_range = 20.0;           // m: cells farther from the robot get no word
  // Demonstration mode: the footprint's cells train the model online; it is
  // saved (atomically) to `model` after each local map and when trailnavd
  // stops, and loaded from there at the next start (a new model when the
  // file does not exist yet).
  bool demonstration = false;
  std::string profile;               // the robot profile's name, kept in the model file
  Footprint footprint;
  std::uint32_t max_words = 400000;  // words one local map holds
  VocabularyConfig vocabulary;       // a new model's (default: docs/traversability.md's bins)
  LearnerConfig learner;             // a new model's; max_models at most kLayerModels
};

// Reads the mapping; ConfigError (file, line, key) on bad values.
TraversabilityConfig parse_traversability_config(const ConfigNode& node);

// The models the layer starts with: the model file's set of `features`, or,
// in demonstration mode when the file does not exist yet, new empty models
// (`created`). Errors: an unreadable or inconsistent file, one without that
// feature set, more terrain models than the layer holds, a
// demonstration under another profile's name than the file's.
struct StartModels {
  std::unique_ptr<TravModels> models;
  bool created = false;
  std::size_t other_sets = 0;  // the file's other sets (thesis, NoRe, NoRS): a demonstration does not extend them
  std::string error;
};
StartModels load_start_models(const TraversabilityConfig& config);

}  // namespace trailnav::perception::trav
