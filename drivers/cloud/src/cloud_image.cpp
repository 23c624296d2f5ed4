#include "trailnav/drivers/cloud/cloud_image.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <iterator>
#include <numeric>

#include "trailnav/drivers/velodyne/model.hpp"
#include "trailnav/runtime/config.hpp"

namespace trailnav::cloud {

namespace {

constexpr int kSlopeBins = 16384;
constexpr double kTwoPi = 2.0 * std::numbers::pi;

// atan2 in [0, 2 pi) to about 1e-5 rad: a polynomial for atan on [0, 1]
// and the octant's symmetry (the column bins are 3e-3 rad wide at 2,048).
inline float azimuth(float y, float x) noexcept {
  const float ax = std::fabs(x), ay = std::fabs(y);
  const float mx = std::max(ax, ay), mn = std::min(ax, ay);
  // (No branch: mn is 0 where mx is.)
  const float a = mn / std::max(mx, std::numeric_limits<float>::min());
  const float s = a * a;
  // Minimax coefficients for atan(a), a in [0, 1].
  float r = ((((-0.0117212f * s + 0.05265332f) * s - 0.11643287f) * s + 0.19354346f) * s - 0.33262347f) * s + 0.99997726f;
  r *= a;
  // Each case computed, then chosen: selects, not branches.
  const float r1 = 1.57079637f - r;
  r = ay > ax ? r1 : r;
  const float r2 = 3.14159274f - r;
  r = x < 0.0f ? r2 : r;
  const float r3 = 6.28318548f - r;
  r = y < 0.0f ? r3 : r;
  return r >= 6.28318548f ? 0.0f : r;
}

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
      sweep_order_(layout.elevation_deg.size() + 1) {
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
  const int b = k <= 0.0f ? 0 : k >= static_cast<float>(kSlopeBins - 1) ? kSlopeBins - 1 : static_cast<int>(k);
  return slope_rows_[static_cast<std::size_t>(b)];
}

int CloudImager::row_of_elevation(float z, float horizontal) const noexcept {
  const float d = std::sqrt(z * z + horizontal * horizontal);
  return row_of_sine(d > 0.0f ? z / d : 0.0f);
}

void CloudImager::fill(const PointCloud& c, velodyne::RangeImage& image, CloudImageStats& st,
                       std::span<PointPlace> places) noexcept {
  const bool trace = places.size() >= c.size && c.size > 0;
  auto note = [&](std::size_t i, PlaceOutcome o, int row, int col) {
    if (trace) places[i] = PointPlace{static_cast<std::uint16_t>(row), static_cast<std::uint16_t>(col), o};
  };
  st = CloudImageStats{};
  const std::uint64_t sequence = image.sequence;
  image.reset(columns_);
  image.mark_received(0, columns_);
  image.sequence = sequence + 1;
  image.start_ns = 0;
  image.end_ns = static_cast<std::int64_t>(options_.period_s * 1e9);
  image.rpm = 60.0 / options_.period_s;
  const auto cols = static_cast<float>(columns_);
  const float to_column = cols / static_cast<float>(kTwoPi);
  const auto period = static_cast<float>(options_.period_s);
  st.points = c.size;
  // Times relative to the cloud's first (a file may hold absolute ones).
  double t0 = 0.0;
  if (c.has_time) {
    t0 = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < c.size; ++i) t0 = std::isfinite(c.time[i]) ? std::min(t0, c.time[i]) : t0;
    if (!std::isfinite(t0)) t0 = 0.0;
  }
  const bool use_field = options_.rings == RingSource::field || (options_.rings == RingSource::automatic && c.has_ring);
  const bool use_order = options_.rings == RingSource::order;
  // Each point's distance, sin(elevation) and azimuth column, once, in a
  // loop without branches; the passes below read them.
  if (distance_.size() < c.size) {
    distance_.resize(c.capacity());
    sine_.resize(c.capacity());
    column_.resize(c.capacity());
  }
  {
    const float* px = c.x.data();
    const float* py = c.y.data();
    const float* pz = c.z.data();
    float* dist = distance_.data();
    float* sine = sine_.data();
    std::int32_t* column = column_.data();
    const int last = columns_ - 1;
    for (std::size_t i = 0; i < c.size; ++i) {
      const float x = px[i], y = py[i], z = pz[i];
      const float d = std::sqrt(x * x + y * y + z * z);
      dist[i] = d;
      sine[i] = z / std::max(d, std::numeric_limits<float>::min());  // (0 at the origin, no branch)
      const int col = static_cast<int>(azimuth(y, x) * to_column);
      column[i] = col < last ? col : last;
    }
  }
  std::size_t sweeps = 0;
  if (use_order) {
    // Pass 1: the sweeps (a new one where the azimuth passes 0 from below
    // after more than 1.5 pi of travel: the column passes from the last
    // half's to the first's after more than three quarters of the columns)
    // and their mean sin(elevation); at most the layout's rings + 1 (the
    // extra one's points are counted bad_ring).
    const auto max_sweeps = static_cast<std::size_t>(rings_) + 1;
    sweep_start_[0] = 0;
    sweeps = 1;
    std::fill(sweep_sum_.begin(), sweep_sum_.end(), 0.0);
    std::fill(sweep_count_.begin(), sweep_count_.end(), 0);
    // Columns counted from the azimuth -pi (the column of +pi is half way).
    const int half = columns_ / 2;
    long travel = 0;
    int previous = 0;
    for (std::size_t i = 0; i < c.size; ++i) {
      const int col = column_[i];
      const int from_back = col >= half ? col - half : col + half;  // 0 at -pi
      if (i > 0) {
        int dc = from_back - previous;
        if (dc > half) dc -= columns_;
        if (dc < -half) dc += columns_;
        // The azimuth passes 0 from below: from the last half (negative) to the first.
        const bool passes_zero = previous < half && from_back >= half;
        if (passes_zero && 4 * travel > 3L * columns_ && sweeps < max_sweeps) {
          sweep_start_[sweeps++] = i;
          travel = 0;
        } else {
          travel += dc;
        }
      }
      previous = from_back;
      const float d = distance_[i];
      if (d > 0.0f && std::isfinite(d)) {
        sweep_sum_[sweeps - 1] += static_cast<double>(sine_[i]);
        ++sweep_count_[sweeps - 1];
      }
    }
    sweep_start_[sweeps] = c.size;
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
  }
  std::size_t sweep = 0;
  for (std::size_t i = 0; i < c.size; ++i) {
    if (use_order) {
      while (sweep + 1 < sweeps && i >= sweep_start_[sweep + 1]) ++sweep;
    }
    const float d = distance_[i];
    if (!std::isfinite(d) || d <= 0.0f) {
      ++st.invalid;
      note(i, PlaceOutcome::invalid, 0, 0);
      continue;
    }
    int row = 0;
    if (use_order) {
      row = sweep_row_[sweep];
      if (row < 0) {
        ++st.bad_ring;
        note(i, PlaceOutcome::bad_ring, 0, 0);
        continue;
      }
    } else if (use_field) {
      if (!c.has_ring) {
        ++st.bad_ring;
        note(i, PlaceOutcome::bad_ring, 0, 0);
        continue;
      }
      const std::uint16_t ring = c.ring[i];
      if (ring >= rings_) {
        ++st.bad_ring;
        note(i, PlaceOutcome::bad_ring, 0, 0);
        continue;
      }
      row = row_of_ring_[ring];
    } else {
      row = row_of_sine(sine_[i]);
      ++st.inferred;
    }
    const int col = column_[i];
    velodyne::RangeCell* cell = &image.at(0, row, col);
    if (cell->valid()) {
      if (layers_ < 2 || image.at(1, row, col).valid()) {
        ++st.collisions;
        note(i, PlaceOutcome::collision, row, col);
        continue;
      }
      cell = &image.at(1, row, col);
      ++st.second;
      note(i, PlaceOutcome::second, row, col);
    } else {
      ++st.placed;
      note(i, PlaceOutcome::placed, row, col);
    }
    const float x = c.x[i], y = c.y[i];
    const float az = azimuth(y, x);
    cell->x = x;
    cell->y = y;
    cell->z = c.z[i];
    cell->distance = d;
    cell->azimuth = az;
    cell->time = c.has_time ? static_cast<float>(c.time[i] - t0) : az / static_cast<float>(kTwoPi) * period;
    cell->intensity = std::clamp(c.intensity[i] * options_.intensity_scale, 0.0f, 255.0f);
  }
  image.finish();
  image.points = static_cast<int>(st.placed + st.second);
}

}  // namespace trailnav::cloud
