// KITTI Velodyne scans (.bin: float32 x, y, z, reflectance per point) as
// range images, so real HDL-64E geometry runs through the obstacle pipeline.
//
// The files keep the sensor's order but not the laser index: each laser's
// points come one after another, sweeping the azimuth once around. A new
// laser starts where the azimuth crosses zero from below after the current
// one has swept most of the circle (1.5 pi). The 64 lasers found are then
// sorted by their median elevation (row 0 = lowest), and each point goes to
// the column of its azimuth.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "trailnav/drivers/velodyne/range_image.hpp"
#include "trailnav/runtime/status.hpp"

namespace trailnav::perception {

inline constexpr int kKittiRings = 64;
inline constexpr int kKittiColumns = 2160;  // a little more than the densest ring's points
// The recording car around its HDL-64E (sensor frame, m: x, y, z from and
// to): its body, roof rack and mirrors, measured on the shared scans as the
// returns that sit at the same place in both. Meant as features.self_box.
inline constexpr std::array<float, 6> kKittiCarBox{-2.8f, 2.8f, -1.6f, 1.6f, -1.45f, 0.3f};

struct KittiStats {
  std::uint64_t points = 0;
  std::uint64_t placed = 0;
  std::uint64_t collisions = 0;  // two points of one ring in one column: the first is kept
  std::uint64_t invalid = 0;     // non-finite or at the origin
};

velodyne::RangeImageShape kitti_shape() noexcept;

// Reads a scan into `image` (of kitti_shape()). `buffer` is reused between
// calls. Errors name the file and what is wrong with it.
Status load_kitti_scan(const std::string& path, std::vector<float>& buffer, velodyne::RangeImage& image,
                       KittiStats* stats = nullptr);
// The same from points already in memory (x, y, z, reflectance; 4 floats each).
Status kitti_to_range_image(const std::vector<float>& points, const std::string& name, velodyne::RangeImage& image,
                            KittiStats* stats = nullptr);

}  // namespace trailnav::perception
