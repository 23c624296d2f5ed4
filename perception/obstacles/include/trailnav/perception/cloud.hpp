// One lidar revolution as a gravity-aligned point image, its smoothing along
// the rings, and the geometric features of thesis §7.1.2.
//
// The image keeps the range image's structure: row i is a ring (0 = lowest
// elevation), column j an azimuth bin, stored as separate arrays (x, y, z,
// ...) so the per-point loops stream through memory. Coordinates are in the
// gravity-aligned odometry frame, in metres from the revolution's reference
// point (the sensor's position at the revolution's first firing, known as
// soon as the revolution begins), which keeps them small enough for floats
// far from the odometry origin.
//
// Everything here also works on a range of columns, so that trailnavd can
// take a revolution in blocks while it arrives (ObstaclePipeline).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "trailnav/drivers/cloud/cloud_image.hpp"
#include "trailnav/drivers/velodyne/range_image.hpp"
#include "trailnav/perception/obstacle_config.hpp"
#include "trailnav/perception/pose_track.hpp"

namespace trailnav::perception {

enum class PointState : std::uint8_t {
  none = 0,      // no return, a missing column, or outside the range limits
  valid = 1,     // aligned, features not computed yet
  measured = 2,  // at least one neighbour farther than x: stepHeight and incline from it
  flat = 3,      // valid neighbours, all within x: stepHeight 0, incline 0
  isolated = 4,  // no valid neighbour at all: no feature, not used
};

struct CloudShape {
  int rings = 0;
  int max_columns = 0;
  // False: only what alignment fills (the points' x, y, z, range, intensity,
  // state and the column transforms), for a cloud that is only registered
  // (the terrain's) or handed on (RevolutionCloud::hand_over_aligned()); the
  // features' and the smoothing's arrays are not allocated.
  bool features = true;
};

class RevolutionCloud {
 public:
  explicit RevolutionCloud(CloudShape shape);

  const CloudShape& shape() const noexcept { return shape_; }
  int rings() const noexcept { return shape_.rings; }
  int columns() const noexcept { return columns_; }
  int stride() const noexcept { return shape_.max_columns; }
  std::size_t index(int ring, int column) const noexcept {
    return static_cast<std::size_t>(ring) * static_cast<std::size_t>(shape_.max_columns) + static_cast<std::size_t>(column);
  }
  // Clears the first `columns` columns of every ring.
  void reset(int columns) noexcept;
  // Takes point k out: no return there. A point exists (state not `none`)
  // exactly when its range is above 0; the neighbour searches test the
  // range, a float compare, instead of widening the state bytes.
  void remove(std::size_t k) noexcept {
    state[k] = PointState::none;
    range[k] = 0.0f;
  }

  // Per point (index()).
  // The coordinates the features and the maps use: smoothed (smooth_rings())
  // in a cloud with features, as aligned in one without.
  std::vector<float> x, y, z;
  std::vector<float> range;          // m, as measured; 0 exactly where state is `none`
  std::vector<float> intensity;      // 0..255
  std::vector<float> step_height;    // m (Eq. 7.5)
  std::vector<float> sin_incline;    // sin of the incline (Eq. 7.6)
  std::vector<PointState> state;
  // A cloud with features: the coordinates as aligned (CloudAligner writes
  // them here; smooth_rings() reads them and writes x, y, z).
  std::vector<float> aligned_x, aligned_y, aligned_z;
  std::vector<std::int64_t> ring_sums;  // smooth_rings(): prefix sums of a stretch of one ring, 3 * (max_columns + 1)
  // CloudAligner: per column, the sensor -> reference transform (rotation
  // row-major, then translation).
  static constexpr std::size_t kTransformFloats = 12;
  std::vector<float> column_transforms;
  // A point of the sensor frame fired in column `c`, in this revolution's
  // frame (what alignment makes of it).
  struct Point {
    float x, y, z;
  };
  static Point transform(const float* t, float px, float py, float pz) noexcept {
    return {t[0] * px + t[1] * py + t[2] * pz + t[9], t[3] * px + t[4] * py + t[5] * pz + t[10],
            t[6] * px + t[7] * py + t[8] * pz + t[11]};
  }
  Point to_reference(int c, float px, float py, float pz) const noexcept {
    return transform(column_transforms.data() + static_cast<std::size_t>(c) * kTransformFloats, px, py, pz);
  }

  // The revolution.
  double ref_x = 0.0;  // odometry-frame position of the reference point
  double ref_y = 0.0;
  double ref_z = 0.0;
  double start_robot_x = 0.0;  // odometry-frame position of the robot at the revolution's first firing
  double start_robot_y = 0.0;
  double robot_x = 0.0;  // odometry-frame pose of the robot at the end of the revolution (CloudAligner::finish)
  double robot_y = 0.0;
  double robot_yaw = 0.0;
  double robot_z = 0.0, robot_roll = 0.0, robot_pitch = 0.0;
  std::int64_t time_ns = 0;  // end of the revolution, on the lidar's clock (its start until CloudAligner::finish)
  std::int64_t start_ns = 0;  // its first firing, same clock
  std::int64_t clock_offset_ns = 0;  // reference clock minus the lidar's (RangeImage::clock_offset_ns)
  std::uint64_t sequence = 0;
  bool full_turn = false;  // the columns close the circle: the last column neighbours the first

  // Gives `to` this revolution's points as aligned, before smoothing: its
  // x, y, z trade places with aligned_x/y/z, its range, intensity and state
  // with these (pointers only: no copy, no allocation), and it takes the
  // revolution's fields. Call after the last look at this cloud's points:
  // its range, intensity and state are `to`'s old ones then, until the next
  // alignment resets them. Same rings and max_columns.
  void hand_over_aligned(RevolutionCloud& to) noexcept;

 private:
  CloudShape shape_;
  int columns_ = 0;
};

// What the obstacle thread hands the terrain thread for each revolution it
// takes (trailnavd): the points as aligned, or why there are none.
struct AlignedRevolution {
  enum class Outcome : std::uint8_t {
    aligned,      // `cloud` holds the revolution's points
    no_odometry,  // not aligned: the odometry did not know the robot's motion
    pose_late,    // not aligned: the pose did not reach the revolution's end in time
  };
  explicit AlignedRevolution(CloudShape shape) : cloud(CloudShape{shape.rings, shape.max_columns, false}) {}
  RevolutionCloud cloud;
  std::uint64_t sequence = 0;  // RangeImage::sequence
  std::int64_t reference_end_ns = 0;
  Outcome outcome = Outcome::aligned;
};

struct AlignCounters {
  std::uint64_t points = 0;         // valid cells read from range images
  std::uint64_t out_of_range = 0;   // outside [min_range, max_range]
  std::uint64_t pose_interpolated = 0;  // columns with an interpolated pose
  std::uint64_t pose_clamped = 0;       // columns outside the pose history (nearest pose used)
  std::uint64_t no_pose = 0;            // revolutions aligned with the fixed orientation
  std::uint64_t collisions = 0;         // points whose azimuth column a point of their ring already took: dropped
  std::uint64_t self_hits = 0;          // returns inside features.self_box (the robot itself): dropped
  std::uint64_t beyond_spread = 0;      // points farther from their firing's column than RangeImage::azimuth_spread: dropped
};

// What became of a range-image point (layer 0) in alignment, when the
// offline tools ask (CloudAligner::keep_fates): its cloud index (>= 0), or
// one of these.
enum AlignFate : std::int32_t {
  kFateNoReturn = -1,       // no return there, or its column was not received
  kFateOutOfRange = -2,     // outside [min_range, max_range]
  kFateSelf = -3,           // inside features.self_box
  kFateBeyondSpread = -4,   // farther from its firing's column than the spread
  kFateCollision = -5,      // its azimuth column already had a point of its ring
};

// Range image -> gravity-aligned cloud, compensating the sensor's motion
// column by column (the pose at each column's firing) when a pose history is
// given. Writes x, y, z of a cloud without features, aligned_x/y/z of one
// with them.
class CloudAligner {
 public:
  CloudAligner(const MountParams& mount, const FeatureParams& features) noexcept;

  // The whole revolution: begin(), align_columns() over every column, finish().
  // `poses` may be null or empty: the fixed orientation is used, at the
  // odometry origin. Reads layer 0 (the strongest return).
  void align(const velodyne::RangeImage& image, const PoseTrack* poses, RevolutionCloud& out) noexcept;

  // In parts, for a revolution still arriving: begin() once its first firing
  // is in `image` (resets `out`, takes the reference from the pose then);
  // align_columns() for the firings of columns [first, end), in increasing
  // order, each range once, after the assembler has passed them; finish()
  // when the revolution is complete (its end time and the robot's pose then).
  // The same `poses` throughout.
  void begin(const velodyne::RangeImage& image, const PoseTrack* poses, RevolutionCloud& out) noexcept;
  void align_columns(const velodyne::RangeImage& image, const PoseTrack* poses, int first, int end,
                     RevolutionCloud& out) noexcept;
  void finish(const velodyne::RangeImage& image, const PoseTrack* poses, RevolutionCloud& out) noexcept;
  // A point-cloud file's scan straight from its cells (cloud::CloudImager::
  // index()), without a range image, at the fixed orientation (a scan has
  // no pose history): the same points, bits, fates and counters as align()
  // without poses over the image CloudImager::fill() makes of that cloud
  // (test), at about a third of the time of fill() and align() together.
  void align_scan(const cloud::ScanCells& scan, RevolutionCloud& out) noexcept;

  // Of the revolution begun: how many columns a point may land from its
  // firing's column, either way (from RangeImage::azimuth_spread).
  int spread_columns() const noexcept { return spread_columns_; }

  const AlignCounters& counters() const noexcept { return counters_; }

  // Keep, per range-image cell of layer 0 (index ring * `stride` + column),
  // what became of its point (AlignFate or the cloud index) in `fates`
  // (rings * stride long, the caller's; null: not kept). begin() resets it.
  void keep_fates(std::int32_t* fates, int stride, std::size_t size) noexcept {
    fates_ = fates;
    fate_stride_ = stride;
    fate_size_ = size;
  }

 private:
  static void set_robot(const Pose& p, RevolutionCloud& out) noexcept;
  // begin() from what a revolution's start needs.
  void begin_at(int columns, std::int64_t start_ns, std::int64_t clock_offset_ns, double azimuth_spread,
                std::int64_t reference_start_ns, const PoseTrack* poses, RevolutionCloud& out) noexcept;
  // A column's sensor -> reference transform (`t`: kTransformFloats) at pose p.
  void set_column_transform(const Pose& p, float* t, const RevolutionCloud& out) const noexcept;
  // Columns [first, end) of the first `rings` rings into `out`, each point
  // to the column of its azimuth; fetch(ring, column, CellPoint&) gives a
  // firing's point, false where there is none (defined in cloud.cpp).
  // kOneTransform: every column has the first one's transform.
  template <bool kOneTransform, class Fetch>
  void place_rows(int rings, int first, int end, double cut_azimuth, Fetch&& fetch, RevolutionCloud& out) noexcept;

  float mount_r_[9];  // sensor -> robot
  float mount_t_[3];
  double fixed_roll_ = 0.0;
  double fixed_pitch_ = 0.0;
  float min_range_ = 0.0f;
  float max_range_ = 0.0f;
  bool self_filter_ = false;
  std::array<float, 6> self_box_{};
  AlignCounters counters_;
  // The revolution begun.
  int columns_ = 0;
  int spread_columns_ = 0;
  bool moving_ = false;
  Pose fixed_pose_{};
  std::int32_t* fates_ = nullptr;
  int fate_stride_ = 0;
  std::size_t fate_size_ = 0;
};

struct FeatureCounters {
  std::uint64_t measured = 0;
  std::uint64_t flat = 0;
  std::uint64_t isolated = 0;
};

// Averages close-by points along each ring with a sliding window of
// 2 * half_window + 1 points, constant cost per point. A window never
// reaches across a missing point or a range jump larger than
// `smoothing_max_jump` (an object's edge), so edges stay sharp. Reads the
// aligned coordinates (aligned_x/y/z), writes the smoothed ones (x, y, z).
// The columns [first, end) of every ring (all by default); they depend on
// the aligned points of half_window + 1 columns either side (not across the
// cut), and are the same bits whichever range they were smoothed in.
void smooth_rings(RevolutionCloud& cloud, const FeatureParams& params) noexcept;
void smooth_rings(RevolutionCloud& cloud, const FeatureParams& params, int first, int end) noexcept;

// How compute_features() searches: `fastest` takes eight points at once on
// x86-64 CPUs with AVX2 (checked at run time), else four (SSE2 on x86-64,
// NEON on ARM); `four_wide` always four; `portable` one point and one
// neighbour at a time. All give bit-identical results (test).
enum class FeatureKernel : std::uint8_t { fastest, four_wide, portable };
bool simd_features_available() noexcept;  // four at a time
bool wide_features_available() noexcept;  // eight at a time (AVX2)

// stepHeight (Eq. 7.5) and sin(incline) (Eq. 7.6) for every valid point from
// the first neighbour farther than x in each of the four directions (Eqs.
// 7.1-7.4): at most 2 (K + L) comparisons per point.
void compute_features(RevolutionCloud& cloud, const FeatureParams& params, FeatureCounters& counters,
                      FeatureKernel kernel = FeatureKernel::fastest) noexcept;
// The columns [first, end) of every ring: they depend on the smoothed points
// of ring_neighbours columns either side (around the cut on a full turn).
void compute_features(RevolutionCloud& cloud, const FeatureParams& params, FeatureCounters& counters, int first, int end,
                      FeatureKernel kernel = FeatureKernel::fastest) noexcept;

}  // namespace trailnav::perception
