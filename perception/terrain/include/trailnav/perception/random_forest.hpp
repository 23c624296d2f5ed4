// A random forest (Breiman) for the terrain classes: inference on flat
// arrays, no allocation, and a versioned, checksummed model file.
//
// Layout: every tree is a run of nodes in pre-order, so an inner node's left
// child is the next node and only the right child needs an index. A leaf
// points at a row of class probabilities. One node is 12 bytes; a walk from
// root to leaf touches one cache line per level at most.
//
// Model file (little-endian; docs/terrain.md):
//   "TNTERRF\0"  magic (8 bytes)
//   u32 version (4; 3 is read too, without the feature settings; 1 and 2,
//               five-feature forests, are refused by name),
//   u32 features (6), u32 classes (5)
//   u32 trees, u32 nodes, u32 leaves
//   16 bytes: the lidar model the forest was trained for ("VLP-16",
//             "HDL-64E", ...), ASCII, NUL-padded; all NUL: not said
//   (version 4) the cells whose features it learnt: f32 map resolution (m),
//             u32 min_points, f32 min_range (m), f32 max_range (m); all 0:
//             not said (a forest trained from CSV files alone)
//   trees  x u32 first node of each tree
//   nodes  x { i16 feature (-1: leaf), u16 0, f32 threshold, i32 right child or leaf row }
//   leaves x classes x f32 probability
//   u32 CRC-32 (zlib's) of everything before it
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "trailnav/perception/terrain_class_map.hpp"
#include "trailnav/perception/terrain_features.hpp"
#include "trailnav/runtime/status.hpp"

namespace trailnav::perception {

struct ForestNode {
  std::int16_t feature = -1;  // < 0: leaf
  std::uint16_t reserved = 0;
  float threshold = 0.0f;     // feature <= threshold: left (the next node); else right
  std::int32_t next = 0;      // inner: the right child's node index; leaf: its row in the leaf table
};
static_assert(sizeof(ForestNode) == 12);

using ClassDistribution = std::array<float, kTerrainClasses>;

// What shaped the features a forest learnt: the terrain settings of its
// training (TerrainConfig's map resolution, min_points, min_range and
// max_range). The same ground gives other features in cells of another size,
// from fewer points or from farther away, where the lidar sees it at a
// grazing angle; a forest used with other settings answers other questions.
struct FeatureSettings {
  float resolution = 0.0f;  // m; 0: not said
  std::uint32_t min_points = 0;
  float min_range = 0.0f;  // m
  float max_range = 0.0f;  // m
  bool said() const noexcept { return resolution > 0.0f; }
  friend bool operator==(const FeatureSettings&, const FeatureSettings&) = default;
};

class RandomForest {
 public:
  // 4: the feature settings after the lidar. 3: six features
  // (area_std_remission), read as a forest that does not say its settings.
  // 1 and 2 held forests of the five per-cell features, which this build
  // cannot use; loading says so.
  static constexpr std::uint32_t kVersion = 4;
  static constexpr std::size_t kLidarBytes = 16;  // the lidar field, NUL-padded
  static constexpr std::size_t kSettingsBytes = 16;  // version 4: the feature settings

  struct Loaded;
  // Reads and validates a model file.
  static Loaded load(const std::string& path);
  // Validates a model file's bytes; `name` prefixes the error (a path).
  static Loaded parse(std::span<const std::uint8_t> data, const std::string& name);
  // Validates parts (as training produces them); the error names the first problem.
  static Loaded from_parts(std::vector<std::uint32_t> roots, std::vector<ForestNode> nodes, std::vector<float> leaves);

  Status save(const std::string& path) const;

  // P(t | f): the mean of the trees' leaf distributions.
  void predict(const FeatureVector& f, ClassDistribution& out) const noexcept {
    out.fill(0.0f);
    for (std::size_t t = 0; t < roots_.size(); ++t) {
      const float* p = tree_leaf(t, f);
      for (int c = 0; c < kTerrainClasses; ++c) out[static_cast<std::size_t>(c)] += p[c];
    }
    const float inv = 1.0f / static_cast<float>(roots_.size());
    for (float& v : out) v *= inv;
  }
  // One tree's leaf distribution.
  const float* tree_leaf(std::size_t tree, const FeatureVector& f) const noexcept {
    const WalkNode* nodes = walk_.data();
    const WalkNode* n = nodes + roots_[tree];
    std::uint32_t word = n->word;
    while ((word & kLeafCode) != kLeafCode) {
      n = f[word & kLeafCode] <= n->threshold ? n + 1 : nodes + (word >> 3);
      word = n->word;
    }
    return leaves_.data() + static_cast<std::size_t>(word >> 3) * kTerrainClasses;
  }

  std::size_t trees() const noexcept { return roots_.size(); }
  std::size_t nodes() const noexcept { return walk_.size(); }
  std::size_t leaves() const noexcept { return leaves_.size() / kTerrainClasses; }
  std::size_t max_depth() const noexcept { return max_depth_; }
  // The lidar model the forest was trained for (its remissions are that
  // sensor's); empty: not said (mixed training data).
  const std::string& lidar() const noexcept { return lidar_; }
  // Empty when `name` (printable ASCII, at most 15 characters) was taken,
  // else what is wrong with it.
  std::string set_lidar(std::string_view name);
  // The cells whose features the forest learnt (not said: said() false).
  const FeatureSettings& feature_settings() const noexcept { return settings_; }
  // Empty when taken (all zero, or plausible values), else what is wrong.
  std::string set_feature_settings(const FeatureSettings& s);
  std::span<const std::uint32_t> roots() const noexcept { return roots_; }
  // The nodes as the file stores them (rebuilt from the walking table).
  std::vector<ForestNode> node_table() const;
  std::span<const float> leaf_table() const noexcept { return leaves_; }

 private:
  RandomForest() = default;
  std::vector<std::uint32_t> roots_;
  // The nodes as inference walks them, 8 bytes each so the whole forest
  // stays in a core's cache while the grid streams past: the threshold, and
  // the feature (low 3 bits; kLeafCode for a leaf) with the right child's
  // index or the leaf's row above them. The only copy of the nodes:
  // node_table() and save() rebuild the file's 12-byte form from it.
  struct WalkNode {
    float threshold;
    std::uint32_t word;
  };
  static constexpr std::uint32_t kLeafCode = 7;
  std::vector<WalkNode> walk_;
  std::vector<float> leaves_;
  std::size_t max_depth_ = 0;
  std::string lidar_;
  FeatureSettings settings_;
};

// Empty when `forest` may classify the returns of a `lidar` (a model name as
// velodyne::Model spells it): the forest does not say its lidar, or says the
// same one (case-insensitive). Else the error to show, naming both.
std::string check_forest_lidar(const RandomForest& forest, std::string_view lidar, const std::string& model_path);

struct RandomForest::Loaded {
  std::optional<RandomForest> forest;
  std::string error;
};

}  // namespace trailnav::perception
