// Smoothing along the rings and the geometric features of thesis §7.1.2.
#include <algorithm>
#include <cmath>
#include <cstring>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif


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

// The coordinates of one revolution, as restrict pointers (the search never
// writes them): the byte-sized state stores would otherwise make the compiler
// reload every array's address after each one.
struct View {
  const float* __restrict x;
  const float* __restrict y;
  const float* __restrict z;
  const PointState* st;
};

// The candidate of Eqs. 7.5/7.6 so far: the largest |dz| among the first
// farther neighbours of the directions searched.
struct Best {
  float dz = -1.0f;
  float d2 = 1.0f;
  bool found = false;
  bool any_valid = false;

  void offer(float adz, float d2_) noexcept {
    found = true;
    if (adz > dz) {
      dz = adz;
      d2 = d2_;
    }
  }
};

// Neighbour q of point p: true when the search in this direction ends here.
inline bool consider(const View& v, std::size_t p, std::size_t q, float x2, Best& best) noexcept {
  if (v.st[q] == PointState::none) return false;
  best.any_valid = true;
  const float dx = v.x[q] - v.x[p];
  const float dy = v.y[q] - v.y[p];
  const float dz = v.z[q] - v.z[p];
  const float d2 = dx * dx + dy * dy + dz * dz;
  if (d2 <= x2) return false;
  best.offer(std::abs(dz), d2);
  return true;
}

// Along the ring, one point at a time, wrapping around a full turn.
void along_ring_portable(const View& v, std::size_t row, int j, int columns, int k_max, bool wrap, float x2,
                         Best& best) noexcept {
  const std::size_t p = row + static_cast<std::size_t>(j);
  for (int dir = -1; dir <= 1; dir += 2) {
    for (int k = 1; k <= k_max; ++k) {
      int jj = j + dir * k;
      if (jj < 0 || jj >= columns) {
        if (!wrap) break;
        jj = jj < 0 ? jj + columns : jj - columns;
      }
      if (consider(v, p, row + static_cast<std::size_t>(jj), x2, best)) break;
    }
  }
}

// Four points at a time with the compilers' generic vectors (GCC and Clang
// turn them into SSE2 on x86-64 and NEON on ARM). For each direction the
// neighbours are visited from the farthest to the nearest, each farther one
// replacing the candidate, so what is left is the first farther neighbour,
// with no branch per point or neighbour.
#if defined(__GNUC__)
constexpr bool kSimd = true;
using F4 = float __attribute__((vector_size(16)));
using I4 = std::int32_t __attribute__((vector_size(16)));
using B4 = std::uint8_t __attribute__((vector_size(4)));

inline F4 load4(const float* p) noexcept {
  F4 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
// -1 where the point is valid, 0 where there is none.
inline I4 valid4(const PointState* p) noexcept {
  B4 b;
  std::memcpy(&b, p, sizeof b);
  return __builtin_convertvector(b, I4) != 0;
}

// Square roots, correctly rounded as std::sqrt's.
inline F4 sqrt4(F4 v) noexcept {
#if defined(__SSE2__)
  return reinterpret_cast<F4>(_mm_sqrt_ps(reinterpret_cast<__m128>(v)));
#else
  return F4{std::sqrt(v[0]), std::sqrt(v[1]), std::sqrt(v[2]), std::sqrt(v[3])};
#endif
}

struct Best4 {
  F4 dz = {-1.0f, -1.0f, -1.0f, -1.0f};
  F4 d2 = {1.0f, 1.0f, 1.0f, 1.0f};
  I4 found = {0, 0, 0, 0};
  I4 any = {0, 0, 0, 0};
};

struct Point4 {
  F4 x, y, z;
};

// One direction: the neighbours at p + step * k for k = reach .. 1.
inline void search4(const View& v, const Point4& p, std::size_t at, std::ptrdiff_t step, int reach, F4 x2,
                    Best4& best) noexcept {
  F4 cdz = {0, 0, 0, 0};
  F4 cd2 = {0, 0, 0, 0};
  I4 cf = {0, 0, 0, 0};
  const F4 sign = {-0.0f, -0.0f, -0.0f, -0.0f};
  for (int k = reach; k >= 1; --k) {
    const auto q = static_cast<std::size_t>(static_cast<std::ptrdiff_t>(at) + step * k);
    const I4 valid = valid4(v.st + q);
    const F4 dx = load4(v.x + q) - p.x;
    const F4 dy = load4(v.y + q) - p.y;
    const F4 dz = load4(v.z + q) - p.z;
    // The same operations in the same order as consider(): identical results.
    const F4 d2 = dx * dx + dy * dy + dz * dz;
    const I4 far = valid & (d2 > x2);
    const F4 adz = reinterpret_cast<F4>(reinterpret_cast<I4>(dz) & ~reinterpret_cast<I4>(sign));
    cdz = far ? adz : cdz;
    cd2 = far ? d2 : cd2;
    cf |= far;
    best.any |= valid;
  }
  // Offer this direction's first farther neighbour, as Best::offer().
  const I4 better = cf & (cdz > best.dz);
  best.dz = better ? cdz : best.dz;
  best.d2 = better ? cd2 : best.d2;
  best.found |= cf;
}
#else
constexpr bool kSimd = false;
#endif

}  // namespace

bool simd_features_available() noexcept { return kSimd; }

void compute_features(RevolutionCloud& cloud, const FeatureParams& params, FeatureCounters& counters,
                      FeatureKernel kernel) noexcept {
  const int columns = cloud.columns();
  const int rings = cloud.rings();
  const int k_max = std::min(params.ring_neighbours, std::max(columns / 2 - 1, 0));
  const int l_max = params.cross_neighbours;
  const float x2 = params.min_distance * params.min_distance;
  const auto stride = static_cast<std::size_t>(cloud.stride());
  const bool wrap = cloud.full_turn;
  const View v{cloud.x.data(), cloud.y.data(), cloud.z.data(), cloud.state.data()};
  PointState* state = cloud.state.data();
  float* __restrict step = cloud.step_height.data();
  float* __restrict sin_incline = cloud.sin_incline.data();
  // The columns the four-wide search may use: k_max from both ends.
  const bool simd = kSimd && kernel == FeatureKernel::fastest;
  const int simd_begin = simd ? k_max : columns;
  const int simd_end = simd ? columns - k_max : columns;
  std::uint64_t measured = 0, flat = 0, isolated = 0;
  // `sine`: best.dz / sqrt(best.d2) when found (Eq. 7.6).
  auto finish = [&](std::size_t p, const Best& best, float sine) {
    if (best.found) {
      step[p] = best.dz;
      sin_incline[p] = sine;
      state[p] = PointState::measured;
      ++measured;
    } else if (best.any_valid) {
      step[p] = 0.0f;
      sin_incline[p] = 0.0f;
      state[p] = PointState::flat;
      ++flat;
    } else {
      state[p] = PointState::isolated;
      ++isolated;
    }
  };
  auto one_point = [&](int i, std::size_t row, int j) {
    const std::size_t p = row + static_cast<std::size_t>(j);
    if (state[p] == PointState::none) return;
    Best best;
    // Along the ring, each way (Eqs. 7.1, 7.2).
    along_ring_portable(v, row, j, columns, k_max, wrap, x2, best);
    // Across the rings, same column (Eqs. 7.3, 7.4).
    for (int l = 1; l <= l_max && l <= i; ++l) {
      if (consider(v, p, p - static_cast<std::size_t>(l) * stride, x2, best)) break;
    }
    for (int l = 1; l <= l_max && i + l < rings; ++l) {
      if (consider(v, p, p + static_cast<std::size_t>(l) * stride, x2, best)) break;
    }
    finish(p, best, best.found ? best.dz / std::sqrt(best.d2) : 0.0f);
  };
  for (int i = 0; i < rings; ++i) {
    const std::size_t row = cloud.index(i, 0);
    int j = 0;
    for (; j < std::min(simd_begin, columns); ++j) one_point(i, row, j);
#if defined(__GNUC__)
    if (simd) {
      const F4 x2v = {x2, x2, x2, x2};
      const auto s = static_cast<std::ptrdiff_t>(stride);
      const int down = std::min(l_max, i);
      const int up = std::min(l_max, rings - 1 - i);
      for (; j + 4 <= simd_end; j += 4) {
        const std::size_t p = row + static_cast<std::size_t>(j);
        std::uint32_t states;
        std::memcpy(&states, state + p, sizeof states);
        if (states == 0) continue;  // four missing points
        const Point4 pt{load4(v.x + p), load4(v.y + p), load4(v.z + p)};
        Best4 b;
        search4(v, pt, p, -1, k_max, x2v, b);
        search4(v, pt, p, 1, k_max, x2v, b);
        search4(v, pt, p, -s, down, x2v, b);
        search4(v, pt, p, s, up, x2v, b);
        // The four sines at once (lanes without a neighbour hold dz -1, d2 1).
        const F4 sine = b.dz / sqrt4(b.d2);
        for (int lane = 0; lane < 4; ++lane) {
          const std::size_t q = p + static_cast<std::size_t>(lane);
          if (state[q] == PointState::none) continue;
          Best one;
          one.found = b.found[lane] != 0;
          one.any_valid = b.any[lane] != 0;
          one.dz = b.dz[lane];
          one.d2 = b.d2[lane];
          finish(q, one, sine[lane]);
        }
      }
    }
#endif
    for (; j < columns; ++j) one_point(i, row, j);
  }
  counters.measured += measured;
  counters.flat += flat;
  counters.isolated += isolated;
}

}  // namespace trailnav::perception
