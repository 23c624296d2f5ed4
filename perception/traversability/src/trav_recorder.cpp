#include "trailnav/perception/trav_recorder.hpp"

#include <algorithm>
#include <cmath>

namespace trailnav::perception::trav {

std::optional<Footprint> builtin_footprint(std::string_view profile) noexcept {
  if (profile == "large") return Footprint{1.2, 0.8, 0.0};
  if (profile == "small") return Footprint{0.6, 0.45, 0.0};
  return std::nullopt;
}


std::string check_recorder(const RecorderConfig& c) {
  if (!(c.local_map_distance > 0.0) || !std::isfinite(c.local_map_distance)) return "local_map_distance must be positive";
  if (!(c.max_range > 0.0) || !std::isfinite(c.max_range)) return "max_range must be positive";
  if (!(c.footprint.length > 0.0 && c.footprint.width > 0.0) || !std::isfinite(c.footprint.length) ||
      !std::isfinite(c.footprint.width) || !std::isfinite(c.footprint.forward)) {
    return "the footprint needs a positive length and width";
  }
  if (c.max_words < 1000 || c.max_words > 50'000'000) return "max_words must lie in 1000..50000000";
  return "";
}

TravRecorder::TravRecorder(const RecorderConfig& config, const Vocabulary& vocabulary, std::int32_t size_x,
                           std::int32_t size_y, double resolution)
    : config_(config),
      vocabulary_(vocabulary),
      marks_(size_x, size_y, resolution, 0u),
      ground_(size_x * resolution, size_y * resolution),
      entries_(config.max_words) {
  words_.reserve(config.max_words);
}

void TravRecorder::drive(double x, double y, double yaw) noexcept {
  if (have_pose_) travelled_ += std::hypot(x - last_x_, y - last_y_);
  have_pose_ = true;
  last_x_ = x;
  last_y_ = y;
  marks_.move_to(x, y);
  ground_.move_to(x, y);
  mark(x, y, yaw);
}

void TravRecorder::mark(double x, double y, double yaw) noexcept {
  // The cells whose squares meet the rectangle: separating axes are the
  // grid's two and the rectangle's two.
  const Footprint& f = config_.footprint;
  const double c = std::cos(yaw), s = std::sin(yaw);
  const double cx = x + c * f.forward, cy = y + s * f.forward;
  const double hl = 0.5 * f.length, hw = 0.5 * f.width;
  const double res = marks_.resolution(), half = 0.5 * res;
  // The rectangle's extent along x and y.
  const double ex = std::abs(c) * hl + std::abs(s) * hw, ey = std::abs(s) * hl + std::abs(c) * hw;
  const CellIndex lo = marks_.world_to_index(cx - ex, cy - ey), hi = marks_.world_to_index(cx + ex, cy + ey);
  for (std::int32_t j = lo.y; j <= hi.y; ++j) {
    for (std::int32_t i = lo.x; i <= hi.x; ++i) {
      const CellIndex k{i, j};
      if (!marks_.contains(k)) continue;
      const WorldPoint p = marks_.cell_center(k);
      const double dx = p.x - cx, dy = p.y - cy;
      // The square's projection on the rectangle's axes: half * (|c| + |s|).
      const double reach = half * (std::abs(c) + std::abs(s));
      if (std::abs(dx * c + dy * s) > hl + reach || std::abs(-dx * s + dy * c) > hw + reach) continue;
      std::uint32_t& m = marks_.at(k);
      if (m != local_map_) {
        m = local_map_;
        ++counters_.footprint_cells;
      }
    }
  }
}

bool TravRecorder::footprint(CellIndex cell) const noexcept {
  return marks_.contains(cell) && marks_.at(cell) == local_map_;
}

bool TravRecorder::too_far(double x, double y) noexcept {
  if (have_pose_ && std::hypot(x - last_x_, y - last_y_) > config_.max_range) {
    ++counters_.too_far;
    return true;
  }
  return false;
}

void TravRecorder::store(CellIndex cell, std::uint32_t word) noexcept {
  if (used_ == entries_.size()) {
    ++counters_.dropped;
    return;
  }
  entries_[used_] = {cell, word, static_cast<std::uint32_t>(used_)};
  ++used_;
  ++counters_.words;
}

void TravRecorder::cell_sums(CellIndex cell, const CellStats& sums, const FeatureVector* feature, double x,
                             double y) noexcept {
  if (too_far(x, y)) return;
  const float height = ground_.height(x, y, sums);
  Feature f;
  if (!cell_feature(sums, f, feature, height)) return;
  store(cell, vocabulary_.word(f));
}

void TravRecorder::finish_local_map(WordCounts& counts, const std::function<void(const CellWords&)>& each_cell) noexcept {
  counts.clear();
  // Cell by cell, in the order recorded within a cell (std::sort, in place:
  // std::stable_sort would take a buffer from the heap).
  std::sort(entries_.begin(), entries_.begin() + static_cast<std::ptrdiff_t>(used_), [](const Entry& a, const Entry& b) {
    if (a.cell.y != b.cell.y) return a.cell.y < b.cell.y;
    if (a.cell.x != b.cell.x) return a.cell.x < b.cell.x;
    return a.order < b.order;
  });
  std::size_t k = 0;
  while (k < used_) {
    const CellIndex cell = entries_[k].cell;
    const bool positive = footprint(cell);
    words_.clear();
    for (; k < used_ && entries_[k].cell == cell; ++k) {
      counts.add(entries_[k].word, positive);
      words_.push_back(entries_[k].word);
      counters_.positive_words += positive ? 1 : 0;
    }
    if (each_cell) each_cell({cell, positive, words_});
  }
  used_ = 0;
  ++local_map_;
  travelled_ = 0.0;
  ++counters_.local_maps;
}

}  // namespace trailnav::perception::trav
