// Fuzzes the point-cloud readers (drivers/cloud): the first byte picks the
// format (KITTI .bin, PCD, PLY, or a sensor_msgs/PointCloud2), the rest is
// the file, or for a PointCloud2 its sizes and fields then its data:
// height u32, width u32, point_step u32, row_step u32, is_bigendian u8,
// fields u8, each field (name length u8, name, offset u32, datatype u8,
// count u32), then the data bytes. Any bytes give a cloud or a message,
// never a crash; a refused input leaves an empty cloud, a read one holds
// as many points as its header or size says.
#include <array>
#include <cstdint>
#include <cstring>
#include <span>
#include <string_view>

#include "check.hpp"

#include "trailnav/drivers/cloud/cloud_file.hpp"

using namespace trailnav::cloud;

namespace {

// Takes a T from the front of `in`; false when too few bytes are left.
template <typename T>
bool take(std::span<const std::uint8_t>& in, T& v) {
  if (in.size() < sizeof v) return false;
  std::memcpy(&v, in.data(), sizeof v);
  in = in.subspan(sizeof v);
  return true;
}

int pointcloud2(std::span<const std::uint8_t> in, PointCloud& cloud) {
  PointCloud2View m;
  std::uint8_t big = 0, count = 0;
  if (!take(in, m.height) || !take(in, m.width) || !take(in, m.point_step) || !take(in, m.row_step) || !take(in, big) ||
      !take(in, count)) {
    return 0;
  }
  m.is_bigendian = big & 1;
  std::array<PointFieldView, 16> fields;
  std::size_t n = 0;
  for (; n < count && n < fields.size(); ++n) {
    std::uint8_t length = 0;
    if (!take(in, length) || in.size() < length) return 0;
    fields[n].name = std::string_view(reinterpret_cast<const char*>(in.data()), length);
    in = in.subspan(length);
    if (!take(in, fields[n].offset) || !take(in, fields[n].datatype) || !take(in, fields[n].count)) return 0;
  }
  m.fields = std::span<const PointFieldView>(fields.data(), n);
  m.data = in;
  const trailnav::Status st = read_pointcloud2(m, "fuzz", cloud);
  if (!st) {
    check(cloud.size == 0);
    check(!st.message().empty());
    return 0;
  }
  check(cloud.size == static_cast<std::size_t>(m.height) * m.width);
  check(cloud.size <= kMaxPoints);
  check(static_cast<std::uint64_t>(m.height) * m.row_step <= m.data.size());
  return 0;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  static PointCloud cloud;
  static CloudScratch scratch;
  const std::span<const std::uint8_t> bytes(data + 1, size - 1);
  if (data[0] % 4 == 3) return pointcloud2(bytes, cloud);
  const auto format = static_cast<CloudFormat>(data[0] % 4);
  const trailnav::Status st = read_cloud(bytes, format, "fuzz", cloud, scratch);
  if (!st) {
    check(cloud.size == 0);
    check(!st.message().empty());
    return 0;
  }
  check(cloud.size <= kMaxPoints);
  check(cloud.size <= cloud.capacity());
  if (format == CloudFormat::kitti_bin) check(cloud.size * 16 == bytes.size());
  return 0;
}
