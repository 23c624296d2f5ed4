// Traversability learnt from demonstrations over recordings, offline and
// deterministically (thesis chapter 6, docs/traversability.md): robot
// profiles and the per-cell traversability truth of a simulated world for
// each, training on demonstration drives (`trailnav trav-train`) and the
// scores of both learners with the thesis' rule on held-out drives
// (`trailnav trav-eval`).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "sim_truth.hpp"
#include "trailnav/perception/obstacle_config.hpp"
#include "trailnav/perception/terrain_config.hpp"
#include "trailnav/perception/trav_learner.hpp"
#include "trailnav/perception/trav_model_file.hpp"
#include "trailnav/perception/trav_recorder.hpp"

namespace trailnav::eval {

// What a robot may drive on: its footprint and the kinds of ground it can
// cross (terrain classes; solid obstacles, ditches and undergrowth, the
// simulator's obstacle truth, never).
struct RobotProfile {
  std::string name;
  perception::trav::Footprint footprint;
  std::array<bool, perception::kTerrainClasses> ground{};  // by sim::TerrainClass code
};
// Built-in: "large" (1.2 x 0.8 m; street, dirt, grass, low vegetation,
// other ground), "small" (0.6 x 0.45 m; paving and dirt: street, dirt and
// other hard ground, never grass or vegetation).
std::optional<RobotProfile> builtin_profile(const std::string& name);
struct LoadedProfile {
  std::optional<RobotProfile> profile;
  std::string error;
};
// A built-in name, or a YAML file (docs/traversability.md) with errors that
// name the file, the line and the key.
LoadedProfile load_profile(const std::string& name_or_file);

// The truth of a grid cell (centre x, y; side `res`) for a profile: true when
// every truth pixel in it is free ground of a kind the profile may cross,
// false when any is not (the thesis labels conservatively: in doubt, not
// traversable), none outside the world.
std::optional<bool> truth_traversable(const RobotProfile& profile, const SimTruth& truth, double x, double y, double res);

// Why a cell is not traversable (its worst pixel: a solid obstacle over a
// ditch over undergrowth over ground the profile may not cross); `none` when it is.
enum class Untraversable : std::uint8_t { none = 0, solid = 1, ditch = 2, undergrowth = 3, ground = 4 };
inline constexpr std::size_t kUntraversableCauses = 5;
const char* untraversable_name(Untraversable cause) noexcept;  // "none", "solid", "ditch", "undergrowth", "ground"
std::optional<Untraversable> truth_cause(const RobotProfile& profile, const SimTruth& truth, double x, double y,
                                         double res);

struct TravRunOptions {
  std::vector<std::string> inputs;  // simulated recordings (truth/ gives the poses and, for eval, the truth)
  perception::TerrainConfig terrain;
  std::string calibration;
  perception::trav::RecorderConfig recorder;  // its footprint is the profile's
  RobotProfile profile;
  std::function<void(double)> progress;       // 0..1 over all inputs
  std::string png_dir;                        // trav-eval: a picture per method of the full vector's answers, if set
};

struct TravLocalMap {
  perception::trav::TravModels::Assignment assignment;
  std::uint64_t positive = 0, unlabelled = 0;  // words
};
struct TravTrainSet {
  perception::trav::FeatureSet set = perception::trav::FeatureSet::full;
  std::uint64_t learnt = 0, created = 0, forced = 0, unlearnt = 0;  // local maps
  std::vector<TravLocalMap> local_maps;  // in order
};
struct TravTrainReport {
  std::string error;
  std::uint64_t revolutions = 0;
  perception::trav::RecorderCounters recorder;  // the full set's (its local maps: sets.front().local_maps)
  std::vector<TravTrainSet> sets;
  perception::trav::TravModelFile model;
};
// Learns every feature set's models from the demonstration drives, in turn.
// `model` may hold an existing model to extend (same profile and sets).
TravTrainReport run_trav_train(const TravRunOptions& options, const perception::trav::VocabularyConfig& vocabulary,
                               const perception::trav::LearnerConfig& learner,
                               const perception::trav::TravModelFile* extend = nullptr);

struct TravScores {
  std::uint64_t tp = 0, fp = 0, tn = 0, fn = 0;
  std::uint64_t forgiven = 0;  // untraversable, called traversable, but a neighbour was not: not a false positive (thesis)
  std::uint64_t cells() const noexcept { return tp + fp + tn + fn; }
  double precision() const noexcept { return tp + fp > 0 ? static_cast<double>(tp) / static_cast<double>(tp + fp) : 0.0; }
  double recall() const noexcept { return tp + fn > 0 ? static_cast<double>(tp) / static_cast<double>(tp + fn) : 0.0; }
  double specificity() const noexcept { return tn + fp > 0 ? static_cast<double>(tn) / static_cast<double>(tn + fp) : 0.0; }
  // Without the thesis' leniency: every untraversable cell called traversable counts.
  double strict_specificity() const noexcept {
    return tn + fp > 0 ? static_cast<double>(tn - forgiven) / static_cast<double>(tn + fp) : 0.0;
  }
};
struct TravEvalRow {
  perception::trav::Method method = perception::trav::Method::pnb;
  perception::trav::FeatureSet set = perception::trav::FeatureSet::full;
  TravScores scores;
  // By true terrain class of the cell (only its single-class cells): cells called traversable / cells.
  std::array<std::uint64_t, perception::kTerrainClasses> called_traversable{}, class_cells{};
  // The false positives (thesis' rule) by why the cell is not traversable (Untraversable).
  std::array<std::uint64_t, kUntraversableCauses> false_positives{};
};
struct TravEvalReport {
  std::string error;
  std::uint64_t revolutions = 0;
  std::uint64_t local_maps = 0;
  std::uint64_t unscored = 0;  // cells outside the world
  std::vector<TravEvalRow> rows;  // per feature set in the model, PNB then POS
  double step_ms = 0.0;           // mean time of a 0.5 m traversability step (features, words), full set
  std::vector<std::string> files;  // pictures written (png_dir)
};
// Every cell with words in a local map is classified when the local map ends
// (P(trav | f_1..n) > 0.5) and scored against the profile's truth.
TravEvalReport run_trav_eval(const TravRunOptions& options, const perception::trav::TravModelFile& model);

}  // namespace trailnav::eval
