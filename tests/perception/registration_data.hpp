// Real data for the registration's tests and benchmarks (run from the
// repository root): a point file's points through the project's own reader
// (cloud::load_cloud), voxel-filtered copies, and the labelled SemanticKITTI
// scan (../shared/data/semantickitti, its labels through
// eval::load_semantickitti_labels) split into its largest car — class 10, the
// instance with the most points — and everything else: a movable object and
// its static surroundings for the multi-body registration.
#pragma once

#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "label_score.hpp"
#include "trailnav/drivers/cloud/cloud_file.hpp"
#include "trailnav/perception/registration/cloud.hpp"

namespace trailnav::perception::registration {

// The points of a KITTI .bin, PCD or PLY file; throws with the reader's
// message when it cannot be read.
inline std::vector<Point> points_of(const std::string& path) {
  cloud::PointCloud c(200'000);
  cloud::CloudScratch scratch;
  if (Status st = cloud::load_cloud(path, c, scratch); !st) throw std::runtime_error(st.message());
  std::vector<Point> p;
  p.reserve(c.size);
  for (std::size_t i = 0; i < c.size; ++i) p.emplace_back(c.x[i], c.y[i], c.z[i]);
  return p;
}

// KITTI scan 0 or 1 of ../shared/data/kitti.
inline std::vector<Point> kitti(int i) { return points_of("../shared/data/kitti/00000" + std::to_string(i) + ".bin"); }

inline Cloud downsampled(const std::vector<Point>& points, float voxel) {
  VoxelFilter filter(points.size());
  Cloud c;
  c.points.reserve(points.size());
  filter.filter(points, voxel, c);
  return c;
}

struct CarScene {
  std::vector<Point> world, car;
};
inline CarScene car_scene() {
  const std::vector<Point> points = points_of("../shared/data/semantickitti/000000.bin");
  std::vector<std::uint32_t> labels;
  if (Status st = eval::load_semantickitti_labels("../shared/data/semantickitti/000000.label", labels); !st) {
    throw std::runtime_error(st.message());
  }
  CarScene s;
  if (points.size() != labels.size()) return s;
  std::map<std::uint32_t, std::size_t> cars;
  for (std::uint32_t v : labels) {
    if ((v & 0xFFFFu) == 10u) ++cars[v >> 16];
  }
  std::uint32_t biggest = 0;
  std::size_t most = 0;
  for (const auto& [id, count] : cars) {
    if (count > most) {
      most = count;
      biggest = id;
    }
  }
  for (std::size_t i = 0; i < points.size(); ++i) {
    const bool is_car = (labels[i] & 0xFFFFu) == 10u && (labels[i] >> 16) == biggest;
    (is_car ? s.car : s.world).push_back(points[i]);
  }
  return s;
}

}  // namespace trailnav::perception::registration
