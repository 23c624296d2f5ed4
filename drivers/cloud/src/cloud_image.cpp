#include "trailnav/drivers/cloud/cloud_image.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numbers>
#include <iterator>
#include <numeric>

#include "trailnav/drivers/velodyne/model.hpp"
#include "trailnav/runtime/config.hpp"
#include "trailnav/runtime/simd_lanes.hpp"

#if defined(__SSE2__) && defined(__x86_64__)
#include <immintrin.h>
#endif

namespace trailnav::cloud {

namespace {

constexpr int kSlopeBins = 16384;
constexpr double kTwoPi = 2.0 * std::numbers::pi;

// A point with a return: a finite distance above 0 (false for NaN).
inline bool has_return(float d) noexcept { return d > 0.0f && d <= std::numeric_limits<float>::max(); }

// Per point: the distance, sin(elevation) (0 at the origin), the azimuth
// and its column (at most `last`).
struct PolarOut {
  float* distance;
  float* sine;
  float* azimuth;
  std::int32_t* column;
};

// W points at a time (eight with AVX2 where the CPU has it, four with SSE2,
// one for the rest): the same operations in the same order whatever W, so
// the same bits. atan2 in [0, 2 pi) to about 1e-5 rad (the column bins are
// 3e-3 rad wide at 2,048): a polynomial for atan on [0, 1] and the octant's
// symmetry, each case computed, then chosen (selects, not branches). The
// square root is the caller's (an intrinsic of its width, which inlines only
// into a function compiled for it; this template is inlined into each).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"  // eight-wide vectors live only inside the AVX2 function

template <int W>
[[gnu::always_inline]] inline void polar_lanes(typename Lanes<W>::F x, typename Lanes<W>::F y, typename Lanes<W>::F z,
                                               typename Lanes<W>::F d, float to_column, int last, const PolarOut& out,
                                               std::size_t i) noexcept {
  using F = typename Lanes<W>::F;
  using I = typename Lanes<W>::I;
  const F tiny = F{} + std::numeric_limits<float>::min();
  const F sine = z / (d < tiny ? tiny : d);
  const I magnitude = I{} + 0x7fffffff;
  const F ax = reinterpret_cast<F>(reinterpret_cast<I>(x) & magnitude);
  const F ay = reinterpret_cast<F>(reinterpret_cast<I>(y) & magnitude);
  const F mx = ax < ay ? ay : ax;
  const F mn = ay < ax ? ay : ax;
  const F a = mn / (mx < tiny ? tiny : mx);  // (no branch: mn is 0 where mx is)
  const F s = a * a;
  // Minimax coefficients for atan(a), a in [0, 1].
  F r = ((((-0.0117212f * s + 0.05265332f) * s - 0.11643287f) * s + 0.19354346f) * s - 0.33262347f) * s + 0.99997726f;
  r *= a;
  const F r1 = 1.57079637f - r;
  r = ay > ax ? r1 : r;
  const F r2 = 3.14159274f - r;
  r = x < 0.0f ? r2 : r;
  const F r3 = 6.28318548f - r;
  r = y < 0.0f ? r3 : r;
  r = r >= 6.28318548f ? F{} : r;
  const I col = __builtin_convertvector(r * to_column, I);
  const I lastv = I{} + last;
  const I low = col < lastv ? col : lastv;
  const I c = low < 0 ? I{} : low;  // (a NaN converts to INT_MIN)
  std::memcpy(out.distance + i, &d, sizeof d);
  std::memcpy(out.sine + i, &sine, sizeof sine);
  std::memcpy(out.azimuth + i, &r, sizeof r);
  std::memcpy(out.column + i, &c, sizeof c);
}

template <int W>
[[gnu::always_inline]] inline void load_lanes(const float* p, std::size_t i, typename Lanes<W>::F& v) noexcept {
  std::memcpy(&v, p + i, sizeof v);
}

// One point (the tail of a loop, or every point without the lanes).
void polar_one(const PointCloud& c, std::size_t i, float to_column, int last, const PolarOut& out) noexcept {
  Lanes<1>::F x, y, z;
  load_lanes<1>(c.x.data(), i, x);
  load_lanes<1>(c.y.data(), i, y);
  load_lanes<1>(c.z.data(), i, z);
  const Lanes<1>::F d{std::sqrt(x[0] * x[0] + y[0] * y[0] + z[0] * z[0])};
  polar_lanes<1>(x, y, z, d, to_column, last, out, i);
}

#if defined(__SSE2__) && defined(__x86_64__)

// Points [i, n) four at a time; returns the first not done.
std::size_t polar_four(const PointCloud& c, std::size_t i, std::size_t n, float to_column, int last,
                       const PolarOut& out) noexcept {
  for (; i + 4 <= n; i += 4) {
    Lanes<4>::F x, y, z;
    load_lanes<4>(c.x.data(), i, x);
    load_lanes<4>(c.y.data(), i, y);
    load_lanes<4>(c.z.data(), i, z);
    const auto d = reinterpret_cast<Lanes<4>::F>(_mm_sqrt_ps(reinterpret_cast<__m128>(x * x + y * y + z * z)));
    polar_lanes<4>(x, y, z, d, to_column, last, out, i);
  }
  return i;
}

// Eight at a time, compiled for AVX2 (called only where the CPU has it).
__attribute__((target("avx2"))) std::size_t polar_eight(const PointCloud& c, std::size_t i, std::size_t n,
                                                        float to_column, int last, const PolarOut& out) noexcept {
  for (; i + 8 <= n; i += 8) {
    Lanes<8>::F x, y, z;
    load_lanes<8>(c.x.data(), i, x);
    load_lanes<8>(c.y.data(), i, y);
    load_lanes<8>(c.z.data(), i, z);
    const auto d = reinterpret_cast<Lanes<8>::F>(_mm256_sqrt_ps(reinterpret_cast<__m256>(x * x + y * y + z * z)));
    polar_lanes<8>(x, y, z, d, to_column, last, out, i);
  }
  return i;
}
#endif
#pragma GCC diagnostic pop

}  // namespace

RingLayout uniform_ring_layout(std::string name, int rings, double lowest_deg, double highest_deg, int columns) {
  RingLayout l;
  l.name = std::move(name);
  l.columns = columns;
  for (int r = 0; r < rings; ++r) {
    l.elevation_deg.push_back(
        static_cast<float>(rings == 1 ? lowest_deg : lowest_deg + (highest_deg - lowest_deg) * r / (rings - 1)));
  }
  return l;
}

RingLayout load_ring_layout(const std::string& path) {
  const ConfigNode root = ConfigNode::load_file(path);
  const ConfigNode l = root.map("lidar_layout");
  RingLayout layout;
  layout.name = l.has("name") ? l.string("name") : path;
  layout.columns = static_cast<int>(l.integer("columns", 16, 65535));
  const std::vector<double> e = l.number_list("elevations_deg", -90.0, 90.0);
  if (e.empty() || e.size() > 1024) l.fail("elevations_deg", "needs one elevation per ring (1 to 1,024 rings)");
  for (double v : e) layout.elevation_deg.push_back(static_cast<float>(v));
  l.reject_unknown_keys();
  return layout;
}

std::optional<RingLayout> ring_layout_named(const std::string& name, std::string& error) {
  const std::size_t dot = name.rfind('.');
  const std::string ext = dot == std::string::npos ? std::string() : name.substr(dot);
  if (ext == ".yaml" || ext == ".yml") {
    try {
      return load_ring_layout(name);
    } catch (const ConfigError& e) {
      error = e.what();
      return std::nullopt;
    }
  }
  if (auto l = ring_layout_preset(name)) return l;
  std::string presets;
  for (const std::string& n : ring_layout_presets()) presets += (presets.empty() ? "" : ", ") + n;
  error = "unknown lidar '" + name + "': a preset (" + presets + ") or a layout file (.yaml)";
  return std::nullopt;
}

std::optional<RingSource> ring_source_named(std::string_view word) noexcept {
  if (word == "automatic") return RingSource::automatic;
  if (word == "field") return RingSource::field;
  if (word == "elevation") return RingSource::elevation;
  if (word == "order") return RingSource::order;
  return std::nullopt;
}

RingLayout ring_layout_from_calibration(const velodyne::Calibration& calibration, std::string name, int columns) {
  RingLayout l;
  l.name = std::move(name);
  l.columns = columns;
  for (const velodyne::LaserCorrection& c : calibration.lasers) {
    l.elevation_deg.push_back(static_cast<float>(c.vert_correction * 180.0 / std::numbers::pi));
  }
  return l;
}

namespace {

// Hesai's default elevation tables (its published angle-correction files for
// the Pandar40P and Pandar64; each unit ships its own, closer), channel 1
// first: ring 0 is the top beam, as Hesai's drivers number the rings.
constexpr float kPandar40P[] = {
    15.21f,  11.36f,  8.387f,  5.385f,  3.368f,  2.356f,  2.016f,  1.679f,  1.341f,  1.003f,
    0.665f,  0.328f,  -0.009f, -0.347f, -0.685f, -1.023f, -1.36f,  -1.7f,   -2.037f, -2.372f,
    -2.712f, -3.047f, -3.384f, -3.722f, -4.057f, -4.392f, -4.729f, -5.063f, -5.398f, -5.733f,
    -6.735f, -7.731f, -8.732f, -9.557f, -10.704f, -11.678f, -12.646f, -13.602f, -18.561f, -24.569f};
constexpr float kPandar64[] = {
    14.708f, 10.858f, 7.885f,  4.883f,  2.866f,  1.854f,  1.686f,  1.514f,  1.348f,  1.177f,
    1.01f,   0.839f,  0.672f,  0.501f,  0.334f,  0.163f,  -0.005f, -0.174f, -0.343f, -0.511f,
    -0.682f, -0.849f, -1.019f, -1.187f, -1.358f, -1.525f, -1.696f, -1.862f, -2.034f, -2.202f,
    -2.372f, -2.539f, -2.71f,  -2.874f, -3.047f, -3.214f, -3.384f, -3.549f, -3.722f, -3.886f,
    -4.058f, -4.224f, -4.395f, -4.559f, -4.732f, -4.894f, -5.066f, -5.231f, -5.403f, -5.565f,
    -5.739f, -5.9f,   -6.072f, -6.235f, -7.237f, -8.233f, -9.234f, -10.059f, -11.206f, -12.18f,
    -13.148f, -14.104f, -19.063f, -25.071f};

// Evenly spaced beams from +half to -half degrees, ring 0 the top (Ouster's numbering).
RingLayout top_first(std::string name, int rings, double half_deg, int columns) {
  RingLayout l;
  l.name = std::move(name);
  l.columns = columns;
  for (int r = 0; r < rings; ++r) l.elevation_deg.push_back(static_cast<float>(half_deg - 2.0 * half_deg * r / (rings - 1)));
  return l;
}

}  // namespace

std::vector<std::string> ring_layout_presets() {
  std::vector<std::string> names{"VLP-16", "VLP-32C", "HDL-32E", "HDL-64E", "Pandar40P", "Pandar64"};
  for (const char* os : {"OS0", "OS1", "OS2"}) {
    for (int beams : {32, 64, 128}) names.push_back(std::string(os) + "-" + std::to_string(beams));
  }
  return names;
}

std::optional<RingLayout> ring_layout_preset(std::string_view name) {
  if (name == "Pandar40P" || name == "Pandar64") {
    // 1,800 firings a turn at 10 Hz (a block every 55.56 us): 0.2 degrees.
    RingLayout l;
    l.name = std::string(name) + " (Hesai's default table)";
    l.columns = 1800;
    if (name == "Pandar40P") l.elevation_deg.assign(std::begin(kPandar40P), std::end(kPandar40P));
    else l.elevation_deg.assign(std::begin(kPandar64), std::end(kPandar64));
    return l;
  }
  // Ouster OS0 / OS1 / OS2 with 32, 64 or 128 beams, the uniform beam
  // configuration over the nominal field of view (90, 45, 22.5 degrees), at
  // the default 1,024 columns. Units come gradient or below-horizon too, and
  // each is calibrated: its own beam_altitude_angles (a layout file) are
  // closer.
  if (name.size() >= 6 && name.substr(0, 2) == "OS" && name[3] == '-') {
    const char family = name[2];
    const std::string_view beams = name.substr(4);
    const int n = beams == "32" ? 32 : beams == "64" ? 64 : beams == "128" ? 128 : 0;
    const double half = family == '0' ? 45.0 : family == '1' ? 22.5 : family == '2' ? 11.25 : 0.0;
    if (n > 0 && half > 0.0) return top_first(std::string(name) + " (uniform, nominal)", n, half, 1024);
    return std::nullopt;
  }
  const auto model = velodyne::parse_model(name);
  if (!model) return std::nullopt;
  if (*model == velodyne::Model::hdl64e) {
    // Each HDL-64E is calibrated on its own (no built-in calibration): the
    // nominal layout, the upper block's 32 lasers from +2 deg down in steps
    // of 1/3 deg, the lower block's from -8.83 deg down in steps of 1/2 deg.
    // A unit's own file (ring_layout_from_calibration) is closer.
    RingLayout l;
    l.name = "HDL-64E (nominal)";
    l.columns = 2083;
    for (int k = 0; k < 32; ++k) l.elevation_deg.push_back(static_cast<float>(2.0 - k / 3.0));
    for (int k = 0; k < 32; ++k) l.elevation_deg.push_back(static_cast<float>(-8.83 - k * 0.5));
    return l;
  }
  const auto calibration = velodyne::builtin_calibration(*model);
  if (!calibration) return std::nullopt;
  // Columns of a revolution at 600 rpm: the models' firing rates.
  int columns = 1808;  // VLP-16 (and VLP-32C): 55.296 us a firing
  if (*model == velodyne::Model::hdl32e) columns = 2170;
  if (*model == velodyne::Model::hdl64e) columns = 2083;
  return ring_layout_from_calibration(*calibration, std::string(velodyne::model_info(*model).name), columns);
}

CloudImager::CloudImager(const RingLayout& layout, int layers, CloudImageOptions options)
    : rings_(static_cast<int>(layout.elevation_deg.size())),
      columns_(layout.columns),
      layers_(std::clamp(layers, 1, 2)),
      options_(options),
      row_of_ring_(layout.elevation_deg.size()),
      slope_rows_(kSlopeBins),
      sweep_start_(layout.elevation_deg.size() + 2),
      sweep_sum_(layout.elevation_deg.size() + 1),
      sweep_count_(layout.elevation_deg.size() + 1),
      sweep_row_(layout.elevation_deg.size() + 1),
      sweep_order_(layout.elevation_deg.size() + 1),
      held_(layout.elevation_deg.size() * static_cast<std::size_t>(std::max(layout.columns, 0))),
      held_before_(held_.size()) {
  // Rows: the rings sorted by elevation (row 0 the lowest).
  std::vector<int> order(static_cast<std::size_t>(rings_));
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return layout.elevation_deg[static_cast<std::size_t>(a)] < layout.elevation_deg[static_cast<std::size_t>(b)];
  });
  std::vector<float> slope(static_cast<std::size_t>(rings_));
  for (int row = 0; row < rings_; ++row) {
    const int ring = order[static_cast<std::size_t>(row)];
    row_of_ring_[static_cast<std::size_t>(ring)] = static_cast<std::uint16_t>(row);
    slope[static_cast<std::size_t>(row)] =
        std::sin(layout.elevation_deg[static_cast<std::size_t>(ring)] * static_cast<float>(std::numbers::pi / 180.0));
  }
  if (rings_ == 0) return;
  // The table reaches half a ring spacing beyond the outermost rings.
  const float margin = rings_ > 1 ? 0.5f * (slope.back() - slope.front()) / static_cast<float>(rings_ - 1) : 0.1f;
  slope_lo_ = slope.front() - margin;
  const float hi = slope.back() + margin;
  slope_scale_ = static_cast<float>(kSlopeBins) / (hi - slope_lo_);
  // Each bin: the ring nearest by elevation angle to the bin's centre.
  int row = 0;
  for (int b = 0; b < kSlopeBins; ++b) {
    const float t = slope_lo_ + (static_cast<float>(b) + 0.5f) / slope_scale_;
    const float e = std::asin(std::clamp(t, -1.0f, 1.0f));
    while (row + 1 < rings_ &&
           std::fabs(std::asin(slope[static_cast<std::size_t>(row + 1)]) - e) <= std::fabs(std::asin(slope[static_cast<std::size_t>(row)]) - e)) {
      ++row;
    }
    slope_rows_[static_cast<std::size_t>(b)] = static_cast<std::uint16_t>(row);
  }
}

velodyne::RangeImageShape CloudImager::shape() const noexcept { return {rings_, columns_, layers_}; }

int CloudImager::row_of_sine(float sine) const noexcept {
  const float k = (sine - slope_lo_) * slope_scale_;
  // (A NaN, a point without a return, lands in bin 0: pass 3 skips it.)
  const int b = !(k > 0.0f) ? 0 : k >= static_cast<float>(kSlopeBins - 1) ? kSlopeBins - 1 : static_cast<int>(k);
  return slope_rows_[static_cast<std::size_t>(b)];
}

int CloudImager::row_of_elevation(float z, float horizontal) const noexcept {
  const float d = std::sqrt(z * z + horizontal * horizontal);
  return row_of_sine(d > 0.0f ? z / d : 0.0f);
}

// Passes 1 and 2 of fill() and index(): each point's distance, sin(elevation),
// azimuth, column and row (or kBadRing). True when the rows came from the
// elevation.
bool CloudImager::locate(const PointCloud& c, CloudImageStats& st) noexcept {
  const auto cols = static_cast<float>(columns_);
  const float to_column = cols / static_cast<float>(kTwoPi);
  const std::size_t n = c.size;
  st.points = n;
  const bool use_field = options_.rings == RingSource::field || (options_.rings == RingSource::automatic && c.has_ring);
  const bool use_order = options_.rings == RingSource::order;
  if (distance_.size() < n) {
    distance_.resize(c.capacity());
    sine_.resize(c.capacity());
    azimuth_.resize(c.capacity());
    column_.resize(c.capacity());
    row_.resize(c.capacity());
    pass_places_.resize(c.capacity());
  }
  // Pass 1: each point's distance, sin(elevation), azimuth and column,
  // eight or four points at a time where the CPU has the lanes.
  {
    const PolarOut out{distance_.data(), sine_.data(), azimuth_.data(), column_.data()};
    const int last = columns_ - 1;
    std::size_t i = 0;
#if defined(__SSE2__) && defined(__x86_64__)
    if (options_.lanes >= 8 && cpu_has_avx2()) i = polar_eight(c, i, n, to_column, last, out);
    if (options_.lanes >= 4) i = polar_four(c, i, n, to_column, last, out);
#endif
    for (; i < n; ++i) polar_one(c, i, to_column, last, out);
  }
  // Pass 2: each point's row, or kBadRing.
  constexpr std::int16_t kBadRing = -1;
  std::int16_t* row = row_.data();
  if (use_order) {
    // The sweeps: a new one where the azimuth passes 0 from below after
    // more than 1.5 pi of travel (the column passes from the last half's to
    // the first's after more than three quarters of the columns); at most
    // the layout's rings + 1 (the extra one's points are counted bad_ring).
    // First the places the azimuth passes 0 from below (a few hundred),
    // each with the running sum u of the column steps (each wrapped to half
    // a turn) before and after it; then the sweeps from those alone: at a
    // place i, the travel since the sweep that began at s is u(i-1) - u(s).
    // Between two events (a pass, or a step that wraps) the steps add up to
    // the difference of the columns, so only the events are visited: four
    // points are checked at once for one.
    const auto max_sweeps = static_cast<std::size_t>(rings_) + 1;
    // Columns counted from the azimuth -pi (the column of +pi is half way).
    const int half = columns_ / 2;
    const auto from_back = [half](int col) { return col >= half ? col - half : col + half; };  // 0 at -pi
    std::size_t places_found = 0;
    if (n > 0) {
      const std::int32_t* column = column_.data();
      std::int64_t u = 0;  // the running sum at the last event (the first point before any)
      int fb_at = from_back(column[0]);  // that point's column from -pi
      // Point i (> 0): an event, handled in order.
      const auto visit = [&](std::size_t i) {
        const int previous = from_back(column[i - 1]), fb = from_back(column[i]);
        int dc = fb - previous;
        const bool wraps = dc > half || dc < -half;
        const bool passes_zero = previous < half && fb >= half;
        if (!wraps && !passes_zero) return;
        const std::int64_t before = u + (previous - fb_at);  // no wrap since the last event
        if (dc > half) dc -= columns_;
        if (dc < -half) dc += columns_;
        if (passes_zero) pass_places_[places_found++] = PassPlace{i, before, before + dc};
        u = before + dc;
        fb_at = fb;
      };
      std::size_t i = 1;
      using V4 = std::int32_t __attribute__((vector_size(16)));
      const V4 halfv = V4{} + half, neg_half = V4{} - half;
      for (; i + 4 <= n; i += 4) {
        V4 now, before;
        std::memcpy(&now, column + i, sizeof now);
        std::memcpy(&before, column + i - 1, sizeof before);
        now = now >= halfv ? now - halfv : now + halfv;
        before = before >= halfv ? before - halfv : before + halfv;
        const V4 step = now - before;
        const V4 event = (step > halfv) | (step < neg_half) | ((before < halfv) & (now >= halfv));
        std::uint64_t any[2];
        std::memcpy(any, &event, sizeof any);
        if ((any[0] | any[1]) == 0) continue;
        for (std::size_t k = i; k < i + 4; ++k) visit(k);
      }
      for (; i < n; ++i) visit(i);
    }
    sweep_start_[0] = 0;
    std::size_t sweeps = 1;
    std::int64_t u_start = 0;
    for (std::size_t k = 0; k < places_found && sweeps < max_sweeps; ++k) {
      const PassPlace& p = pass_places_[k];
      if (4 * (p.u_before - u_start) > 3L * columns_) {
        sweep_start_[sweeps++] = p.index;
        u_start = p.u_after;
      }
    }
    // Each sweep's mean sin(elevation) over its points with a return (four
    // sums, so the additions need not wait on each other).
    for (std::size_t k = 0; k < sweeps; ++k) {
      const std::size_t end = k + 1 < sweeps ? sweep_start_[k + 1] : n;
      double sum[4] = {0.0, 0.0, 0.0, 0.0};
      std::uint64_t count = 0;
      std::size_t i = sweep_start_[k];
      for (; i + 4 <= end; i += 4) {
        for (std::size_t l = 0; l < 4; ++l) {
          const bool ok = has_return(distance_[i + l]);
          sum[l] += ok ? static_cast<double>(sine_[i + l]) : 0.0;
          count += ok ? 1 : 0;
        }
      }
      for (; i < end; ++i) {
        const bool ok = has_return(distance_[i]);
        sum[0] += ok ? static_cast<double>(sine_[i]) : 0.0;
        count += ok ? 1 : 0;
      }
      sweep_sum_[k] = (sum[0] + sum[1]) + (sum[2] + sum[3]);
      sweep_count_[k] = count;
    }
    sweep_start_[sweeps] = n;
    st.sweeps = sweeps;
    // Rows: the first `rings_` sweeps by mean sin(elevation) (the elevation's order); a sweep beyond has none.
    const std::size_t ranked = std::min(sweeps, static_cast<std::size_t>(rings_));
    for (std::size_t k = 0; k < ranked; ++k) sweep_order_[k] = static_cast<int>(k);
    std::sort(sweep_order_.begin(), sweep_order_.begin() + static_cast<std::ptrdiff_t>(ranked), [&](int a, int b) {
      const auto ua = static_cast<std::size_t>(a), ub = static_cast<std::size_t>(b);
      const double ma = sweep_count_[ua] > 0 ? sweep_sum_[ua] / static_cast<double>(sweep_count_[ua]) : 0.0;
      const double mb = sweep_count_[ub] > 0 ? sweep_sum_[ub] / static_cast<double>(sweep_count_[ub]) : 0.0;
      return ma < mb;
    });
    // (With fewer sweeps than rings, the rows above the last stay empty.)
    for (std::size_t r = 0; r < ranked; ++r) sweep_row_[static_cast<std::size_t>(sweep_order_[r])] = static_cast<int>(r);
    for (std::size_t k = ranked; k < sweeps; ++k) sweep_row_[k] = -1;
    for (std::size_t k = 0; k < sweeps; ++k) {
      const auto r = static_cast<std::int16_t>(sweep_row_[k] < 0 ? kBadRing : sweep_row_[k]);
      std::fill(row + sweep_start_[k], row + sweep_start_[k + 1], r);
    }
  } else if (use_field) {
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint16_t ring = c.has_ring ? c.ring[i] : std::uint16_t{0xffff};
      row[i] = ring < rings_ ? static_cast<std::int16_t>(row_of_ring_[ring]) : kBadRing;
    }
  } else {
    for (std::size_t i = 0; i < n; ++i) row[i] = static_cast<std::int16_t>(row_of_sine(sine_[i]));
  }
  return !use_order && !use_field;
}

// Pass 3 of fill() and index(): each point's cell and layer, in the cloud's
// order (the first point of a cell in layer 0, the second in layer 1 while
// there are two layers, the rest counted), with `places` and the counts.
// first(i, row, column, cell) takes a cell's first point (cell: row *
// columns + column); second(i, row, column, cell) its second and returns the
// first one's distance.
template <class First, class Second>
void CloudImager::place_points(const PointCloud& c, bool inferred, CloudImageStats& st, std::span<PointPlace> places,
                               First&& first, Second&& second) noexcept {
  const std::size_t n = c.size;
  const std::int16_t* row = row_.data();
  const bool trace = places.size() >= n && n > 0;
  std::uint64_t invalid = 0, bad_ring = 0, collisions = 0, seconds = 0, placed = 0;
  std::fill(held_.begin(), held_.end(), std::uint8_t{0});
  std::uint8_t* held = held_.data();
  for (std::size_t i = 0; i < n; ++i) {
    const float d = distance_[i];
    const int r = row[i];
    const int col = column_[i];
    PlaceOutcome outcome;
    float apart = 0.0f;
    if (!has_return(d)) {
      outcome = PlaceOutcome::invalid;
      ++invalid;
    } else if (r < 0) {
      outcome = PlaceOutcome::bad_ring;
      ++bad_ring;
    } else {
      // How many points the cell holds, from the small table (reading an
      // image's cell itself waited on memory: the image is megabytes).
      const std::size_t cell = static_cast<std::size_t>(r) * static_cast<std::size_t>(columns_) + static_cast<std::size_t>(col);
      std::uint8_t& count = held[cell];
      if (count == 0) {
        first(i, r, col, cell);
        outcome = PlaceOutcome::placed;
        ++placed;
        count = 1;
      } else if (count < layers_) {
        apart = std::fabs(d - second(i, r, col, cell));
        outcome = PlaceOutcome::second;
        ++seconds;
        count = 2;
      } else {
        outcome = PlaceOutcome::collision;
        ++collisions;
      }
    }
    if (trace) {
      places[i] = outcome == PlaceOutcome::invalid || outcome == PlaceOutcome::bad_ring
                      ? PointPlace{0, 0, outcome}
                      : PointPlace{static_cast<std::uint16_t>(r), static_cast<std::uint16_t>(col), outcome, apart};
    }
  }
  st.invalid = invalid;
  st.bad_ring = bad_ring;
  st.collisions = collisions;
  st.second = seconds;
  st.placed = placed;
  // Rows found from the elevation: every point with a return.
  if (inferred) st.inferred = n - invalid;
}

void CloudImager::fill(const PointCloud& c, velodyne::RangeImage& image, CloudImageStats& st,
                       std::span<PointPlace> places, std::int64_t start_ns) noexcept {
  st = CloudImageStats{};
  const std::uint64_t sequence = image.sequence;
  // The image this imager filled last, untouched since (its sequence as
  // left): only the cells that held a point then and hold none now are
  // cleared, after pass 3 (the rest are overwritten whole); any other image
  // is cleared whole. Sweeping the whole image (8.8 MB for KITTI's two
  // layers) was a third of the fill.
  const bool known = &image == last_image_ && sequence == last_sequence_ && image.columns() == columns_ &&
                     image.layers() == layers_;
  if (known) {
    image.begin(columns_);
  } else {
    image.reset(columns_);
    std::fill(held_.begin(), held_.end(), std::uint8_t{0});
  }
  held_.swap(held_before_);
  image.mark_received(0, columns_);
  image.sequence = sequence + 1;
  image.start_ns = start_ns;
  image.end_ns = start_ns + static_cast<std::int64_t>(options_.period_s * 1e9);
  image.rpm = 60.0 / options_.period_s;
  // A point without a time of its own: its azimuth's share of the revolution.
  const auto seconds_per_rad = static_cast<float>(options_.period_s / kTwoPi);
  // Times relative to the cloud's first (a file may hold absolute ones).
  const double t0 = first_time(c);
  const bool inferred = locate(c, st);
  // Pass 3: into the image.
  const auto write = [&](std::size_t i, velodyne::RangeCell& cell) {
    const float az = azimuth_[i];
    cell = velodyne::RangeCell{c.x[i],
                               c.y[i],
                               c.z[i],
                               distance_[i],
                               az,
                               c.has_time ? static_cast<float>(c.time[i] - t0) : az * seconds_per_rad,
                               scaled_intensity(c.intensity[i]),
                               velodyne::ReturnKind::strongest};
  };
  place_points(
      c, inferred, st, places, [&](std::size_t i, int r, int col, std::size_t) { write(i, image.at(0, r, col)); },
      [&](std::size_t i, int r, int col, std::size_t) {
        const float first_distance = image.at(0, r, col).distance;
        write(i, image.at(1, r, col));
        return first_distance;
      });
  const std::uint8_t* held = held_.data();
  // The cells that held a point in the last fill and hold none now (all
  // were cleared when this image was not the last one).
  {
    const std::uint8_t* before = held_before_.data();
    for (int r = 0; r < rings_; ++r) {
      const std::size_t base = static_cast<std::size_t>(r) * static_cast<std::size_t>(columns_);
      for (int col = 0; col < columns_; ++col) {
        const std::uint8_t was = before[base + static_cast<std::size_t>(col)];
        const std::uint8_t now = held[base + static_cast<std::size_t>(col)];
        if (was <= now) continue;
        if (now == 0) image.at(0, r, col) = velodyne::RangeCell{};
        if (was == 2) image.at(1, r, col) = velodyne::RangeCell{};
      }
    }
  }
  last_image_ = &image;
  image.finish();
  image.points = static_cast<int>(st.placed + st.second);
  last_sequence_ = image.sequence;
}

ScanCells CloudImager::index(const PointCloud& c, CloudImageStats& st, std::span<PointPlace> places) noexcept {
  st = CloudImageStats{};
  const std::size_t n = c.size;
  const bool inferred = locate(c, st);
  // Sized on the first call (an imager that only fills images, trailnavd's,
  // never holds them).
  if (intensity_.size() < n) intensity_.resize(c.capacity());
  if (first_.size() != held_.size()) first_.resize(held_.size());
  for (std::size_t i = 0; i < n; ++i) intensity_[i] = scaled_intensity(c.intensity[i]);
  // Pass 3 as fill() places the points, with the cell's first point's
  // index where fill() writes the point.
  std::fill(first_.begin(), first_.end(), std::int32_t{-1});
  std::int32_t* first = first_.data();
  const float* distance = distance_.data();
  place_points(
      c, inferred, st, places,
      [first](std::size_t i, int, int, std::size_t cell) { first[cell] = static_cast<std::int32_t>(i); },
      [first, distance](std::size_t, int, int, std::size_t cell) { return distance[first[cell]]; });
  // The next fill() clears its image whole (this one's counts are not its).
  last_image_ = nullptr;
  ScanCells cells;
  cells.rings = rings_;
  cells.columns = columns_;
  cells.sequence = ++scans_;
  cells.end_ns = static_cast<std::int64_t>(options_.period_s * 1e9);
  cells.first = first_.data();
  cells.x = c.x.data();
  cells.y = c.y.data();
  cells.z = c.z.data();
  cells.distance = distance_.data();
  cells.azimuth = azimuth_.data();
  cells.intensity = intensity_.data();
  return cells;
}

}  // namespace trailnav::cloud
