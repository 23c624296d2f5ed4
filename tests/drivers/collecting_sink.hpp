// A revolution sink for tests: keeps a copy of every finished revolution.
#pragma once

#include <vector>

#include "trailnav/drivers/velodyne/range_image.hpp"

namespace trailnav::test {

class CollectingSink final : public velodyne::RevolutionSink {
 public:
  explicit CollectingSink(velodyne::RangeImageShape shape) : work_(shape) {}
  velodyne::RangeImage& next_image() noexcept override { return work_; }
  void complete(velodyne::RangeImage& image) noexcept override { images.push_back(image); }
  std::vector<velodyne::RangeImage> images;

 private:
  velodyne::RangeImage work_;
};

}  // namespace trailnav::test
