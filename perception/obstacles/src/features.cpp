// Smoothing along the rings and the geometric features of thesis §7.1.2.
#include <algorithm>
#include <cmath>

#include "trailnav/perception/cloud.hpp"

namespace trailnav::perception {

void smooth_rings(RevolutionCloud& cloud, const FeatureParams& params) noexcept {
  const int half = params.smoothing_half_window;
  if (half <= 0) return;
  const int columns = cloud.columns();
  const auto stride = static_cast<std::size_t>(columns) + 1;
  double* sx = cloud.ring_sums.data();
  double* sy = sx + stride;
  double* sz = sy + stride;
  const float jump = params.smoothing_max_jump;
  for (int ring = 0; ring < cloud.rings(); ++ring) {
    const std::size_t base = cloud.index(ring, 0);
    const PointState* st = cloud.state.data() + base;
    const float* r = cloud.range.data() + base;
    float* px = cloud.x.data() + base;
    float* py = cloud.y.data() + base;
    float* pz = cloud.z.data() + base;
    int a = 0;
    while (a < columns) {
      if (st[a] == PointState::none) {
        ++a;
        continue;
      }
      // The segment [a, b): consecutive valid points without a range jump.
      int b = a + 1;
      while (b < columns && st[b] != PointState::none && std::abs(r[b] - r[b - 1]) <= jump) ++b;
      if (b - a > 1) {
        // Prefix sums over the segment (doubles: no drift over long rings).
        sx[0] = sy[0] = sz[0] = 0.0;
        for (int j = a; j < b; ++j) {
          const auto q = static_cast<std::size_t>(j - a);
          sx[q + 1] = sx[q] + static_cast<double>(px[j]);
          sy[q + 1] = sy[q] + static_cast<double>(py[j]);
          sz[q + 1] = sz[q] + static_cast<double>(pz[j]);
        }
        for (int j = a; j < b; ++j) {
          // A symmetric window, narrowed near the segment's ends so the
          // average stays centred on the point.
          const int w = std::min({half, j - a, b - 1 - j});
          const auto lo = static_cast<std::size_t>(j - w - a);
          const auto hi = static_cast<std::size_t>(j + w + 1 - a);
          const double inv = 1.0 / static_cast<double>(2 * w + 1);
          px[j] = static_cast<float>((sx[hi] - sx[lo]) * inv);
          py[j] = static_cast<float>((sy[hi] - sy[lo]) * inv);
          pz[j] = static_cast<float>((sz[hi] - sz[lo]) * inv);
        }
      }
      a = b;
    }
  }
}

namespace {

struct Best {
  float dz = -1.0f;  // largest |dz| so far
  float d2 = 1.0f;   // its squared distance
  bool found = false;
  bool any_valid = false;
};

inline void consider(const RevolutionCloud& c, std::size_t p, std::size_t q, float x2, Best& best, bool& done) noexcept {
  if (c.state[q] == PointState::none) return;
  best.any_valid = true;
  const float dx = c.x[q] - c.x[p];
  const float dy = c.y[q] - c.y[p];
  const float dz = c.z[q] - c.z[p];
  const float d2 = dx * dx + dy * dy + dz * dz;
  if (d2 <= x2) return;
  done = true;
  best.found = true;
  const float adz = std::abs(dz);
  if (adz > best.dz) {
    best.dz = adz;
    best.d2 = d2;
  }
}

}  // namespace

void compute_features(RevolutionCloud& cloud, const FeatureParams& params, FeatureCounters& counters) noexcept {
  const int columns = cloud.columns();
  const int rings = cloud.rings();
  const int k_max = std::min(params.ring_neighbours, std::max(columns / 2 - 1, 0));
  const int l_max = params.cross_neighbours;
  const float x2 = params.min_distance * params.min_distance;
  const auto stride = static_cast<std::ptrdiff_t>(cloud.stride());
  const bool wrap = cloud.full_turn;
  std::uint64_t measured = 0, flat = 0, isolated = 0;
  for (int i = 0; i < rings; ++i) {
    for (int j = 0; j < columns; ++j) {
      const std::size_t p = cloud.index(i, j);
      if (cloud.state[p] == PointState::none) continue;
      Best best;
      // Along the ring, each way (Eqs. 7.1, 7.2).
      for (int dir = -1; dir <= 1; dir += 2) {
        bool done = false;
        for (int k = 1; k <= k_max && !done; ++k) {
          int jj = j + dir * k;
          if (jj < 0 || jj >= columns) {
            if (!wrap) break;
            jj = jj < 0 ? jj + columns : jj - columns;
          }
          consider(cloud, p, cloud.index(i, jj), x2, best, done);
        }
      }
      // Across the rings, same column (Eqs. 7.3, 7.4).
      for (int dir = -1; dir <= 1; dir += 2) {
        bool done = false;
        for (int l = 1; l <= l_max && !done; ++l) {
          const int ii = i + dir * l;
          if (ii < 0 || ii >= rings) break;
          consider(cloud, p, static_cast<std::size_t>(static_cast<std::ptrdiff_t>(p) + dir * l * stride), x2, best, done);
        }
      }
      if (best.found) {
        cloud.step_height[p] = best.dz;
        cloud.sin_incline[p] = best.dz / std::sqrt(best.d2);
        cloud.state[p] = PointState::measured;
        ++measured;
      } else if (best.any_valid) {
        cloud.step_height[p] = 0.0f;
        cloud.sin_incline[p] = 0.0f;
        cloud.state[p] = PointState::flat;
        ++flat;
      } else {
        cloud.state[p] = PointState::isolated;
        ++isolated;
      }
    }
  }
  counters.measured += measured;
  counters.flat += flat;
  counters.isolated += isolated;
}

}  // namespace trailnav::perception
