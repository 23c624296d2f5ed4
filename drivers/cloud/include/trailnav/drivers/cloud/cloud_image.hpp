// A point cloud as a range image (drivers/velodyne/range_image.hpp), so any
// spinning lidar's points run through the obstacle and terrain pipelines:
// each point's row is its laser ring — from the file's ring field when it
// has one, else inferred from the point's elevation and the sensor's ring
// layout — and its column the bin of its azimuth (atan2(y, x) from +x,
// counter-clockwise, as the KITTI loader has it). Every point is accounted
// for: the first in a cell fills layer 0, a second layer 1 (the image's
// second layer, as for dual returns), any further one is counted, never
// silently dropped. No allocation after the first cloud of the largest size
// (a few arrays per point, sized then).
#pragma once

#include <algorithm>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "trailnav/drivers/cloud/point_cloud.hpp"
#include "trailnav/drivers/velodyne/calibration.hpp"
#include "trailnav/drivers/velodyne/range_image.hpp"

namespace trailnav::cloud {

// A spinning lidar's rings: each one's elevation (degrees), indexed by the
// ring number its files use, and the columns of one revolution.
struct RingLayout {
  std::string name;
  std::vector<float> elevation_deg;  // by the file's ring number
  int columns = 2048;
};

// Velodyne models from their built-in calibrations ("VLP-16", "VLP-32C",
// "HDL-32E"; ring numbers: the laser ids) and the HDL-64E's nominal layout
// (its units are calibrated one by one: rings 0-31 the upper block from the
// top, 32-63 the lower). Nothing for another name.
// Also Hesai's Pandar40P and Pandar64 (its default elevation tables, ring 0
// the top beam, 1,800 columns) and Ouster's OS0, OS1 and OS2 with 32, 64 or
// 128 beams ("OS1-64": the uniform configuration over the nominal field of
// view, ring 0 the top beam, 1,024 columns).
std::optional<RingLayout> ring_layout_preset(std::string_view name);
std::vector<std::string> ring_layout_presets();  // every name ring_layout_preset() knows
// A layout from a YAML file: `lidar_layout: {name, columns, elevations_deg:
// [one per ring, by the ring number the files use]}`. ConfigError (file,
// line, key) on anything wrong.
RingLayout load_ring_layout(const std::string& path);
// A preset's name or a layout file (.yaml, .yml); nothing and `error`
// (naming the presets, or the file's line and key) otherwise.
std::optional<RingLayout> ring_layout_named(const std::string& preset_or_file, std::string& error);
RingLayout ring_layout_from_calibration(const velodyne::Calibration& calibration, std::string name, int columns);
// Evenly spaced rings from `lowest_deg` to `highest_deg` (ring 0 the lowest).
RingLayout uniform_ring_layout(std::string name, int rings, double lowest_deg, double highest_deg, int columns);

struct CloudImageStats {
  std::uint64_t points = 0;
  std::uint64_t placed = 0;        // in layer 0
  std::uint64_t second = 0;        // a second point of its cell, in layer 1
  std::uint64_t collisions = 0;    // a third or later (or a second with one layer): counted, not placed
  std::uint64_t invalid = 0;       // non-finite or at the origin
  std::uint64_t bad_ring = 0;      // a ring field beyond the layout's rings
  std::uint64_t inferred = 0;      // rows found from the elevation
  std::uint64_t sweeps = 0;        // RingSource::order: the sweeps found (the layout's rings: every point placed)
  // Several clouds' counts summed.
  CloudImageStats& operator+=(const CloudImageStats& o) noexcept {
    points += o.points;
    placed += o.placed;
    second += o.second;
    collisions += o.collisions;
    invalid += o.invalid;
    bad_ring += o.bad_ring;
    inferred += o.inferred;
    sweeps += o.sweeps;
    return *this;
  }
};

// Where a point's ring comes from.
enum class RingSource : std::uint8_t {
  automatic,  // the file's ring field when it has one, else the elevation
  field,      // the file's ring field (a file without one: every point bad_ring)
  elevation,  // the ring whose elevation is nearest the point's
  // The file keeps the sensor's order, each laser's points one sweep after
  // another (KITTI): a new ring where the azimuth passes 0 after most of a
  // turn; the sweeps ordered by their mean slope (z / horizontal distance:
  // the elevation's order). For lidars whose
  // lasers sit at different heights (the HDL-64E), where a point's
  // elevation from the origin lands in the neighbouring ring's.
  order,
};

// Where fill() put a point: its cell (row, column) and layer, or why none.
enum class PlaceOutcome : std::uint8_t {
  placed,     // layer 0 of its cell
  second,     // layer 1: its cell already had a point
  collision,  // its cell's layers were full: counted, not placed
  invalid,    // non-finite or at the origin
  bad_ring,   // its ring is not one of the layout's
};
struct PointPlace {
  std::uint16_t row = 0;
  std::uint16_t column = 0;
  PlaceOutcome outcome = PlaceOutcome::invalid;
  // second: how far (m) its distance lies from its cell's first point's
  // (known here at no cost; read back from the image later, each a miss).
  float apart = 0.0f;
};

// "automatic", "field", "elevation", "order"; nothing for another word.
std::optional<RingSource> ring_source_named(std::string_view word) noexcept;

struct CloudImageOptions {
  float intensity_scale = 1.0f;    // the file's intensity to 0..255 (KITTI's 0..1: 255)
  double period_s = 0.1;           // a revolution, for points without a time of their own
  RingSource rings = RingSource::automatic;
  // Points at a time for the polar coordinates: 8 (AVX2 where the CPU has
  // it, else 4), 4 (SSE2) or 1; the same bits whichever (a test).
  int lanes = 8;
};

// A cloud's points by cell, without a range image (CloudImager::index()):
// for a caller that takes each cell's first point straight from the cloud
// (the obstacle pipeline's path for point-cloud files, perception's
// CloudAligner::align_scan). Per cell (row * columns + column): the index of
// the cloud's first point there, -1 for none. Per point of the cloud: what
// fill() writes into its cell (distance, azimuth, intensity scaled to
// 0..255); x, y, z are the cloud's own. Valid until the imager's next
// index() or fill(), and while the cloud is unchanged.
struct ScanCells {
  int rings = 0;
  int columns = 0;
  std::uint64_t sequence = 0;  // this imager's index() calls, from 1 (as fill() counts an image's)
  std::int64_t end_ns = 0;     // the revolution's end: its period after 0 (as fill() with start_ns 0)
  const std::int32_t* first = nullptr;
  const float* x = nullptr;
  const float* y = nullptr;
  const float* z = nullptr;
  const float* distance = nullptr;
  const float* azimuth = nullptr;
  const float* intensity = nullptr;
};

class CloudImager {
 public:
  explicit CloudImager(const RingLayout& layout, int layers = 2, CloudImageOptions options = {});
  // The shape of the images fill() writes.
  velodyne::RangeImageShape shape() const noexcept;
  // Fills `image` (of shape()) from the cloud.
  void fill(const PointCloud& cloud, velodyne::RangeImage& image, CloudImageStats& stats) noexcept {
    fill(cloud, image, stats, {});
  }
  // The same, and where each point went: `places` empty, or at least
  // cloud.size long (places[i] for the cloud's point i); the revolution
  // starting at `start_ns` (its columns' times from there; a file's: 0).
  void fill(const PointCloud& cloud, velodyne::RangeImage& image, CloudImageStats& stats,
            std::span<PointPlace> places, std::int64_t start_ns = 0) noexcept;
  // The same placement as fill() (every point's row, column and layer, the
  // same `places` and stats), without writing an image: each cell's first
  // point by its index in the cloud. About a third of fill()'s time for a
  // KITTI scan (docs/obstacles.md, "Speed").
  ScanCells index(const PointCloud& cloud, CloudImageStats& stats, std::span<PointPlace> places) noexcept;
  // The row (0 = the lowest ring) of a point by its elevation alone.
  int row_of_elevation(float z, float horizontal) const noexcept;

 private:
  bool locate(const PointCloud& cloud, CloudImageStats& stats) noexcept;
  // A file's intensity as a cell holds it: scaled to 0..255.
  float scaled_intensity(float v) const noexcept { return std::clamp(v * options_.intensity_scale, 0.0f, 255.0f); }
  template <class First, class Second>
  void place_points(const PointCloud& cloud, bool inferred, CloudImageStats& stats, std::span<PointPlace> places,
                    First&& first, Second&& second) noexcept;
  int rings_;
  int columns_;
  int layers_;
  CloudImageOptions options_;
  std::vector<std::uint16_t> row_of_ring_;  // the file's ring number -> row
  int row_of_sine(float sine) const noexcept;
  // Row by sin(elevation) (z / distance): kSlopeBins bins from slope_lo_.
  std::vector<std::uint16_t> slope_rows_;
  float slope_lo_ = 0.0f, slope_scale_ = 0.0f;
  // RingSource::order: each sweep's first point, elevation sum and count, its row.
  std::vector<std::size_t> sweep_start_;
  std::vector<double> sweep_sum_;
  std::vector<std::uint64_t> sweep_count_;
  std::vector<int> sweep_row_, sweep_order_;
  // Per point of the cloud filled (grown to a larger cloud's size, once).
  std::vector<float> distance_, sine_, azimuth_;
  std::vector<std::int32_t> column_;
  std::vector<std::int16_t> row_;
  // RingSource::order: where the azimuth passes 0 from below, with the
  // running sum of the column steps before and after that point.
  struct PassPlace {
    std::size_t index;
    std::int64_t u_before, u_after;
  };
  std::vector<PassPlace> pass_places_;
  // Points in each cell (row * columns + column) this fill and the last.
  std::vector<std::uint8_t> held_, held_before_;
  // index(): each cell's first point, and each point's scaled intensity
  // (sized by its first call).
  std::vector<std::int32_t> first_;
  std::vector<float> intensity_;
  std::uint64_t scans_ = 0;
  const velodyne::RangeImage* last_image_ = nullptr;  // the image the last fill wrote
  std::uint64_t last_sequence_ = 0;                   // the sequence it left there
};

}  // namespace trailnav::cloud
