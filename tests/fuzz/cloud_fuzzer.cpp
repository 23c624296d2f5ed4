// Fuzzes the point-cloud reader (drivers/cloud): the first byte picks the
// format (KITTI .bin, PCD, PLY), the rest is the file. Any bytes give a
// cloud or a message, never a crash; a refused file leaves an empty cloud,
// a read one holds as many points as its header or size says.
#include <cstdint>
#include <span>

#include "check.hpp"

#include "trailnav/drivers/cloud/cloud_file.hpp"

using namespace trailnav::cloud;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  static PointCloud cloud;
  static CloudScratch scratch;
  const auto format = static_cast<CloudFormat>(data[0] % 3);
  const std::span<const std::uint8_t> bytes(data + 1, size - 1);
  const trailnav::Status st = read_cloud(bytes, format, "fuzz", cloud, scratch);
  if (!st) {
    check(cloud.size == 0);
    check(!st.message().empty());
    return 0;
  }
  check(cloud.size <= kMaxPoints);
  check(cloud.size <= cloud.capacity());
  if (format == CloudFormat::kitti_bin) check(cloud.size * 16 == bytes.size());
  // Binary files hold at least a byte per point and field read.
  return 0;
}
