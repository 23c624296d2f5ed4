// Traversability features of a grid cell and the vocabulary they are counted
// in (thesis §6.1–6.2).
//
// Every d_P of travel each cell with at least five points since its last
// feature gets one feature vector f = (max |Δz|, mean remission, variance of
// remission, roughness, slope): the roughness is the smallest eigenvalue of
// the points' covariance, the slope the angle between its eigenvector (the
// least-squares plane's normal) and gravity. Beyond the thesis a sixth
// dimension, the height of the cell's lowest point above the lowest ground
// seen around it (GroundReference): every other dimension is the cell's
// own, and the tops of undergrowth seen from afar — a thin level layer of
// leaves — look like the low heather a large robot was driven through
// (docs/traversability.md "The height above the ground"). A seventh, the
// depth of a cell in a valley below the valley's bank: a ditch's flat bottom
// otherwise has the words of a road. The thesis' five dimensions alone are
// the feature set `thesis`. The vector is discretised by
// bins of fixed increments per dimension; the tuple of bin indices is one
// word of the vocabulary V, a cell is a document of the words it produced
// (thesis §6.3.1: "the words are the discretized features f and the
// documents are the cells of the grid").
//
// Our choices where the thesis gives no value (docs/traversability.md):
// - The remission variance and the roughness are binned on their square
//   roots (the standard deviation of remission, 0..255, and the RMS distance
//   of the points from their plane in metres): the same information, but
//   fixed increments then spread the cells over the bins instead of putting
//   nearly all into the first.
// - Default bins: max |Δz| 0.1 m x 6, mean remission 16 x 10, remission
//   standard deviation 8 x 4, RMS plane distance 0.03 m x 3, slope 15° x 3,
//   height above the ground 0.4 m x 5, depth below it 0.1 m x 3; the last
//   bin of each dimension is open-ended. |V| = 32 400 for the full vector,
//   2 160 for the thesis' five, 810 without remission (NoRe), 3 600 without
//   roughness and slope (NoRS): the ablations of §6.4 drop those
//   dimensions from the word. Chosen
//   by measurement (docs/traversability.md): finer geometry bins left most of
//   a meadow's words unseen in a demonstration, coarser remission bins let
//   grass and dirt share words, max |Δz| must reach past half a metre to
//   tell low heather from undergrowth, the height's first bin must hold
//   the ground on a hillside (up to 0.4 m above the lowest point within
//   3 m) while undergrowth's leaves start at 0.8 m, and the depth's bins
//   must tell a ditch's shallow edge (0.1-0.2 m) from the road.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

#include "trailnav/perception/terrain_features.hpp"

namespace trailnav::perception::trav {

inline constexpr int kDims = 7;
enum class Dim : std::uint8_t {
  max_dz = 0,
  remission_mean = 1,
  remission_var = 2,
  roughness = 3,
  slope = 4,
  height = 5,
  depth = 6,
};
std::string_view dim_name(Dim d) noexcept;

// One cell's feature: max |Δz| in m, remission mean (0..255) and variance,
// roughness in m², slope in degrees (0..90), height above the ground and
// depth below it in m (one of the two is 0).
struct Feature {
  std::array<float, kDims> v{};
  float operator[](Dim d) const noexcept { return v[static_cast<std::size_t>(d)]; }
};

// Cells with fewer points get no feature (the eigenvalues would not be
// defined, thesis §6.2).
inline constexpr std::uint32_t kMinPoints = 5;
// The feature of a cell from its running sums; false with fewer than
// kMinPoints points. `terrain`: the terrain feature of the same sums, when
// the terrain step has computed it (its remission, roughness and slope are
// taken from there instead of being computed again); `above_ground`: the
// cell's height above the ground around it, negative below it
// (GroundReference::height()): the height dimension takes the positive part,
// the depth dimension the negative.
bool cell_feature(const CellStats& s, Feature& out, const FeatureVector* terrain = nullptr,
                  float above_ground = 0.0f) noexcept;

// Which dimensions make the word (thesis §6.4's ablations).
enum class FeatureSet : std::uint8_t {
  full = 0,
  no_remission = 1,        // NoRe: without the remission mean and variance
  no_roughness_slope = 2,  // NoRS: without roughness and slope
  thesis = 3,              // the thesis' five dimensions: without the height above the ground and the depth
};
inline constexpr int kFeatureSets = 4;
std::string_view feature_set_name(FeatureSet s) noexcept;  // "full", "NoRe", "NoRS", "thesis"
bool uses(FeatureSet s, Dim d) noexcept;

// Bins of `width` from 0; values below 0 fall in the first, values beyond
// the last bin's start in the last.
struct Binning {
  float width = 1.0f;
  std::uint32_t bins = 1;
  bool operator==(const Binning&) const = default;
};

struct VocabularyConfig {
  std::array<Binning, kDims> bins{{{0.1f, 6}, {16.0f, 10}, {8.0f, 4}, {0.03f, 3}, {15.0f, 3}, {0.4f, 5}, {0.1f, 3}}};
  FeatureSet set = FeatureSet::full;
  bool operator==(const VocabularyConfig&) const = default;  // the same words
};
// "" if usable, else what is wrong (bins 1..64 per dimension, finite positive
// widths, |V| at most kMaxVocabulary).
inline constexpr std::uint32_t kMaxVocabulary = 1u << 18;
std::string check_vocabulary(const VocabularyConfig& c);

class Vocabulary {
 public:
  explicit Vocabulary(const VocabularyConfig& config);  // config must pass check_vocabulary

  const VocabularyConfig& config() const noexcept { return config_; }
  std::uint32_t size() const noexcept { return size_; }
  // The bin of one dimension's value (the square root for variance and
  // roughness, see above).
  std::uint32_t bin(Dim d, float value) const noexcept;
  // The word of a feature vector: the bins of the used dimensions in mixed
  // radix, max |Δz| the most significant.
  std::uint32_t word(const Feature& f) const noexcept;

 private:
  VocabularyConfig config_;
  std::uint32_t size_ = 1;
};

}  // namespace trailnav::perception::trav
