// Per-point obstacle answers scored against SemanticKITTI's hand-made labels
// (docs/obstacles.md "On real labelled lidar"): the points of the ground
// classes (road, parking, sidewalk, other-ground, terrain) should not be
// obstacles, those of the obstacle classes (building, fence, car, truck,
// other-vehicle, person, bicyclist, pole, traffic-sign, trunk) should;
// vegetation is reported apart (a robot may or may not drive into it) and
// every other class is left out. An answer that is not 1 (0, or -1 not
// evaluated) counts as "not an obstacle". The same scoring for any tool's
// answers, so peers are compared on the same points by the same code.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "trailnav/runtime/status.hpp"

namespace trailnav::eval {

enum class LabelRole : std::uint8_t { ground, obstacle, vegetation, other };

// A SemanticKITTI class id (the label's lower 16 bits): its name and role.
std::string_view semantickitti_name(std::uint16_t id) noexcept;
LabelRole semantickitti_role(std::uint16_t id) noexcept;

// A .label file: one little-endian uint32 per point (class in the lower 16
// bits, instance in the upper). Errors name the file.
Status load_semantickitti_labels(const std::string& path, std::vector<std::uint32_t>& labels);

struct LabelClassRow {
  std::uint16_t id = 0;
  LabelRole role = LabelRole::other;
  std::uint64_t points = 0;
  std::uint64_t obstacle = 0;     // answered 1
  std::uint64_t unevaluated = 0;  // answered -1
  double obstacle_share() const noexcept { return points ? static_cast<double>(obstacle) / static_cast<double>(points) : 0.0; }
};

struct LabelScore {
  std::vector<LabelClassRow> classes;  // every class present, by id
  std::uint64_t true_positives = 0;    // obstacle class, answered 1
  std::uint64_t false_positives = 0;   // ground class, answered 1
  std::uint64_t false_negatives = 0;   // obstacle class, not answered 1
  std::uint64_t true_negatives = 0;    // ground class, not answered 1
  double precision() const noexcept;
  double recall() const noexcept;
  double f1() const noexcept;
};

// `obstacle[i]` is point i's answer (1, 0, -1); as many as `labels`.
LabelScore score_labels(std::span<const std::int8_t> obstacle, std::span<const std::uint32_t> labels);

// Adds `one`'s counts to `into` (several scans scored together).
void merge_label_scores(LabelScore& into, const LabelScore& one);

// The score as a Markdown table (per class, then precision, recall, F1).
std::string label_score_table(const LabelScore& score, const std::string& title);

}  // namespace trailnav::eval
