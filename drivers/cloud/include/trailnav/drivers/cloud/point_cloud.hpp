// Point clouds read from files (KITTI .bin, PCD, PLY): any spinning lidar's
// points, whatever wrote them, as arrays sized once. The reader takes the
// coordinates, the intensity, the laser's ring and the point's time from
// the fields a file has (their names as lidar drivers write them,
// cloud_file.hpp) and says which it found; what is missing is inferred
// later (the ring from the elevation, cloud_image.hpp) or left out.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace trailnav::cloud {

struct PointCloud {
  explicit PointCloud(std::size_t capacity = 0);
  std::size_t capacity() const noexcept { return x.size(); }

  // Structure of arrays, capacity() long; the first `size` are the points,
  // in the file's order.
  std::vector<float> x, y, z;     // m, the sensor's frame
  std::vector<float> intensity;   // as the file has it (0 when it has none)
  std::vector<std::uint16_t> ring;  // the laser's index as the file numbers it (has_ring)
  std::vector<double> time;       // s, as the file has it (has_time): relative or absolute, the file's choice
  std::size_t size = 0;
  bool has_intensity = false;
  bool has_ring = false;
  bool has_time = false;
};

// The earliest finite time of the cloud's points (their times' origin when
// they are made relative); 0 without times or without a finite one.
double first_time(const PointCloud& cloud) noexcept;

}  // namespace trailnav::cloud
