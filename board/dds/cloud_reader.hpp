// Point clouds in: sensor_msgs/PointCloud2 from any lidar's ROS 2 driver
// (Ouster's, Hesai's, Velodyne's) or from `trailnav replay --clouds`, on a
// plain thread of its own (never a real-time one: Cyclone allocates as it
// deserialises). Each message is read by its fields' names
// (drivers/cloud, read_pointcloud2), made a range image by the CloudImager
// (rows from the ring field, the elevation or the sensor's order; a cell's
// second point in the second layer) and published to the revolution
// readers as the Velodyne driver publishes a revolution, so the obstacle
// and terrain threads take it the same way. A message that cannot be read
// is counted with its reason (the last one kept for health) and never
// published. Every buffer is sized at creation for `max_points`; a larger
// message is refused, not grown into.
//
// Times: header.stamp is the revolution's start on the sender's clock
// (CLOCK_REALTIME, as ROS 2 stamps), the image's start_ns; the offset that
// puts it on trailnavd's reference clock is taken at each message.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "dds.hpp"
#include "sensor_msgs.h"
#include "trailnav/drivers/cloud/cloud_file.hpp"
#include "trailnav/drivers/cloud/cloud_image.hpp"
#include "trailnav/drivers/velodyne/range_image.hpp"
#include "trailnav/runtime/broadcast.hpp"
#include "trailnav/runtime/clock.hpp"
#include "trailnav/runtime/scheduler.hpp"

namespace trailnav::dds {

struct CloudReaderOptions {
  std::string topic = "points";  // DDS rt/points
  cloud::RingLayout layout;      // the sensor's rings and columns
  cloud::CloudImageOptions image;
  int layers = 2;
  std::size_t max_points = 0;  // the largest message taken; 0: rings x columns x layers
  std::size_t readers = 1;     // revolution readers (one per thread)
};

struct CloudReaderStats {
  std::uint64_t messages = 0;   // samples taken
  std::uint64_t published = 0;  // range images published
  std::uint64_t refused = 0;    // messages that could not be read (last_error says why)
  std::uint64_t points = 0;     // points in the messages read
  cloud::CloudImageStats image; // where they went, summed
  std::int64_t last_receive_ns = 0;  // host time of the newest message taken (0: none yet)
  std::string last_error;
};

class CloudReader {
 public:
  struct Created;
  static Created create(const Domain& domain, const CloudReaderOptions& options);
  ~CloudReader();
  CloudReader(const CloudReader&) = delete;
  CloudReader& operator=(const CloudReader&) = delete;

  // Reader i of the range images (i < options.readers), one per thread.
  Broadcast<velodyne::RangeImage>::Reader& revolutions(std::size_t reader = 0) noexcept {
    return revolutions_.reader(reader);
  }
  velodyne::RangeImageShape revolution_shape() const noexcept { return shape_; }
  // Signalled after each image is published, at `clock`'s now: the
  // scheduler's clock, on which an event-driven task's latency is counted
  // from the signal. Before start().
  void set_revolution_event(TaskEvent* event, const Clock& clock) noexcept {
    event_ = event;
    event_clock_ = &clock;
  }
  void start();
  void stop();
  CloudReaderStats stats() const;
  const CloudReaderOptions& options() const noexcept { return options_; }
  // One message, as the thread handles it (tests call it without DDS).
  void handle(const sensor_msgs_msg_dds__PointCloud2_& message, std::int64_t receive_ns) noexcept;

 private:
  CloudReader(const CloudReaderOptions& options, velodyne::RangeImageShape shape, std::size_t max_points);

  CloudReaderOptions options_;
  velodyne::RangeImageShape shape_;
  std::size_t max_points_;
  cloud::CloudImager imager_;
  cloud::PointCloud cloud_;
  std::vector<cloud::PointFieldView> fields_;  // room for 64
  Broadcast<velodyne::RangeImage> revolutions_;
  TaskEvent* event_ = nullptr;
  const Clock* event_clock_ = nullptr;
  std::string name_;  // the topic, for errors
  std::unique_ptr<SampleReader> input_;
  sensor_msgs_msg_dds__PointCloud2_ sample_{};
  mutable std::mutex mutex_;  // stats_ (the health thread reads them)
  CloudReaderStats stats_;
};

struct CloudReader::Created {
  std::unique_ptr<CloudReader> reader;
  std::string error;
};

}  // namespace trailnav::dds
