// Smoothing along the rings and the geometric features of thesis §7.1.2.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

#if defined(__x86_64__)
#include <immintrin.h>
#elif defined(__SSE2__)
#include <emmintrin.h>
#endif


#include "trailnav/runtime/simd_lanes.hpp"
#include "trailnav/perception/cloud.hpp"

namespace trailnav::perception {

void smooth_rings(RevolutionCloud& cloud, const FeatureParams& params) noexcept {
  smooth_rings(cloud, params, 0, cloud.columns());
}

namespace {

// The smoothing's sums are kept in fixed point, 2^-24 m, in 64-bit
// integers: exact, so a window's sum (the difference of two prefix sums)
// has the same bits wherever the prefix began, and a block of columns
// smoothed on its own matches the whole ring smoothed at once.
constexpr float kFixedScale = 16777216.0f;  // 2^24
constexpr double kFixedUnit = 1.0 / 16777216.0;
inline std::int64_t fixed(float v) noexcept { return static_cast<std::int64_t>(v * kFixedScale); }

// out[i] = the mean of a window from two prefix sums: (hi[i] - lo[i]) in
// fixed point times `scale` (kFixedUnit / the window's points), rounded to
// float; the same bits whichever way it is computed.
void window_means_one(const std::int64_t* lo, const std::int64_t* hi, int n, double scale, float* out) noexcept {
  for (int i = 0; i < n; ++i) out[i] = static_cast<float>(static_cast<double>(hi[i] - lo[i]) * scale);
}

#if defined(__GNUC__) && defined(__x86_64__)
// Four at a time, compiled for AVX2 (called only where the CPU has it).
// AVX2 has no int64 -> double conversion; a difference below 2^51 in
// magnitude converts exactly by the usual trick: added to the bits of
// 1.5 * 2^52, whose ulp is 1, then 1.5 * 2^52 taken away again as a
// double. A window's sum is 2^24 times at most 2 * half + 1 coordinates of
// a revolution (metres from its reference point, within max_range): far
// below 2^51 for any window a config allows.
__attribute__((target("avx2"))) void window_means_avx2(const std::int64_t* lo, const std::int64_t* hi, int n,
                                                       double scale, float* out) noexcept {
  const __m256i magic_bits = _mm256_set1_epi64x(0x4338000000000000LL);
  const __m256d magic = _mm256_set1_pd(6755399441055744.0);  // 1.5 * 2^52
  const __m256d sc = _mm256_set1_pd(scale);
  int i = 0;
  for (; i + 4 <= n; i += 4) {
    const __m256i a = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(hi + i));
    const __m256i b = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(lo + i));
    const __m256i d = _mm256_sub_epi64(a, b);
    const __m256d f = _mm256_sub_pd(_mm256_castsi256_pd(_mm256_add_epi64(d, magic_bits)), magic);
    _mm_storeu_ps(out + i, _mm256_cvtpd_ps(_mm256_mul_pd(f, sc)));
  }
  window_means_one(lo + i, hi + i, n - i, scale, out + i);
}
#endif

void window_means(const std::int64_t* lo, const std::int64_t* hi, int n, double scale, float* out) noexcept {
#if defined(__GNUC__) && defined(__x86_64__)
  if (cpu_has_avx2()) {
    window_means_avx2(lo, hi, n, scale, out);
    return;
  }
#endif
  window_means_one(lo, hi, n, scale, out);
}

}  // namespace

void smooth_rings(RevolutionCloud& cloud, const FeatureParams& params, int first, int end) noexcept {
  const int half = params.smoothing_half_window;
  const int columns = cloud.columns();
  first = std::max(first, 0);
  end = std::min(end, columns);
  if (first >= end) return;
  if (half <= 0) {
    for (int ring = 0; ring < cloud.rings(); ++ring) {
      const auto base = static_cast<std::ptrdiff_t>(cloud.index(ring, first));
      std::copy_n(cloud.aligned_x.begin() + base, end - first, cloud.x.begin() + base);
      std::copy_n(cloud.aligned_y.begin() + base, end - first, cloud.y.begin() + base);
      std::copy_n(cloud.aligned_z.begin() + base, end - first, cloud.z.begin() + base);
    }
    return;
  }
  // The stretch a window of the range can reach. Its ends count as segment
  // ends below: a window of a point in [first, end) is at most `half` wide,
  // so an end `half` away from it never narrows it.
  const int lo = std::max(0, first - half);
  const int hi = std::min(columns, end + half);
  std::int64_t* sx = cloud.ring_sums.data();
  const auto stride = static_cast<std::size_t>(hi - lo) + 1;
  std::int64_t* sy = sx + stride;
  std::int64_t* sz = sy + stride;
  const float jump = params.smoothing_max_jump;
  for (int ring = 0; ring < cloud.rings(); ++ring) {
    const std::size_t base = cloud.index(ring, 0);
    const PointState* st = cloud.state.data() + base;
    const float* r = cloud.range.data() + base;
    const float* px = cloud.aligned_x.data() + base;
    const float* py = cloud.aligned_y.data() + base;
    const float* pz = cloud.aligned_z.data() + base;
    float* qx = cloud.x.data() + base;
    float* qy = cloud.y.data() + base;
    float* qz = cloud.z.data() + base;
    int a = lo;
    while (a < hi) {
      if (st[a] == PointState::none) {
        ++a;
        continue;
      }
      // The segment [a, b): consecutive points without a range jump.
      int b = a + 1;
      while (b < hi && st[b] != PointState::none && std::abs(r[b] - r[b - 1]) <= jump) ++b;
      const int from = std::max(a, first), to = std::min(b, end);
      if (from < to) {
        if (b - a == 1) {
          qx[a] = px[a];
          qy[a] = py[a];
          qz[a] = pz[a];
        } else {
          // Prefix sums over the part of the segment the windows reach, in
          // registers while they run.
          const int start = std::max(a, first - half);
          const int last = std::min(b, end + half);
          const auto zero = static_cast<std::size_t>(start - lo);
          sx[zero] = sy[zero] = sz[zero] = 0;
          std::int64_t ax = 0, ay = 0, az = 0;
          for (int j = start; j < last; ++j) {
            const auto q = static_cast<std::size_t>(j - lo) + 1;
            ax += fixed(px[j]);
            ay += fixed(py[j]);
            az += fixed(pz[j]);
            sx[q] = ax;
            sy[q] = ay;
            sz[q] = az;
          }
          // Near the segment's ends a symmetric window, narrowed so the
          // average stays centred on the point, one point at a time.
          const auto narrowed = [&](int j0, int j1) {
            for (int j = j0; j < j1; ++j) {
              const int w = std::min({half, j - a, b - 1 - j});
              if (w == 0) {
                qx[j] = px[j];
                qy[j] = py[j];
                qz[j] = pz[j];
                continue;
              }
              const auto wa = static_cast<std::size_t>(j - w - lo);
              const auto wb = static_cast<std::size_t>(j + w + 1 - lo);
              const double scale = kFixedUnit / static_cast<double>(2 * w + 1);
              qx[j] = static_cast<float>(static_cast<double>(sx[wb] - sx[wa]) * scale);
              qy[j] = static_cast<float>(static_cast<double>(sy[wb] - sy[wa]) * scale);
              qz[j] = static_cast<float>(static_cast<double>(sz[wb] - sz[wa]) * scale);
            }
          };
          // Where the whole window fits (most points): the means of a run.
          const int m0 = std::max(from, a + half), m1 = std::min(to, b - half);
          if (m0 < m1) {
            narrowed(from, m0);
            const double scale = kFixedUnit / static_cast<double>(2 * half + 1);
            const auto wa = static_cast<std::size_t>(m0 - half - lo);
            const auto wb = static_cast<std::size_t>(m0 + half + 1 - lo);
            window_means(sx + wa, sx + wb, m1 - m0, scale, qx + m0);
            window_means(sy + wa, sy + wb, m1 - m0, scale, qy + m0);
            window_means(sz + wa, sz + wb, m1 - m0, scale, qz + m0);
            narrowed(m1, to);
          } else {
            narrowed(from, to);
          }
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
  const float* __restrict range;
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
// A neighbour exists where its range is above 0, the test the W-wide searches
// make too. A neighbour farther from p than `reach2` (squared) lies on another
// surface, behind or far below p, and counts as missing.
inline bool consider(const View& v, std::size_t p, std::size_t q, float x2, float reach2, Best& best) noexcept {
  if (!(v.range[q] > 0.0f)) return false;
  const float dx = v.x[q] - v.x[p];
  const float dy = v.y[q] - v.y[p];
  const float dz = v.z[q] - v.z[p];
  const float d2 = dx * dx + dy * dy + dz * dz;
  if (d2 > reach2) return false;
  best.any_valid = true;
  if (d2 <= x2) return false;
  best.offer(std::abs(dz), d2);
  return true;
}

// Along the ring, one point at a time, wrapping around a full turn.
void along_ring_portable(const View& v, std::size_t row, int j, int columns, int k_max, bool wrap, float x2,
                         float reach2, Best& best) noexcept {
  const std::size_t p = row + static_cast<std::size_t>(j);
  for (int dir = -1; dir <= 1; dir += 2) {
    for (int k = 1; k <= k_max; ++k) {
      int jj = j + dir * k;
      if (jj < 0 || jj >= columns) {
        if (!wrap) break;
        jj = jj < 0 ? jj + columns : jj - columns;
      }
      if (consider(v, p, row + static_cast<std::size_t>(jj), x2, reach2, best)) break;
    }
  }
}

// W points at a time with the compilers' generic vectors: four (SSE2 on
// x86-64, NEON on ARM) and, on x86-64 CPUs that have it, eight (AVX2, chosen
// at run time). For each direction the neighbours are visited from the
// farthest to the nearest, each farther one replacing the candidate, so what
// is left is the first farther neighbour, with no branch per point or
// neighbour. The same operations in the same order as consider(), no fused
// multiply-add: the same bits as one point at a time.
#if defined(__GNUC__)
constexpr bool kSimd = true;

// The best farther neighbour of W points so far (as Best).
template <int W>
struct BestW {
  using F = typename Lanes<W>::F;
  using I = typename Lanes<W>::I;
  F dz = F{} - 1.0f;
  F d2 = F{} + 1.0f;
  I found = I{};
  I any = I{};
};

// (Through a reference: an eight-wide vector returned by value would have a
// different ABI with and without AVX.)
template <int W>
[[gnu::always_inline]] inline void load_lanes(const float* p, typename Lanes<W>::F& v) noexcept {
  std::memcpy(&v, p, sizeof v);
}

// One direction for W consecutive points at `at`: the neighbours at
// at + step * k for k = reach .. 1.
template <int W>
[[gnu::always_inline]] inline void search_lanes(const View& v, std::size_t at, std::ptrdiff_t step, int reach, float x2,
                                                const typename Lanes<W>::F& reach2, BestW<W>& best) noexcept {
  using F = typename Lanes<W>::F;
  using I = typename Lanes<W>::I;
  F px, py, pz;
  load_lanes<W>(v.x + at, px);
  load_lanes<W>(v.y + at, py);
  load_lanes<W>(v.z + at, pz);
  F cdz = F{};
  F cd2 = F{};
  I cf = I{};
  const I magnitude = I{} + 0x7fffffff;
  for (int k = reach; k >= 1; --k) {
    const auto q = static_cast<std::size_t>(static_cast<std::ptrdiff_t>(at) + step * k);
    // A point exists where its range is above 0 (the aligner writes both
    // together): one float compare instead of widening the state bytes.
    F qr, qx, qy, qz;
    load_lanes<W>(v.range + q, qr);
    load_lanes<W>(v.x + q, qx);
    load_lanes<W>(v.y + q, qy);
    load_lanes<W>(v.z + q, qz);
    const F dx = qx - px;
    const F dy = qy - py;
    const F dz = qz - pz;
    const F d2 = dx * dx + dy * dy + dz * dz;
    const I valid = (qr > 0.0f) & (d2 <= reach2);
    const I far = valid & (d2 > x2);
    const F adz = reinterpret_cast<F>(reinterpret_cast<I>(dz) & magnitude);
    cdz = far ? adz : cdz;
    cd2 = far ? d2 : cd2;
    cf |= far;
    best.any |= valid;
  }
  // Offer this direction's first farther neighbour, as Best::offer().
  const I better = cf & (cdz > best.dz);
  best.dz = better ? cdz : best.dz;
  best.d2 = better ? cd2 : best.d2;
  best.found |= cf;
}

// The four directions of W points at p: along the ring (k_max each way) and
// across it (`down` rings below, `up` above, `stride` apart).
template <int W>
[[gnu::always_inline]] inline void search_block(const View& v, std::size_t p, int k_max, std::ptrdiff_t stride, int down,
                                                int up, float x2, float reach, BestW<W>& best) noexcept {
  typename Lanes<W>::F range;
  load_lanes<W>(v.range + p, range);
  const typename Lanes<W>::F r = range * reach;
  const typename Lanes<W>::F reach2 = r * r;
  search_lanes<W>(v, p, -1, k_max, x2, reach2, best);
  search_lanes<W>(v, p, 1, k_max, x2, reach2, best);
  search_lanes<W>(v, p, -stride, down, x2, reach2, best);
  search_lanes<W>(v, p, stride, up, x2, reach2, best);
}
#else
constexpr bool kSimd = false;
#endif

// Where the features of a point go.
struct FeatureSink {
  PointState* state;
  float* __restrict step;
  float* __restrict sin_incline;
  std::uint64_t measured = 0, flat = 0, isolated = 0;

  // `sine`: dz / sqrt(d2) when found (Eq. 7.6).
  void finish(std::size_t p, bool found, bool any_valid, float dz, float sine) noexcept {
    if (found) {
      step[p] = dz;
      sin_incline[p] = sine;
      state[p] = PointState::measured;
      ++measured;
    } else if (any_valid) {
      step[p] = 0.0f;
      sin_incline[p] = 0.0f;
      state[p] = PointState::flat;
      ++flat;
    } else {
      state[p] = PointState::isolated;
      ++isolated;
    }
  }
};

// The search geometry of one ring.
struct RowSearch {
  std::size_t row;   // index of column 0
  int k_max;
  std::ptrdiff_t stride;
  int down, up;      // rings searched below and above
  float x2;
  float reach;       // a neighbour counts up to reach * the point's range away
};

#if defined(__GNUC__)
// Writes the W points at p that exist, from the block's search and sines.
template <int W>
[[gnu::always_inline]] inline void finish_lanes(const View& v, std::size_t p, const BestW<W>& b,
                                                const typename Lanes<W>::F& sine, FeatureSink& out) noexcept {
  for (int lane = 0; lane < W; ++lane) {
    const std::size_t q = p + static_cast<std::size_t>(lane);
    if (v.st[q] == PointState::none) continue;
    out.finish(q, b.found[lane] != 0, b.any[lane] != 0, b.dz[lane], sine[lane]);
  }
}

// Columns [j, end) of a ring, four at a time; returns the first column not done.
int search_row4(const View& v, const RowSearch& r, int j, int end, FeatureSink& out) noexcept {
  for (; j + 4 <= end; j += 4) {
    const std::size_t p = r.row + static_cast<std::size_t>(j);
    std::uint32_t states;
    std::memcpy(&states, v.st + p, sizeof states);
    if (states == 0) continue;  // four missing points
    BestW<4> b;
    search_block<4>(v, p, r.k_max, r.stride, r.down, r.up, r.x2, r.reach, b);
    // The four sines at once (lanes without a neighbour hold dz -1, d2 1).
    Lanes<4>::F sine;
#if defined(__SSE2__)
    sine = b.dz / reinterpret_cast<Lanes<4>::F>(_mm_sqrt_ps(reinterpret_cast<__m128>(b.d2)));
#else
    for (int lane = 0; lane < 4; ++lane) sine[lane] = b.dz[lane] / std::sqrt(b.d2[lane]);
#endif
    finish_lanes<4>(v, p, b, sine, out);
  }
  return j;
}
#endif

#if defined(__GNUC__) && defined(__x86_64__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"  // the eight-wide vectors live only inside this AVX2 function
// The same eight at a time, compiled for AVX2 (called only when the CPU has
// it). The row loop is not one template with search_row4: the AVX square root
// can only be inlined into a function compiled for AVX, and a template
// instance is not (the eight-wide search then ran emulated, 13 ms).
__attribute__((target("avx2"))) int search_row8(const View& v, const RowSearch& r, int j, int end,
                                                 FeatureSink& out) noexcept {
  for (; j + 8 <= end; j += 8) {
    const std::size_t p = r.row + static_cast<std::size_t>(j);
    std::uint64_t states;
    std::memcpy(&states, v.st + p, sizeof states);
    if (states == 0) continue;  // eight missing points
    BestW<8> b;
    search_block<8>(v, p, r.k_max, r.stride, r.down, r.up, r.x2, r.reach, b);
    const Lanes<8>::F sine = b.dz / reinterpret_cast<Lanes<8>::F>(_mm256_sqrt_ps(reinterpret_cast<__m256>(b.d2)));
    finish_lanes<8>(v, p, b, sine, out);
  }
  return j;
}
#pragma GCC diagnostic pop
#else
int search_row8(const View&, const RowSearch&, int j, int, FeatureSink&) noexcept { return j; }
#endif

}  // namespace

bool simd_features_available() noexcept { return kSimd; }
bool wide_features_available() noexcept { return kSimd && cpu_has_avx2(); }

void compute_features(RevolutionCloud& cloud, const FeatureParams& params, FeatureCounters& counters,
                      FeatureKernel kernel) noexcept {
  compute_features(cloud, params, counters, 0, cloud.columns(), kernel);
}

void compute_features(RevolutionCloud& cloud, const FeatureParams& params, FeatureCounters& counters, int first, int end,
                      FeatureKernel kernel) noexcept {
  const int columns = cloud.columns();
  first = std::max(first, 0);
  end = std::min(end, columns);
  if (first >= end) return;
  const int rings = cloud.rings();
  const int k_max = std::min(params.ring_neighbours, std::max(columns / 2 - 1, 0));
  const int l_max = params.cross_neighbours;
  const float x2 = params.min_distance * params.min_distance;
  const auto stride = static_cast<std::size_t>(cloud.stride());
  const bool wrap = cloud.full_turn;
  const float reach = params.neighbour_reach;
  const View v{cloud.x.data(), cloud.y.data(), cloud.z.data(), cloud.range.data(), cloud.state.data()};
  FeatureSink out{cloud.state.data(), cloud.step_height.data(), cloud.sin_incline.data()};
  // The columns the W-wide search may use: k_max from both ends.
  const bool simd = kSimd && kernel != FeatureKernel::portable;
  const bool eight = simd && kernel != FeatureKernel::four_wide && cpu_has_avx2();
  const int simd_begin = simd ? k_max : columns;
  const int simd_end = simd ? columns - k_max : columns;
  auto one_point = [&](int i, std::size_t row, int j) {
    const std::size_t p = row + static_cast<std::size_t>(j);
    if (v.st[p] == PointState::none) return;
    Best best;
    const float r = v.range[p] * reach;
    const float reach2 = r * r;
    // Along the ring, each way (Eqs. 7.1, 7.2).
    along_ring_portable(v, row, j, columns, k_max, wrap, x2, reach2, best);
    // Across the rings, same column (Eqs. 7.3, 7.4).
    for (int l = 1; l <= l_max && l <= i; ++l) {
      if (consider(v, p, p - static_cast<std::size_t>(l) * stride, x2, reach2, best)) break;
    }
    for (int l = 1; l <= l_max && i + l < rings; ++l) {
      if (consider(v, p, p + static_cast<std::size_t>(l) * stride, x2, reach2, best)) break;
    }
    out.finish(p, best.found, best.any_valid, best.dz, best.found ? best.dz / std::sqrt(best.d2) : 0.0f);
  };
  for (int i = 0; i < rings; ++i) {
    const std::size_t row = cloud.index(i, 0);
    int j = first;
    for (; j < std::min(simd_begin, end); ++j) one_point(i, row, j);
#if defined(__GNUC__)
    if (simd) {
      const RowSearch r{row,  k_max, static_cast<std::ptrdiff_t>(stride), std::min(l_max, i), std::min(l_max, rings - 1 - i),
                        x2,   reach};
      const int stop = std::min(simd_end, end);
      if (eight) j = search_row8(v, r, j, stop, out);
      j = search_row4(v, r, j, stop, out);
    }
#endif
    for (; j < end; ++j) one_point(i, row, j);
  }
  const std::uint64_t measured = out.measured, flat = out.flat, isolated = out.isolated;
  counters.measured += measured;
  counters.flat += flat;
  counters.isolated += isolated;
}

}  // namespace trailnav::perception
