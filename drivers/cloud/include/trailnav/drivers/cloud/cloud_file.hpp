// Reading point-cloud files into a PointCloud:
//
//   KITTI .bin   float32 x, y, z, reflectance per point, little-endian
//   PCD (.pcd)   Point Cloud Library's format v0.7: DATA ascii, binary or
//                binary_compressed (LZF, fields one after another)
//   PLY (.ply)   format ascii, binary_little_endian or binary_big_endian;
//                the `vertex` element's properties
//
// Fields are found by name, as lidar drivers write them: x, y, z;
// intensity / reflectance / reflectivity / remission / i; ring / laser_id /
// channel / line; time / t / timestamp / offset_time. Any scalar type is
// taken (int8 .. uint32, float32, float64) and converted. Every error names
// the file, where in it (header line or point), and what is wrong; a
// file is read whole or not at all. Reading allocates nothing once the
// cloud and the scratch are large enough (they grow for a larger file; a
// caller that sizes them for its sensor up front never sees them grow).
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "trailnav/drivers/cloud/point_cloud.hpp"
#include "trailnav/runtime/status.hpp"

namespace trailnav::cloud {

// The most points one file may hold (16.8 million: a 128-beam lidar's
// revolution of 2,048 columns with two returns is half a million); a header
// that says more is refused before anything is allocated for it.
inline constexpr std::size_t kMaxPoints = std::size_t{1} << 24;

enum class CloudFormat : std::uint8_t { kitti_bin, pcd, ply };
std::string_view cloud_format_name(CloudFormat f) noexcept;  // "KITTI .bin", "PCD", "PLY"
// By the file's extension (.bin, .pcd, .ply, any case); nothing for another.
std::optional<CloudFormat> cloud_format_of(std::string_view path) noexcept;

// Buffers a reader reuses between files.
struct CloudScratch {
  std::vector<std::uint8_t> bytes;     // the file
  std::vector<std::uint8_t> inflated;  // a binary_compressed PCD's data
};

// Parses a file's bytes (`name` for errors).
Status read_cloud(std::span<const std::uint8_t> bytes, CloudFormat format, const std::string& name, PointCloud& out,
                  CloudScratch& scratch);
// Reads the file at `path` (its format from its extension).
Status load_cloud(const std::string& path, PointCloud& out, CloudScratch& scratch);

}  // namespace trailnav::cloud
