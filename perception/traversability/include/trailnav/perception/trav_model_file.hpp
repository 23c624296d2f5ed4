// A learnt traversability model on disk: the robot profile it was learnt
// for and, per feature set (the full vector, the thesis' five dimensions and
// the ablations NoRe and NoRS, thesis §6.4, each at most once), the vocabulary and learner settings and
// each terrain model's word counts (the learner recomputes every table from
// them, so a model can be trained further later). Little-endian, versioned, CRC-32 at the end; only
// words with a count are stored. Saving is atomic: a temporary file beside
// the target, flushed to the disk, then renamed over it, so a reader (or a
// power cut) never sees a half-written model. docs/traversability.md gives
// the layout.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "trailnav/perception/trav_learner.hpp"
#include "trailnav/runtime/status.hpp"

namespace trailnav::perception::trav {

// Version 3: seven feature dimensions (the height above the ground, then the
// depth below it, added); version 1 files (the thesis' five) and version 2
// (six) are refused with what to do.
inline constexpr std::uint32_t kModelFileVersion = 3;
inline constexpr std::size_t kMaxProfileName = 64;

struct TravModelSet {
  VocabularyConfig vocabulary;
  LearnerConfig learner;
  std::vector<WordCounts> models;  // each over the vocabulary's size
};

struct TravModelFile {
  std::string profile;  // printable ASCII, at most kMaxProfileName characters
  std::vector<TravModelSet> sets;  // 1 to kFeatureSets, distinct feature sets
  // The set of a feature set, or null.
  const TravModelSet* set(FeatureSet s) const noexcept;
};

// The file's bytes (the model must be consistent: check_vocabulary,
// check_learner, counts over |V|, at most max_models).
std::vector<std::uint8_t> serialize_trav_model(const TravModelFile& model);
Status save_trav_model(const std::string& path, const TravModelFile& model);

// The largest file of one feature set of `models` models over a vocabulary
// of that size, with a profile name of `profile` characters.
std::size_t trav_model_bound(std::size_t profile, std::uint32_t vocabulary, std::uint32_t models) noexcept;
// The file of live models (one feature set, their own), into `out` (cleared
// first): no allocation when out's capacity is trav_model_bound() of them
// (a demonstration saving on a thread the allocation guard watches).
void serialize_trav_models(std::string_view profile, const TravModels& models, std::vector<std::uint8_t>& out) noexcept;

struct LoadedTravModel {
  std::optional<TravModelFile> model;
  std::string error;  // "<name>: what is wrong", when model is empty
};
LoadedTravModel load_trav_model(const std::string& path);
LoadedTravModel parse_trav_model(std::span<const std::uint8_t> bytes, const std::string& name);

}  // namespace trailnav::perception::trav
