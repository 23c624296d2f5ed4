#include "trailnav/perception/ground_height.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace trailnav::perception {

namespace {
constexpr float kInf = std::numeric_limits<float>::infinity();
}

GroundGrid::GroundGrid(const GroundParams& params, float max_range, std::size_t points) : params_(params) {
  const float cell = std::max(params.cell, 0.01f);
  taps_ = std::max(0, static_cast<int>(std::floor(params.radius / cell + 1e-4f)));
  n_ = 2 * (static_cast<int>(std::ceil(max_range / cell)) + taps_ + 2);
  half_ = 0.5f * static_cast<float>(n_) * cell;
  inv_cell_ = 1.0f / cell;
  const auto cells = static_cast<std::size_t>(n_) * static_cast<std::size_t>(n_);
  low_.assign(cells, Lowest{kInf, kInf});
  pass_.assign(cells, kInf);
  ground_.assign(cells, kInf);
  cell_.assign(points, -1);
}

int GroundGrid::cell_of(float x, float y) const noexcept {
  const float fx = (x + half_) * inv_cell_;
  const float fy = (y + half_) * inv_cell_;
  if (!(fx >= 0.0f && fy >= 0.0f)) return -1;
  const int ix = static_cast<int>(fx), iy = static_cast<int>(fy);
  if (ix >= n_ || iy >= n_) return -1;
  return iy * n_ + ix;
}

float GroundGrid::ground_at(float x, float y) const noexcept {
  const int c = cell_of(x, y);
  if (c < 0) return std::numeric_limits<float>::quiet_NaN();
  const float g = ground_[static_cast<std::size_t>(c)];
  return g < kInf ? g : std::numeric_limits<float>::quiet_NaN();
}

void GroundGrid::build(const RevolutionCloud& cloud) noexcept {
  std::fill(low_.begin(), low_.end(), Lowest{kInf, kInf});
  // Each point's cell first (no branch: the compiler runs it several points
  // at a time), then the two lowest points of each cell.
  const auto n = static_cast<std::uint32_t>(n_);
  const float half = half_, inv = inv_cell_;
  for (int i = 0; i < cloud.rings(); ++i) {
    const std::size_t base = cloud.index(i, 0);
    const float* x = cloud.x.data() + base;
    const float* y = cloud.y.data() + base;
    const float* r = cloud.range.data() + base;
    std::int32_t* out = cell_.data() + base;
    const int columns = cloud.columns();
    const float top = static_cast<float>(n) - 0.5f;
    for (int j = 0; j < columns; ++j) {
      float fx = (x[j] + half) * inv, fy = (y[j] + half) * inv;
      // Outside the grid (or no point): -1. Selects, not branches; the
      // compares keep NaN out too.
      const bool inside = (r[j] > 0.0f) & (fx >= 0.0f) & (fy >= 0.0f) & (fx < top) & (fy < top);
      fx = fx > 0.0f ? fx : 0.0f;
      fy = fy > 0.0f ? fy : 0.0f;
      fx = fx < top ? fx : top;
      fy = fy < top ? fy : top;
      const auto cell = static_cast<std::int32_t>(fy) * static_cast<std::int32_t>(n) + static_cast<std::int32_t>(fx);
      out[j] = inside ? cell : -1;
    }
    const float* z = cloud.z.data() + base;
    for (int j = 0; j < columns; ++j) {
      if (out[j] < 0) continue;
      Lowest& l = low_[static_cast<std::size_t>(out[j])];
      const float h = z[j];
      if (h < l.first) {
        l.second = l.first;
        l.first = h;
      } else if (h < l.second) {
        l.second = h;
      }
    }
  }
  // ground = min over |dx| + |dy| <= taps of low2 + slope * cell * (|dx| + |dy|):
  // along x, then along y (the L1 weight is the sum of the two passes').
  // A tap reaching past the edge reads nothing (the grid's margin is wider
  // than any point's reach).
  const float step = params_.max_slope * params_.cell;
  const int t = taps_;
  const int side = n_;
  for (std::size_t i = 0; i < low_.size(); ++i) ground_[i] = low_[i].second;
  for (int y = 0; y < side; ++y) {
    const float* in = ground_.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(side);
    float* out = pass_.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(side);
    for (int x = 0; x < side; ++x) out[x] = in[x];
    for (int d = 1; d <= t; ++d) {
      const float w = step * static_cast<float>(d);
      for (int x = d; x < side; ++x) out[x] = std::min(out[x], in[x - d] + w);
      for (int x = 0; x + d < side; ++x) out[x] = std::min(out[x], in[x + d] + w);
    }
  }
  std::copy(pass_.begin(), pass_.end(), ground_.begin());
  for (int d = 1; d <= t; ++d) {
    const float w = step * static_cast<float>(d);
    const auto off = static_cast<std::size_t>(d) * static_cast<std::size_t>(side);
    for (std::size_t i = off; i < ground_.size(); ++i) ground_[i] = std::min(ground_[i], pass_[i - off] + w);
    for (std::size_t i = 0; i + off < ground_.size(); ++i) ground_[i] = std::min(ground_[i], pass_[i + off] + w);
  }
}

void GroundGrid::apply(RevolutionCloud& cloud, std::vector<float>& height) noexcept {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float above = params_.height;
  const bool raise = params_.raise, cut = params_.cut;
  std::uint64_t raised = 0, lowered = 0, none = 0;
  for (int i = 0; i < cloud.rings(); ++i) {
    const std::size_t base = cloud.index(i, 0);
    const std::int32_t* cells = cell_.data() + base;
    for (int j = 0; j < cloud.columns(); ++j) {
      if (cells[j] < 0) {
        // No point, or one outside the grid.
        if (cloud.state[base + static_cast<std::size_t>(j)] != PointState::none) {
          height[base + static_cast<std::size_t>(j)] = nan;
          ++none;
        }
        continue;
      }
      const std::size_t k = base + static_cast<std::size_t>(j);
      const float g = ground_[static_cast<std::size_t>(cells[j])];
      if (!(g < kInf)) {
        height[k] = nan;
        ++none;
        continue;
      }
      const float h = cloud.z[k] - g;
      height[k] = h;
      const PointState st = cloud.state[k];
      if (st == PointState::isolated) continue;
      const float s = st == PointState::measured ? cloud.step_height[k] : 0.0f;
      if (raise && h > above) {
        cloud.step_height[k] = std::max(s, h);
        cloud.sin_incline[k] = 1.0f;
        cloud.state[k] = PointState::measured;
        ++raised;
      } else if (cut && st == PointState::measured && s > std::max(h, 0.0f)) {
        cloud.step_height[k] = std::max(h, 0.0f);
        ++lowered;
      }
    }
  }
  counters_.raised += raised;
  counters_.lowered += lowered;
  counters_.no_ground += none;
}

}  // namespace trailnav::perception
