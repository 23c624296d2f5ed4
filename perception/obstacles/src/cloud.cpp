#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdlib>
#include <numbers>

#include "trailnav/perception/cloud.hpp"

namespace trailnav::perception {

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// R = Rz(yaw) * Ry(pitch) * Rx(roll), row-major.
void rotation(double roll, double pitch, double yaw, double r[9]) noexcept {
  const double cr = std::cos(roll), sr = std::sin(roll);
  const double cp = std::cos(pitch), sp = std::sin(pitch);
  const double cy = std::cos(yaw), sy = std::sin(yaw);
  r[0] = cy * cp;
  r[1] = cy * sp * sr - sy * cr;
  r[2] = cy * sp * cr + sy * sr;
  r[3] = sy * cp;
  r[4] = sy * sp * sr + cy * cr;
  r[5] = sy * sp * cr - cy * sr;
  r[6] = -sp;
  r[7] = cp * sr;
  r[8] = cp * cr;
}

void multiply(const double a[9], const double b[9], double out[9]) noexcept {
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      out[i * 3 + j] = a[i * 3] * b[j] + a[i * 3 + 1] * b[3 + j] + a[i * 3 + 2] * b[6 + j];
    }
  }
}

}  // namespace

RevolutionCloud::RevolutionCloud(CloudShape shape) : shape_(shape) {
  const auto n = static_cast<std::size_t>(shape.rings) * static_cast<std::size_t>(shape.max_columns);
  x.assign(n, 0.0f);
  y.assign(n, 0.0f);
  z.assign(n, 0.0f);
  range.assign(n, 0.0f);
  intensity.assign(n, 0.0f);
  state.assign(n, PointState::none);
  column_transforms.assign(kTransformFloats * static_cast<std::size_t>(shape.max_columns), 0.0f);
  if (!shape.features) return;
  step_height.assign(n, 0.0f);
  sin_incline.assign(n, 0.0f);
  aligned_x.assign(n, 0.0f);
  aligned_y.assign(n, 0.0f);
  aligned_z.assign(n, 0.0f);
  ring_sums.assign(3 * (static_cast<std::size_t>(shape.max_columns) + 1), 0);
}

void RevolutionCloud::hand_over_aligned(RevolutionCloud& to) noexcept {
  assert(to.shape_.rings == shape_.rings && to.shape_.max_columns == shape_.max_columns && shape_.features);
  to.x.swap(aligned_x);
  to.y.swap(aligned_y);
  to.z.swap(aligned_z);
  to.range.swap(range);
  to.intensity.swap(intensity);
  to.state.swap(state);
  to.columns_ = columns_;
  to.ref_x = ref_x;
  to.ref_y = ref_y;
  to.ref_z = ref_z;
  to.start_robot_x = start_robot_x;
  to.start_robot_y = start_robot_y;
  to.robot_x = robot_x;
  to.robot_y = robot_y;
  to.robot_yaw = robot_yaw;
  to.robot_z = robot_z;
  to.robot_roll = robot_roll;
  to.robot_pitch = robot_pitch;
  to.time_ns = time_ns;
  to.start_ns = start_ns;
  to.clock_offset_ns = clock_offset_ns;
  to.sequence = sequence;
  to.full_turn = full_turn;
}

void RevolutionCloud::reset(int columns) noexcept {
  columns_ = std::clamp(columns, 0, shape_.max_columns);
  for (int i = 0; i < shape_.rings; ++i) {
    const std::size_t b = index(i, 0);
    std::fill_n(state.begin() + static_cast<std::ptrdiff_t>(b), columns_, PointState::none);
    std::fill_n(range.begin() + static_cast<std::ptrdiff_t>(b), columns_, 0.0f);
  }
}

CloudAligner::CloudAligner(const MountParams& mount, const FeatureParams& features) noexcept
    : fixed_roll_(mount.fixed_roll_deg * kDeg),
      fixed_pitch_(mount.fixed_pitch_deg * kDeg),
      min_range_(features.min_range),
      max_range_(features.max_range),
      self_filter_(features.self_box.has_value()),
      self_box_(features.self_box.value_or(std::array<float, 6>{})) {
  double r[9];
  rotation(mount.rotation_deg[0] * kDeg, mount.rotation_deg[1] * kDeg, mount.rotation_deg[2] * kDeg, r);
  for (int i = 0; i < 9; ++i) mount_r_[i] = static_cast<float>(r[i]);
  for (int i = 0; i < 3; ++i) mount_t_[i] = static_cast<float>(mount.translation[static_cast<std::size_t>(i)]);
}

void CloudAligner::begin(const velodyne::RangeImage& image, const PoseTrack* poses, RevolutionCloud& out) noexcept {
  begin_at(image.columns(), image.start_ns, image.clock_offset_ns, image.azimuth_spread, image.reference_start_ns(), poses,
           out);
}

void CloudAligner::begin_at(int columns, std::int64_t start_ns, std::int64_t clock_offset_ns, double azimuth_spread,
                            std::int64_t reference_start_ns, const PoseTrack* poses, RevolutionCloud& out) noexcept {
  columns_ = std::min(columns, out.shape().max_columns);
  // Only what the assembler sets when the revolution begins: the rest (its
  // sequence, its end) is the lidar task's to write until it is complete.
  out.reset(columns_);
  if (fates_ != nullptr) std::fill(fates_, fates_ + fate_size_, kFateNoReturn);
  out.sequence = 0;
  out.time_ns = start_ns;  // finish() sets the end
  out.start_ns = start_ns;
  out.clock_offset_ns = clock_offset_ns;
  out.full_turn = true;
  moving_ = poses != nullptr && poses->size() > 0;
  spread_columns_ = static_cast<int>(std::ceil(azimuth_spread * columns_ / (2.0 * std::numbers::pi))) + 1;

  // The reference: the sensor at the revolution's first firing.
  Pose start{};
  if (moving_) {
    // Poses are on the reference clock (docs/dds.md, "One clock").
    poses->at(reference_start_ns, start);
  } else {
    start.roll = fixed_roll_;
    start.pitch = fixed_pitch_;
    ++counters_.no_pose;
  }
  double r[9];
  rotation(start.roll, start.pitch, start.yaw, r);
  const double mt[3] = {mount_t_[0], mount_t_[1], mount_t_[2]};
  out.ref_x = start.x + r[0] * mt[0] + r[1] * mt[1] + r[2] * mt[2];
  out.ref_y = start.y + r[3] * mt[0] + r[4] * mt[1] + r[5] * mt[2];
  out.ref_z = start.z + r[6] * mt[0] + r[7] * mt[1] + r[8] * mt[2];
  out.start_robot_x = start.x;
  out.start_robot_y = start.y;
  set_robot(start, out);
  fixed_pose_ = start;
}

void CloudAligner::set_robot(const Pose& p, RevolutionCloud& out) noexcept {
  out.robot_x = p.x;
  out.robot_y = p.y;
  out.robot_yaw = p.yaw;
  out.robot_z = p.z;
  out.robot_roll = p.roll;
  out.robot_pitch = p.pitch;
}

void CloudAligner::set_column_transform(const Pose& p, float* t, const RevolutionCloud& out) const noexcept {
  double mount_r[9];
  for (int i = 0; i < 9; ++i) mount_r[i] = static_cast<double>(mount_r_[i]);
  const double mt[3] = {mount_t_[0], mount_t_[1], mount_t_[2]};
  double r[9];
  rotation(p.roll, p.pitch, p.yaw, r);
  double rt[9];
  multiply(r, mount_r, rt);
  for (int i = 0; i < 9; ++i) t[i] = static_cast<float>(rt[i]);
  t[9] = static_cast<float>(p.x + r[0] * mt[0] + r[1] * mt[1] + r[2] * mt[2] - out.ref_x);
  t[10] = static_cast<float>(p.y + r[3] * mt[0] + r[4] * mt[1] + r[5] * mt[2] - out.ref_y);
  t[11] = static_cast<float>(p.z + r[6] * mt[0] + r[7] * mt[1] + r[8] * mt[2] - out.ref_z);
}

namespace {
// A firing's point as place_rows() takes it (a range image's cell, or a
// scan's point).
struct CellPoint {
  float x, y, z, distance, azimuth, intensity;
};
}  // namespace

template <bool kOneTransform, class Fetch>
void CloudAligner::place_rows(int rings, int first, int end, double cut_azimuth, Fetch&& fetch,
                              RevolutionCloud& out) noexcept {
  // Each point goes to the column of its own azimuth: lasers with a
  // rotation correction (the HDL-64E's are several degrees) fire in one
  // column but point into another, and the features need the rings'
  // neighbours in a column to look the same way. A point goes at most
  // spread_columns_ from its firing's column (RangeImage::azimuth_spread),
  // so that a column's points are all there once the firings that far
  // past it are (trailnavd works on a revolution while it arrives).
  // kOneTransform: every column's transform is the first's (a scan without
  // poses), kept in registers.
  const int columns = columns_;
  const float* const xf = out.column_transforms.data();
  float one[RevolutionCloud::kTransformFloats];
  std::copy_n(xf, RevolutionCloud::kTransformFloats, one);
  const double columns_per_rad = columns / (2.0 * std::numbers::pi);
  const auto cut = static_cast<float>(cut_azimuth);
  const float min_r = min_range_;
  const float max_r = max_range_;
  const bool self = self_filter_;
  const std::array<float, 6> box = self_box_;
  const int spread = spread_columns_;
  const bool smoothing = out.shape().features;
  std::uint64_t points = 0, out_of_range = 0, collisions = 0, self_hits = 0, beyond = 0;
  const int fate_rows = fate_stride_ > 0 ? static_cast<int>(fate_size_ / static_cast<std::size_t>(fate_stride_)) : 0;
  for (int i = 0; i < rings; ++i) {
    const std::size_t base = out.index(i, 0);
    PointState* __restrict st = out.state.data() + base;
    float* __restrict ox = (smoothing ? out.aligned_x : out.x).data() + base;
    float* __restrict oy = (smoothing ? out.aligned_y : out.y).data() + base;
    float* __restrict oz = (smoothing ? out.aligned_z : out.z).data() + base;
    float* __restrict orange = out.range.data() + base;
    float* __restrict ointensity = out.intensity.data() + base;
    std::int32_t* __restrict fate =
        fates_ != nullptr && i < fate_rows ? fates_ + static_cast<std::size_t>(i) * static_cast<std::size_t>(fate_stride_)
                                           : nullptr;
    const int fate_end = fate != nullptr ? fate_stride_ : 0;
    for (int c = first; c < end; ++c) {
      CellPoint cell;
      if (!fetch(i, c, cell)) continue;
      ++points;
      std::int32_t outcome;
      if (cell.distance < min_r || cell.distance > max_r) {
        ++out_of_range;
        outcome = kFateOutOfRange;
      } else if (self && cell.x >= box[0] && cell.x <= box[1] && cell.y >= box[2] && cell.y <= box[3] &&
                 cell.z >= box[4] && cell.z <= box[5]) {
        ++self_hits;
        outcome = kFateSelf;
      } else {
        double rel = static_cast<double>(cell.azimuth - cut);
        if (rel < 0.0) rel += 2.0 * std::numbers::pi;
        const int target = std::min(columns - 1, static_cast<int>(rel * columns_per_rad));
        int apart = std::abs(target - c);
        apart = std::min(apart, columns - apart);
        const auto k = static_cast<std::size_t>(target);
        if (apart > spread) {
          ++beyond;
          outcome = kFateBeyondSpread;
        } else if (st[k] != PointState::none) {
          ++collisions;
          outcome = kFateCollision;
        } else {
          outcome = static_cast<std::int32_t>(base + k);
          const float* t = kOneTransform ? one : xf + static_cast<std::size_t>(c) * RevolutionCloud::kTransformFloats;
          const RevolutionCloud::Point q = RevolutionCloud::transform(t, cell.x, cell.y, cell.z);
          ox[k] = q.x;
          oy[k] = q.y;
          oz[k] = q.z;
          orange[k] = cell.distance;
          ointensity[k] = cell.intensity;
          st[k] = PointState::valid;
        }
      }
      if (c < fate_end) fate[c] = outcome;
    }
  }
  counters_.points += points;
  counters_.out_of_range += out_of_range;
  counters_.collisions += collisions;
  counters_.self_hits += self_hits;
  counters_.beyond_spread += beyond;
}

void CloudAligner::align_columns(const velodyne::RangeImage& image, const PoseTrack* poses, int first, int end,
                                 RevolutionCloud& out) noexcept {
  first = std::max(first, 0);
  end = std::min(end, columns_);
  if (first >= end) return;
  // Each column's sensor -> reference transform, computed once per column
  // from the pose at its firing; the points are then read ring by ring, the
  // order both the range image and the cloud are stored in.
  float* const xf = out.column_transforms.data();
  for (int c = first; c < end; ++c) {
    float* t = xf + static_cast<std::size_t>(c) * RevolutionCloud::kTransformFloats;
    if (image.column_state(c) != velodyne::ColumnState::received) continue;
    if (moving_) {
      Pose p{};
      if (poses->at(image.column_time_ns(c) + image.clock_offset_ns, p) == PoseLookup::interpolated) {
        ++counters_.pose_interpolated;
      } else {
        ++counters_.pose_clamped;
      }
      set_column_transform(p, t, out);
    } else {
      set_column_transform(fixed_pose_, t, out);
    }
  }
  const int rings = std::min(image.rings(), out.rings());
  place_rows<false>(
      rings, first, end, image.cut_azimuth,
      [&image](int ring, int c, CellPoint& p) {
        const velodyne::RangeCell& cell = image.row(0, ring)[static_cast<std::size_t>(c)];
        if (!cell.valid() || image.column_state(c) != velodyne::ColumnState::received) return false;
        p = CellPoint{cell.x, cell.y, cell.z, cell.distance, cell.azimuth, cell.intensity};
        return true;
      },
      out);
}

void CloudAligner::align_scan(const cloud::ScanCells& scan, RevolutionCloud& out) noexcept {
  // As align(image, nullptr) over the image fill() makes: it starts at 0
  // with no azimuth spread, every column received, no cut.
  begin_at(scan.columns, 0, 0, 0.0, 0, nullptr, out);
  float* const xf = out.column_transforms.data();
  if (columns_ > 0) set_column_transform(fixed_pose_, xf, out);
  for (int c = 1; c < columns_; ++c) {
    std::copy_n(xf, RevolutionCloud::kTransformFloats, xf + static_cast<std::size_t>(c) * RevolutionCloud::kTransformFloats);
  }
  const int rings = std::min(scan.rings, out.rings());
  const auto stride = static_cast<std::size_t>(scan.columns);
  const float* __restrict px = scan.x;
  const float* __restrict py = scan.y;
  const float* __restrict pz = scan.z;
  const float* __restrict pd = scan.distance;
  const float* __restrict pa = scan.azimuth;
  const float* __restrict pi = scan.intensity;
  const std::int32_t* __restrict firsts = scan.first;
  place_rows<true>(
      rings, 0, columns_, 0.0,
      [=](int ring, int c, CellPoint& p) {
        const std::int32_t k = firsts[static_cast<std::size_t>(ring) * stride + static_cast<std::size_t>(c)];
        if (k < 0) return false;
        const auto i = static_cast<std::size_t>(k);
        p = CellPoint{px[i], py[i], pz[i], pd[i], pa[i], pi[i]};
        return true;
      },
      out);
  out.sequence = scan.sequence;
  out.time_ns = scan.end_ns;
}

void CloudAligner::finish(const velodyne::RangeImage& image, const PoseTrack* poses, RevolutionCloud& out) noexcept {
  out.sequence = image.sequence;
  out.time_ns = image.end_ns;
  if (moving_) {
    Pose end{};
    poses->at(image.reference_end_ns(), end);
    set_robot(end, out);
  }
}

void CloudAligner::align(const velodyne::RangeImage& image, const PoseTrack* poses, RevolutionCloud& out) noexcept {
  begin(image, poses, out);
  align_columns(image, poses, 0, columns_, out);
  finish(image, poses, out);
}

}  // namespace trailnav::perception
