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
  ground_.assign(cells + 1, kInf);  // + a last cell that stays nothing: where apply() looks for a point off the grid
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
  // Only the rows the last revolution's points reached hold anything (the
  // ground's up to `taps` rows beyond): back to nothing there.
  const auto side_z = static_cast<std::size_t>(n_);
  if (row_lo_ <= row_hi_) {
    const auto lo = static_cast<std::size_t>(row_lo_) * side_z, hi = static_cast<std::size_t>(row_hi_ + 1) * side_z;
    std::fill(low_.begin() + static_cast<std::ptrdiff_t>(lo), low_.begin() + static_cast<std::ptrdiff_t>(hi), Lowest{kInf, kInf});
    std::fill(pass_.begin() + static_cast<std::ptrdiff_t>(lo), pass_.begin() + static_cast<std::ptrdiff_t>(hi), kInf);
    const auto glo = static_cast<std::size_t>(std::max(row_lo_ - taps_, 0)) * side_z;
    const auto ghi = static_cast<std::size_t>(std::min(row_hi_ + taps_, n_ - 1) + 1) * side_z;
    std::fill(ground_.begin() + static_cast<std::ptrdiff_t>(glo), ground_.begin() + static_cast<std::ptrdiff_t>(ghi), kInf);
  }
  std::int32_t first_cell = std::numeric_limits<std::int32_t>::max(), last_cell = -1;
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
      first_cell = std::min(first_cell, out[j]);
      last_cell = std::max(last_cell, out[j]);
      // The two lowest so far, without a branch (which way a point goes
      // is not predictable): a new lowest pushes the old one to second.
      Lowest& l = low_[static_cast<std::size_t>(out[j])];
      const float h = z[j];
      const float first = l.first, second = l.second;
      l.second = std::min(second, std::max(first, h));
      l.first = std::min(first, h);
    }
  }
  // ground = min over |dx| + |dy| <= taps of low2 + slope * cell * (|dx| + |dy|):
  // along x, then along y (the L1 weight is the sum of the two passes').
  // A tap reaching past the edge reads nothing (the grid's margin is wider
  // than any point's reach).
  const float step = params_.max_slope * params_.cell;
  const int t = taps_;
  const int side = n_;
  if (last_cell < 0) {
    row_lo_ = 0;
    row_hi_ = -1;
    return;
  }
  // The rows holding points; the ground reaches `taps` rows beyond. Every
  // row outside [row_lo_, row_hi_] of low_ and pass_ is empty (nothing), so
  // the passes need not look there.
  row_lo_ = first_cell / side;
  row_hi_ = last_cell / side;
  const auto sz = static_cast<std::size_t>(side);
  for (int y = row_lo_; y <= row_hi_; ++y) {
    const Lowest* low = low_.data() + static_cast<std::size_t>(y) * sz;
    float* in = ground_.data() + static_cast<std::size_t>(y) * sz;  // (ground_ as scratch for the row)
    float* out = pass_.data() + static_cast<std::size_t>(y) * sz;
    for (int x = 0; x < side; ++x) in[x] = low[x].second;
    for (int x = 0; x < side; ++x) out[x] = in[x];
    for (int d = 1; d <= t; ++d) {
      const float w = step * static_cast<float>(d);
      for (int x = d; x < side; ++x) out[x] = std::min(out[x], in[x - d] + w);
      for (int x = 0; x + d < side; ++x) out[x] = std::min(out[x], in[x + d] + w);
    }
  }
  const int g_lo = std::max(row_lo_ - t, 0), g_hi = std::min(row_hi_ + t, side - 1);
  for (int y = g_lo; y <= g_hi; ++y) {
    float* g = ground_.data() + static_cast<std::size_t>(y) * sz;
    const float* p0 = pass_.data() + static_cast<std::size_t>(y) * sz;
    for (int x = 0; x < side; ++x) g[x] = p0[x];
    for (int d = 1; d <= t; ++d) {
      const float w = step * static_cast<float>(d);
      if (y - d >= row_lo_) {
        const float* p = pass_.data() + static_cast<std::size_t>(y - d) * sz;
        for (int x = 0; x < side; ++x) g[x] = std::min(g[x], p[x] + w);
      }
      if (y + d <= row_hi_) {
        const float* p = pass_.data() + static_cast<std::size_t>(y + d) * sz;
        for (int x = 0; x < side; ++x) g[x] = std::min(g[x], p[x] + w);
      }
    }
  }
}

void GroundGrid::apply(RevolutionCloud& cloud, std::vector<float>& height) noexcept {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float above = params_.height;
  const bool raise = params_.raise, cut = params_.cut;
  std::uint64_t raised = 0, lowered = 0, none = 0;
  // Selects instead of branches (which way a point goes is not
  // predictable: the branches were most of the time here).
  const auto nothing = static_cast<std::int32_t>(ground_.size() - 1);
  for (int i = 0; i < cloud.rings(); ++i) {
    const std::size_t base = cloud.index(i, 0);
    const std::int32_t* cells = cell_.data() + base;
    const float* z = cloud.z.data() + base;
    float* step = cloud.step_height.data() + base;
    float* sine = cloud.sin_incline.data() + base;
    PointState* state = cloud.state.data() + base;
    float* out = height.data() + base;
    for (int j = 0; j < cloud.columns(); ++j) {
      const std::int32_t c = cells[j];
      const PointState st = state[j];
      // No point, or one outside the grid (c < 0): the cell of nothing.
      const float g = ground_[static_cast<std::size_t>(c < 0 ? nothing : c)];
      const bool known = g < kInf;
      const bool point = c >= 0 || st != PointState::none;
      const float h = known ? z[j] - g : nan;
      out[j] = point ? h : out[j];
      none += point && !known ? 1 : 0;
      const bool measured = st == PointState::measured;
      const float s = measured ? step[j] : 0.0f;
      const bool up = known && st != PointState::isolated && raise && h > above;
      const float floor = std::max(h, 0.0f);
      const bool down = known && !up && cut && measured && s > floor;
      step[j] = up ? std::max(s, h) : down ? floor : step[j];
      sine[j] = up ? 1.0f : sine[j];
      state[j] = up ? PointState::measured : st;
      raised += up ? 1 : 0;
      lowered += down ? 1 : 0;
    }
  }
  counters_.raised += raised;
  counters_.lowered += lowered;
  counters_.no_ground += none;
}

}  // namespace trailnav::perception
