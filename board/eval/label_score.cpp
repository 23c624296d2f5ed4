#include "label_score.hpp"

#include <cstdio>
#include <fstream>
#include <map>

namespace trailnav::eval {

std::string_view semantickitti_name(std::uint16_t id) noexcept {
  switch (id) {
    case 0: return "unlabeled";
    case 1: return "outlier";
    case 10: return "car";
    case 11: return "bicycle";
    case 13: return "bus";
    case 15: return "motorcycle";
    case 16: return "on-rails";
    case 18: return "truck";
    case 20: return "other-vehicle";
    case 30: return "person";
    case 31: return "bicyclist";
    case 32: return "motorcyclist";
    case 40: return "road";
    case 44: return "parking";
    case 48: return "sidewalk";
    case 49: return "other-ground";
    case 50: return "building";
    case 51: return "fence";
    case 52: return "other-structure";
    case 60: return "lane-marking";
    case 70: return "vegetation";
    case 71: return "trunk";
    case 72: return "terrain";
    case 80: return "pole";
    case 81: return "traffic-sign";
    case 99: return "other-object";
    default: return id >= 252 && id <= 259 ? "moving" : "unknown id";
  }
}

LabelRole semantickitti_role(std::uint16_t id) noexcept {
  switch (id) {
    case 40: case 44: case 48: case 49: case 72:
      return LabelRole::ground;
    case 50: case 51: case 10: case 18: case 20: case 30: case 31: case 80: case 81: case 71:
      return LabelRole::obstacle;
    case 70:
      return LabelRole::vegetation;
    default:
      return LabelRole::other;
  }
}

Status load_semantickitti_labels(const std::string& path, std::vector<std::uint32_t>& labels) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return Status::error(path + ": cannot open");
  const auto size = static_cast<std::size_t>(in.tellg());
  if (size % 4 != 0) {
    return Status::error(path + ": " + std::to_string(size) + " bytes, not a whole number of 4-byte labels");
  }
  labels.resize(size / 4);
  in.seekg(0);
  for (std::size_t i = 0; i < labels.size(); ++i) {
    unsigned char b[4];
    if (!in.read(reinterpret_cast<char*>(b), 4)) return Status::error(path + ": read failed at label " + std::to_string(i));
    labels[i] = static_cast<std::uint32_t>(b[0]) | static_cast<std::uint32_t>(b[1]) << 8 |
                static_cast<std::uint32_t>(b[2]) << 16 | static_cast<std::uint32_t>(b[3]) << 24;
  }
  return Status::ok();
}

double LabelScore::precision() const noexcept {
  const auto d = true_positives + false_positives;
  return d ? static_cast<double>(true_positives) / static_cast<double>(d) : 0.0;
}
double LabelScore::recall() const noexcept {
  const auto d = true_positives + false_negatives;
  return d ? static_cast<double>(true_positives) / static_cast<double>(d) : 0.0;
}
double LabelScore::f1() const noexcept {
  const double p = precision(), r = recall();
  return p + r > 0.0 ? 2.0 * p * r / (p + r) : 0.0;
}

LabelScore score_labels(std::span<const std::int8_t> obstacle, std::span<const std::uint32_t> labels) {
  std::map<std::uint16_t, LabelClassRow> rows;
  LabelScore s;
  const std::size_t n = std::min(obstacle.size(), labels.size());
  for (std::size_t i = 0; i < n; ++i) {
    const auto id = static_cast<std::uint16_t>(labels[i] & 0xFFFFu);
    LabelClassRow& row = rows[id];
    row.id = id;
    row.role = semantickitti_role(id);
    ++row.points;
    const bool yes = obstacle[i] == 1;
    row.obstacle += yes ? 1u : 0u;
    row.unevaluated += obstacle[i] < 0 ? 1u : 0u;
    if (row.role == LabelRole::obstacle) {
      (yes ? s.true_positives : s.false_negatives) += 1;
    } else if (row.role == LabelRole::ground) {
      (yes ? s.false_positives : s.true_negatives) += 1;
    }
  }
  for (auto& [id, row] : rows) s.classes.push_back(row);
  return s;
}

void merge_label_scores(LabelScore& into, const LabelScore& one) {
  into.true_positives += one.true_positives;
  into.false_positives += one.false_positives;
  into.false_negatives += one.false_negatives;
  into.true_negatives += one.true_negatives;
  std::map<std::uint16_t, LabelClassRow> rows;
  for (const LabelClassRow& r : into.classes) rows[r.id] = r;
  for (const LabelClassRow& r : one.classes) {
    LabelClassRow& t = rows[r.id];
    t.id = r.id;
    t.role = r.role;
    t.points += r.points;
    t.obstacle += r.obstacle;
    t.unevaluated += r.unevaluated;
  }
  into.classes.clear();
  for (auto& [id, row] : rows) into.classes.push_back(row);
}

std::string label_score_table(const LabelScore& s, const std::string& title) {
  std::string out = "| " + title + " | role | points | answered obstacle | share | not evaluated |\n|---|---|---|---|---|---|\n";
  char line[256];
  for (const LabelClassRow& r : s.classes) {
    const char* role = r.role == LabelRole::ground     ? "ground"
                       : r.role == LabelRole::obstacle ? "obstacle"
                       : r.role == LabelRole::vegetation ? "vegetation (apart)"
                                                         : "left out";
    std::snprintf(line, sizeof line, "| %s (%u) | %s | %llu | %llu | %.3f | %llu |\n",
                  std::string(semantickitti_name(r.id)).c_str(), static_cast<unsigned>(r.id), role,
                  static_cast<unsigned long long>(r.points), static_cast<unsigned long long>(r.obstacle),
                  r.obstacle_share(), static_cast<unsigned long long>(r.unevaluated));
    out += line;
  }
  std::snprintf(line, sizeof line,
                "\nprecision %.3f, recall %.3f, F1 %.3f (true positives %llu, false positives %llu, false negatives %llu, "
                "true negatives %llu)\n",
                s.precision(), s.recall(), s.f1(), static_cast<unsigned long long>(s.true_positives),
                static_cast<unsigned long long>(s.false_positives), static_cast<unsigned long long>(s.false_negatives),
                static_cast<unsigned long long>(s.true_negatives));
  out += line;
  return out;
}

}  // namespace trailnav::eval
