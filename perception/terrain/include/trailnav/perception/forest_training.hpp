// Growing the terrain random forest from labelled features (offline: it
// allocates freely). CART trees with Gini impurity on bootstrap samples,
// a few random features per split (thesis §7.4: 6 trees, 2 features per
// split, at least 100 samples to split, no depth limit). Deterministic for a
// seed, whatever the number of threads.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "trailnav/perception/random_forest.hpp"

namespace trailnav::perception {

struct ForestParams {
  int trees = 6;
  int features_per_split = 2;
  int min_samples_split = 100;
  int max_depth = 0;  // 0: unlimited
  std::uint64_t seed = 1;
  int threads = 0;    // 0: one per core
};
std::string check_forest_params(const ForestParams& p);

struct LabelledFeatures {
  std::vector<FeatureVector> features;
  std::vector<std::uint8_t> labels;  // TerrainClass codes
  void add(const FeatureVector& f, TerrainClass t) {
    features.push_back(f);
    labels.push_back(static_cast<std::uint8_t>(t));
  }
  std::size_t size() const noexcept { return labels.size(); }
  void append(const LabelledFeatures& more) {
    features.insert(features.end(), more.features.begin(), more.features.end());
    labels.insert(labels.end(), more.labels.begin(), more.labels.end());
  }
  std::array<std::uint64_t, kTerrainClasses> class_counts() const noexcept;
  // Keeps at most `per_class` samples of each class, chosen at random with `seed`.
  void limit_per_class(std::size_t per_class, std::uint64_t seed);
  // The same with a cap per class (0: keep all of that class).
  void limit_per_class(const std::array<std::size_t, kTerrainClasses>& caps, std::uint64_t seed);
};

// Rows: the true class; columns: the predicted one.
struct ConfusionMatrix {
  std::array<std::array<std::uint64_t, kTerrainClasses>, kTerrainClasses> counts{};
  void add(int truth, int predicted) noexcept { ++counts[static_cast<std::size_t>(truth)][static_cast<std::size_t>(predicted)]; }
  ConfusionMatrix& operator+=(const ConfusionMatrix& other) noexcept {
    for (std::size_t t = 0; t < counts.size(); ++t) {
      for (std::size_t p = 0; p < counts[t].size(); ++p) counts[t][p] += other.counts[t][p];
    }
    return *this;
  }
  std::uint64_t row_total(int truth) const noexcept;
  std::uint64_t total() const noexcept;
  double rate(int truth, int predicted) const noexcept;  // of the row
  double recall(int truth) const noexcept { return rate(truth, truth); }
  double accuracy() const noexcept;
};
// The matrix as a table of row fractions (as the thesis' Table 7.2), classes
// without cells left out; `bracketed` adds a second matrix's value in brackets.
std::string format_confusion(const ConfusionMatrix& m, const ConfusionMatrix* bracketed = nullptr);

struct TrainedForest {
  std::optional<RandomForest> forest;
  ConfusionMatrix out_of_bag;  // each sample classified by the trees that did not see it
  std::string error;
};

// `progress` (any thread, serialised) gets the fraction of trees grown.
TrainedForest train_forest(const LabelledFeatures& data, const ForestParams& params,
                           const std::function<void(double)>& progress = {});

}  // namespace trailnav::perception
