#include "trailnav/perception/trav_vocabulary.hpp"

#include <cmath>

namespace trailnav::perception::trav {

std::string_view dim_name(Dim d) noexcept {
  switch (d) {
    case Dim::max_dz: return "max_dz";
    case Dim::remission_mean: return "remission_mean";
    case Dim::remission_var: return "remission_var";
    case Dim::roughness: return "roughness";
    case Dim::slope: return "slope";
    case Dim::height: return "height";
    case Dim::depth: return "depth";
  }
  return "?";
}

std::string_view feature_set_name(FeatureSet s) noexcept {
  switch (s) {
    case FeatureSet::full: return "full";
    case FeatureSet::no_remission: return "NoRe";
    case FeatureSet::no_roughness_slope: return "NoRS";
    case FeatureSet::thesis: return "thesis";
  }
  return "?";
}

bool uses(FeatureSet s, Dim d) noexcept {
  switch (s) {
    case FeatureSet::full: return true;
    case FeatureSet::no_remission: return d != Dim::remission_mean && d != Dim::remission_var;
    case FeatureSet::no_roughness_slope: return d != Dim::roughness && d != Dim::slope;
    case FeatureSet::thesis: return d != Dim::height && d != Dim::depth;
  }
  return false;
}

bool cell_feature(const CellStats& s, Feature& out, const FeatureVector* terrain, float above_ground) noexcept {
  if (s.n < kMinPoints) return false;
  const FeatureVector t = terrain != nullptr ? *terrain : compute_terrain_feature(s);
  const float sd = t[static_cast<std::size_t>(TerrainFeature::std_remission)];
  out.v[static_cast<std::size_t>(Dim::max_dz)] = s.max_dz - s.min_dz;
  out.v[static_cast<std::size_t>(Dim::remission_mean)] = t[static_cast<std::size_t>(TerrainFeature::mean_remission)];
  out.v[static_cast<std::size_t>(Dim::remission_var)] = sd * sd;
  out.v[static_cast<std::size_t>(Dim::roughness)] = t[static_cast<std::size_t>(TerrainFeature::roughness)];
  out.v[static_cast<std::size_t>(Dim::slope)] = t[static_cast<std::size_t>(TerrainFeature::slope)];
  out.v[static_cast<std::size_t>(Dim::height)] = above_ground > 0.0f ? above_ground : 0.0f;
  out.v[static_cast<std::size_t>(Dim::depth)] = above_ground < 0.0f ? -above_ground : 0.0f;
  return true;
}

std::string check_vocabulary(const VocabularyConfig& c) {
  if (static_cast<int>(c.set) >= kFeatureSets) return "unknown feature set";
  std::uint64_t size = 1;
  for (int d = 0; d < kDims; ++d) {
    const Binning& b = c.bins[static_cast<std::size_t>(d)];
    const std::string name(dim_name(static_cast<Dim>(d)));
    if (!(b.width > 0.0f) || !std::isfinite(b.width)) return "bins of " + name + ": the width must be a positive number";
    if (b.bins < 1 || b.bins > 64) return "bins of " + name + ": 1 to 64 bins, got " + std::to_string(b.bins);
    if (uses(c.set, static_cast<Dim>(d))) size *= b.bins;
  }
  if (size > kMaxVocabulary) {
    return "the vocabulary would hold " + std::to_string(size) + " words; at most " + std::to_string(kMaxVocabulary);
  }
  return "";
}

Vocabulary::Vocabulary(const VocabularyConfig& config) : config_(config) {
  for (int d = 0; d < kDims; ++d) {
    if (uses(config_.set, static_cast<Dim>(d))) size_ *= config_.bins[static_cast<std::size_t>(d)].bins;
  }
}

std::uint32_t Vocabulary::bin(Dim d, float value) const noexcept {
  const Binning& b = config_.bins[static_cast<std::size_t>(d)];
  // Variance and roughness on their square roots (the header says why).
  if (d == Dim::remission_var || d == Dim::roughness) value = value > 0.0f ? std::sqrt(value) : 0.0f;
  if (!(value > 0.0f)) return 0;  // also NaN
  const float k = value / b.width;
  if (!(k < static_cast<float>(b.bins - 1))) return b.bins - 1;
  return static_cast<std::uint32_t>(k);
}

std::uint32_t Vocabulary::word(const Feature& f) const noexcept {
  std::uint32_t w = 0;
  for (int d = 0; d < kDims; ++d) {
    const auto dim = static_cast<Dim>(d);
    if (!uses(config_.set, dim)) continue;
    w = w * config_.bins[static_cast<std::size_t>(d)].bins + bin(dim, f[dim]);
  }
  return w;
}

}  // namespace trailnav::perception::trav
