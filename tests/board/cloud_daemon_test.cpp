// trailnavd with its lidar input `pointcloud2` (issue 39: the daemon takes
// any spinning lidar's points): the daemon built from a config in this
// process, the two real KITTI scans sent as sensor_msgs/PointCloud2 over a
// loopback-only DDS domain (dds::CloudSender, what `trailnav replay
// --clouds` sends), and what comes out checked: obstacle maps with the
// car's surroundings occupied and the road free, the lidar's health
// counting the clouds, and a config that names no layout refused.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "cloud_sender.hpp"
#include "daemon.hpp"
#include "dds.hpp"
#include "nav_msgs.h"
#include "robot_config.hpp"
#include "subscriber.hpp"
#include "test_data.hpp"
#include "trailnav/drivers/cloud/cloud_file.hpp"
#include "trailnav/runtime/host_clock.hpp"

using namespace trailnav;
using namespace trailnav::daemon;
namespace fs = std::filesystem;

namespace {

constexpr std::uint32_t kDomain = 93;

std::string write_config(const std::string& name, const std::string& lidar) {
  const fs::path dir = fs::temp_directory_path() / ("trailnav-cloud-daemon-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string path = (dir / name).string();
  std::ofstream c(path);
  c << "runtime: {realtime: off, lock_memory: false, log_level: warn, log_sink: stderr}\n"
    << "lidar: " << lidar << "\n"
    << "obstacles: {model: PW, mount: {translation: [0.0, 0.0, 1.73]}, map: {size: 600, resolution: 0.1}}\n"
    << "dds: {domain: " << kDomain << ", cyclone_config: loopback, health_period_s: 0.2}\n"
    << "tasks:\n"
    << "  - {name: obstacles, kind: event, budget_ms: 200.0}\n";
  return path;
}

}  // namespace

TEST(CloudDaemon, KittiScansSentAsPointCloud2BecomeObstacleMaps) {
  host_clock_start();
  const std::string path =
      write_config("kitti.yaml", "{input: pointcloud2, topic: test/kitti_points, layout: HDL-64E, columns: 2160, rings: order, "
                                 "intensity_scale: 255, max_points: 150000}");
  RobotConfigResult loaded = load_robot_config(path);
  ASSERT_TRUE(loaded.config) << loaded.error;
  auto made = Daemon::create(*loaded.config);
  ASSERT_TRUE(made.daemon) << made.error;
  Daemon& daemon = *made.daemon;
  ASSERT_TRUE(daemon.start());

  auto domain = dds::Domain::create(kDomain, dds::loopback_config());
  ASSERT_TRUE(domain.domain) << domain.error;
  auto maps = dds::Subscriber::create(*domain.domain, "trailnav/obstacle_map", &nav_msgs_msg_dds__OccupancyGrid__desc, 0);
  ASSERT_TRUE(maps.subscriber) << maps.error;
  auto sender = dds::CloudSender::create(*domain.domain, "test/kitti_points", "velodyne");
  ASSERT_TRUE(sender.sender) << sender.error;
  ASSERT_TRUE(sender.sender->wait_for_reader(10.0)) << "trailnavd's reader never matched";

  cloud::PointCloud scan[2];
  cloud::CloudScratch scratch;
  ASSERT_TRUE(cloud::load_cloud(test::shared_data("kitti/000000.bin"), scan[0], scratch));
  ASSERT_TRUE(cloud::load_cloud(test::shared_data("kitti/000001.bin"), scan[1], scratch));
  // Scans until maps come (each one waits for the last to be mapped or 2 s,
  // so a loaded machine is given time, not skipped scans).
  std::size_t grids = 0, occupied = 0, free_near = 0, known = 0;
  for (int k = 0; k < 20 && grids < 3; ++k) {
    const auto stamp = std::chrono::duration_cast<std::chrono::nanoseconds>(
                           std::chrono::system_clock::now().time_since_epoch()).count();
    ASSERT_TRUE(sender.sender->send(scan[k % 2], stamp));
    maps.subscriber->take(2.0, [&](const dds::ReceivedSample& r) {
      const auto& g = *static_cast<const nav_msgs_msg_dds__OccupancyGrid_*>(r.sample);
      ++grids;
      occupied = free_near = known = 0;
      const double res = g.info.resolution;
      for (std::uint32_t i = 0; i < g.data._length; ++i) {
        const std::int8_t v = g.data._buffer[i];
        if (v < 0) continue;
        ++known;
        if (v >= 65) ++occupied;
        // Within 5 m ahead of the car, on the road: free.
        const double x = g.info.origin.position.x + (static_cast<double>(i % g.info.width) + 0.5) * res;
        const double y = g.info.origin.position.y + (static_cast<double>(i / g.info.width) + 0.5) * res;
        if (x > 3.0 && x < 8.0 && y > -1.0 && y < 1.0 && v < 35) ++free_near;
      }
    });
  }
  daemon.stop();
  const DaemonSummary s = daemon.summary();
  std::printf("%zu obstacle maps; the last: %zu cells known, %zu occupied, %zu free on the road ahead\n", grids, known,
              occupied, free_near);
  EXPECT_GE(grids, 1u) << "no obstacle map from the point clouds";
  EXPECT_GE(s.revolutions, 1u);
  EXPECT_GE(s.maps_published, 1u);
  // The last map: the street's buildings, cars and poles occupied, the road in front free.
  EXPECT_GT(known, 20000u);
  EXPECT_GT(occupied, 500u);
  EXPECT_GT(free_near, 200u);
  fs::remove_all(fs::path(path).parent_path());
}

TEST(CloudDaemon, APointCloudInputNeedsALayout) {
  const std::string path = write_config("bad.yaml", "{input: pointcloud2, topic: points}");
  RobotConfigResult loaded = load_robot_config(path);
  EXPECT_FALSE(loaded.config);
  EXPECT_NE(loaded.error.find("layout"), std::string::npos) << loaded.error;
  const std::string path2 = write_config("bad2.yaml", "{input: pointcloud2, layout: OS9-64}");
  loaded = load_robot_config(path2);
  EXPECT_FALSE(loaded.config);
  EXPECT_NE(loaded.error.find("unknown lidar 'OS9-64'"), std::string::npos) << loaded.error;
  const std::string path3 = write_config("bad3.yaml", "{input: udp, layout: OS1-64}");
  loaded = load_robot_config(path3);
  EXPECT_FALSE(loaded.config);
  EXPECT_NE(loaded.error.find("'udp' is not one of velodyne"), std::string::npos) << loaded.error;
  fs::remove_all(fs::path(path).parent_path());
}
