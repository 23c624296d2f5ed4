// Point clouds out as sensor_msgs/PointCloud2, what `trailnav replay
// --clouds` sends to a trailnavd whose lidar input is `pointcloud2`: x, y,
// z, intensity (float32), ring (uint16) and time (float64, s after the
// cloud's first point) when the cloud has them; little endian, one row,
// stamped with the time of sending (CLOCK_REALTIME, as ROS 2 stamps).
// Reliable, the newest two kept: a slow reader loses old clouds, never
// blocks the sender for long. Not for real-time threads.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "dds.hpp"
#include "sensor_msgs.h"
#include "trailnav/drivers/cloud/point_cloud.hpp"
#include "trailnav/runtime/status.hpp"

namespace trailnav::dds {

class CloudSender {
 public:
  struct Created;
  static Created create(const Domain& domain, const std::string& topic, const std::string& frame_id);
  CloudSender(const CloudSender&) = delete;
  CloudSender& operator=(const CloudSender&) = delete;

  // Waits up to `timeout_s` for a reader to match; whether one did.
  bool wait_for_reader(double timeout_s) const;
  // Waits up to `timeout_s` until every matched reader has acknowledged
  // what was sent; whether they had.
  bool wait_for_acks(double timeout_s) const;
  // One cloud, stamped `stamp_ns` (CLOCK_REALTIME).
  Status send(const cloud::PointCloud& cloud, std::int64_t stamp_ns);
  const std::string& topic() const noexcept { return writer_->topic(); }

 private:
  CloudSender() = default;
  std::string frame_;
  std::unique_ptr<Writer> writer_;
  std::vector<std::string> names_;
  std::vector<sensor_msgs_msg_dds__PointField_> fields_;
  std::vector<std::uint8_t> data_;
};

struct CloudSender::Created {
  std::unique_ptr<CloudSender> sender;
  std::string error;
};

}  // namespace trailnav::dds
