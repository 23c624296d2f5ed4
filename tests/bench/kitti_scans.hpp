// The two real KITTI scans of ../shared/data/kitti as HDL-64E range images,
// for the benchmarks (run from the repository root).
#pragma once

#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "trailnav/perception/kitti.hpp"

namespace trailnav::bench {

inline std::vector<std::unique_ptr<velodyne::RangeImage>> kitti_scans() {
  std::vector<std::unique_ptr<velodyne::RangeImage>> images;
  std::vector<float> buffer;
  for (int i = 0; i < 2; ++i) {
    images.push_back(std::make_unique<velodyne::RangeImage>(perception::kitti_shape()));
    const std::string path = "../shared/data/kitti/00000" + std::to_string(i) + ".bin";
    if (!perception::load_kitti_scan(path, buffer, *images.back())) throw std::runtime_error("cannot read " + path);
  }
  return images;
}

}  // namespace trailnav::bench
