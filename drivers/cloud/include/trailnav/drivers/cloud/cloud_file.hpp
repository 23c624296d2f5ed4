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
// channel / line; time / t / timestamp / offset_time (seconds in a float
// field, nanoseconds in an integer one: Ouster's `t`, Livox's
// `offset_time`). Any scalar type is taken (int8 .. uint32, float32,
// float64) and converted. Every error names
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

// A sensor_msgs/PointCloud2 (ROS 2's point cloud message) as plain values,
// whatever carried it (trailnavd takes it from DDS): each field's name,
// byte offset in a point, datatype as ROS numbers them (1 INT8, 2 UINT8,
// 3 INT16, 4 UINT16, 5 INT32, 6 UINT32, 7 FLOAT32, 8 FLOAT64) and count.
struct PointFieldView {
  std::string_view name;
  std::uint32_t offset = 0;
  std::uint8_t datatype = 0;
  std::uint32_t count = 1;
};
struct PointCloud2View {
  std::uint32_t height = 1;  // rows (1: an unorganised cloud)
  std::uint32_t width = 0;   // points a row
  std::span<const PointFieldView> fields;
  bool is_bigendian = false;
  std::uint32_t point_step = 0;  // bytes a point
  std::uint32_t row_step = 0;    // bytes a row
  std::span<const std::uint8_t> data;
};
// Reads a PointCloud2's points, row after row, by the same field names as
// the files (a name given twice: the last). Every error says which field
// or which size is wrong (`name` for the message, e.g. its topic); the
// cloud is read whole or not at all; nothing is allocated once the cloud
// holds height x width points.
Status read_pointcloud2(const PointCloud2View& message, const std::string& name, PointCloud& out);

// Parses a file's bytes (`name` for errors).
Status read_cloud(std::span<const std::uint8_t> bytes, CloudFormat format, const std::string& name, PointCloud& out,
                  CloudScratch& scratch);
// Reads the file at `path` (its format from its extension).
Status load_cloud(const std::string& path, PointCloud& out, CloudScratch& scratch);

}  // namespace trailnav::cloud
