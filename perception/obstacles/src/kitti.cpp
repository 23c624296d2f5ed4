#include "trailnav/perception/kitti.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>

namespace trailnav::perception {

velodyne::RangeImageShape kitti_shape() noexcept { return {kKittiRings, kKittiColumns, 1}; }

Status load_kitti_scan(const std::string& path, std::vector<float>& buffer, velodyne::RangeImage& image,
                       KittiStats* stats) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) return Status::error(path + ": cannot open");
  std::fseek(f, 0, SEEK_END);
  const long size = std::ftell(f);
  std::fseek(f, 0, SEEK_SET);
  if (size <= 0 || size % 16 != 0) {
    std::fclose(f);
    return Status::error(path + ": " + std::to_string(size) +
                         " bytes is not a KITTI scan (a whole number of 16-byte points: float32 x, y, z, reflectance)");
  }
  buffer.resize(static_cast<std::size_t>(size) / sizeof(float));
  const std::size_t got = std::fread(buffer.data(), sizeof(float), buffer.size(), f);
  std::fclose(f);
  if (got != buffer.size()) return Status::error(path + ": short read");
  return kitti_to_range_image(buffer, path, image, stats);
}

Status kitti_to_range_image(const std::vector<float>& pts, const std::string& name, velodyne::RangeImage& image,
                            KittiStats* stats) {
  constexpr double kTwoPi = 2.0 * std::numbers::pi;
  const std::size_t n = pts.size() / 4;
  if (image.rings() != kKittiRings || image.shape().max_columns < kKittiColumns) {
    return Status::error("KITTI scans need a range image of kitti_shape()");
  }
  KittiStats local;
  local.points = n;
  // Pass 1: where each laser starts.
  std::array<std::size_t, kKittiRings + 1> start{};
  int lasers = 1;
  double travel = 0.0;
  double previous = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double az = std::atan2(static_cast<double>(pts[4 * i + 1]), static_cast<double>(pts[4 * i]));
    if (i > 0) {
      double d = az - previous;
      if (d > std::numbers::pi) d -= kTwoPi;
      if (d < -std::numbers::pi) d += kTwoPi;
      if (previous < 0.0 && az >= 0.0 && travel > 1.5 * std::numbers::pi) {
        if (lasers == kKittiRings) {
          return Status::error(name + ": more than " + std::to_string(kKittiRings) +
                               " laser sweeps (a new one starts at point " + std::to_string(i) +
                               "); not an HDL-64E scan in sensor order");
        }
        start[static_cast<std::size_t>(lasers++)] = i;
        travel = 0.0;
      } else {
        travel += d;
      }
    }
    previous = az;
  }
  start[static_cast<std::size_t>(lasers)] = n;
  if (lasers != kKittiRings) {
    return Status::error(name + ": found " + std::to_string(lasers) + " laser sweeps, expected " +
                         std::to_string(kKittiRings) + "; not an HDL-64E scan in sensor order");
  }
  // Rows by median elevation.
  std::array<double, kKittiRings> elevation{};
  std::vector<double> el;
  for (int l = 0; l < kKittiRings; ++l) {
    el.clear();
    for (std::size_t i = start[static_cast<std::size_t>(l)]; i < start[static_cast<std::size_t>(l) + 1]; ++i) {
      const double x = pts[4 * i], y = pts[4 * i + 1], z = pts[4 * i + 2];
      el.push_back(std::atan2(z, std::hypot(x, y)));
    }
    if (el.empty()) return Status::error(name + ": laser sweep " + std::to_string(l) + " has no points");
    std::nth_element(el.begin(), el.begin() + static_cast<std::ptrdiff_t>(el.size() / 2), el.end());
    elevation[static_cast<std::size_t>(l)] = el[el.size() / 2];
  }
  std::array<int, kKittiRings> order{};
  for (int l = 0; l < kKittiRings; ++l) order[static_cast<std::size_t>(l)] = l;
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return elevation[static_cast<std::size_t>(a)] < elevation[static_cast<std::size_t>(b)];
  });
  std::array<int, kKittiRings> row_of{};
  for (int r = 0; r < kKittiRings; ++r) row_of[static_cast<std::size_t>(order[static_cast<std::size_t>(r)])] = r;

  const int columns = kKittiColumns;
  const std::uint64_t sequence = image.sequence;
  image.reset(columns);
  image.mark_received(0, columns);
  image.sequence = sequence + 1;
  image.start_ns = 0;
  image.end_ns = 100'000'000;
  image.rpm = 600.0;
  for (int l = 0; l < kKittiRings; ++l) {
    const int row = row_of[static_cast<std::size_t>(l)];
    for (std::size_t i = start[static_cast<std::size_t>(l)]; i < start[static_cast<std::size_t>(l) + 1]; ++i) {
      const float x = pts[4 * i], y = pts[4 * i + 1], z = pts[4 * i + 2], r = pts[4 * i + 3];
      const float d = std::sqrt(x * x + y * y + z * z);
      if (!std::isfinite(d) || !std::isfinite(r) || d <= 0.0f) {
        ++local.invalid;
        continue;
      }
      double az = std::atan2(static_cast<double>(y), static_cast<double>(x));
      if (az < 0.0) az += kTwoPi;
      const int c = std::min(columns - 1, static_cast<int>(az / kTwoPi * columns));
      velodyne::RangeCell& cell = image.at(0, row, c);
      if (cell.valid()) {
        ++local.collisions;
        continue;
      }
      cell.x = x;
      cell.y = y;
      cell.z = z;
      cell.distance = d;
      cell.azimuth = static_cast<float>(az);
      cell.time = static_cast<float>(az / kTwoPi * 0.1);
      cell.intensity = std::clamp(r, 0.0f, 1.0f) * 255.0f;
      ++local.placed;
    }
  }
  image.finish();
  image.points = static_cast<int>(local.placed);
  if (stats != nullptr) *stats = local;
  return Status::ok();
}

}  // namespace trailnav::perception
