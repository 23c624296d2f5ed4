// Planar scans in: sensor_msgs/LaserScan from a 2D laser's ROS 2 driver (a
// safety laser's, a SICK's, a Hokuyo's), on a plain thread of its own (never
// a real-time one: Cyclone allocates as it deserialises). Each beam with a
// range inside [range_min, range_max] (and the config's max_range) becomes a
// point in the robot frame (the laser's mount: x, y, yaw), z = 0, handed to
// the station task's mailbox. A message that cannot be read is counted with
// its reason (the last one kept for health) and never handed over. Buffers
// are sized at creation for `max_beams`; a longer scan is refused, not grown
// into.
//
// Times: header.stamp is the scan's start on the sender's clock
// (CLOCK_REALTIME, as ROS 2 stamps), put on trailnavd's reference clock at
// each message; the scan's stamp is its last beam's (stamp + (n − 1) ·
// time_increment), where the robot was when the scan was complete.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "dds.hpp"
#include "sensor_msgs.h"
#include "trailnav/perception/registration/station_task.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/status.hpp"

namespace trailnav::dds {

struct LaserScanOptions {
  std::string topic = "scan";  // DDS rt/scan
  std::size_t max_beams = 2048;
  float max_range = 0.0f;      // m; 0: the message's range_max alone
  double mount_x = 0.0, mount_y = 0.0, mount_yaw = 0.0;  // the laser on the robot (m, rad)
};

// One message into `out` (its capacity at least max_beams): an error says
// what is wrong with the message (and nothing is written to out's points).
Status read_laser_scan(const sensor_msgs_msg_dds__LaserScan_& m, const LaserScanOptions& o, std::string_view what,
                       perception::registration::PlanarScan& out) noexcept;

struct LaserScanStats {
  std::uint64_t messages = 0;  // samples taken
  std::uint64_t handed = 0;    // scans handed to the station task
  std::uint64_t refused = 0;   // messages that could not be read (last_error says why)
  std::uint64_t beams = 0, returns = 0;  // beams in the messages read, of them returns kept
  std::int64_t last_receive_ns = 0;
  std::string last_error;
};

class LaserScanReader {
 public:
  struct Created;
  static Created create(const Domain& domain, const LaserScanOptions& options,
                        Mailbox<perception::registration::PlanarScan>& out);
  ~LaserScanReader();
  LaserScanReader(const LaserScanReader&) = delete;
  LaserScanReader& operator=(const LaserScanReader&) = delete;

  void start();
  void stop();
  LaserScanStats stats() const;
  // One message, as the thread handles it (tests call it without DDS).
  void handle(const sensor_msgs_msg_dds__LaserScan_& message, std::int64_t receive_ns) noexcept;

 private:
  LaserScanReader(const LaserScanOptions& options, Mailbox<perception::registration::PlanarScan>& out);

  LaserScanOptions options_;
  Mailbox<perception::registration::PlanarScan>& out_;
  std::string name_;
  std::unique_ptr<SampleReader> input_;
  sensor_msgs_msg_dds__LaserScan_ sample_{};
  std::uint64_t sequence_ = 0;
  mutable std::mutex mutex_;
  LaserScanStats stats_;
};

struct LaserScanReader::Created {
  std::unique_ptr<LaserScanReader> reader;
  std::string error;
};

}  // namespace trailnav::dds
