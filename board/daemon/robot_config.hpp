// One robot config (YAML) for trailnavd: the sensors and how they are
// reached, calibrations and extrinsics, the obstacle map, the task table and
// DDS. Read once at start-up; every problem is one ConfigError naming the
// file, the line and the key (docs/trailnavd.md lists every key).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "cloud_reader.hpp"
#include "scan_reader.hpp"
#include "commands.hpp"
#include "publisher.hpp"
#include "trailnav/drivers/camera/camera_driver.hpp"
#include "trailnav/drivers/can/can_driver.hpp"
#include "trailnav/drivers/gpio/gpio_driver.hpp"
#include "trailnav/drivers/gps/gps_driver.hpp"
#include "trailnav/drivers/imu/imu_driver.hpp"
#include "trailnav/drivers/velodyne/driver.hpp"
#include "trailnav/drivers/velodyne/model.hpp"
#include "trailnav/navigation/navigator/navigation_config.hpp"
#include "trailnav/navigation/pose/pose_estimator.hpp"
#include "trailnav/navigation/slam/mapping_task.hpp"
#include "trailnav/perception/obstacle_config.hpp"
#include "trailnav/perception/place/bayes_filter.hpp"
#include "trailnav/perception/place/place_task.hpp"
#include "trailnav/perception/pose_track.hpp"
#include "trailnav/perception/terrain_config.hpp"
#include "trailnav/perception/trav_config.hpp"
#include "trailnav/runtime/runtime_config.hpp"

namespace trailnav::daemon {

struct LidarSection {
  velodyne::Model model = velodyne::Model::vlp16;
  std::string calibration;  // a file, or empty: the model's built-in one
  velodyne::DriverOptions driver;
  // `input: pointcloud2`: the points come as sensor_msgs/PointCloud2 over
  // DDS (any lidar's ROS 2 driver, or `trailnav replay --clouds`) instead of
  // Velodyne packets; `model` is then the Velodyne model whose task preset
  // and budget checks stand for it (given, or the first with at least as
  // many rings).
  std::optional<dds::CloudReaderOptions> cloud;
};

struct CanSection {
  std::string dbc;  // file
  can::CanDriverOptions driver;
};

// The place task (docs/place.md "On the robot"): a database from an earlier
// drive, the filter's transition, and how its answer is published.
struct PlaceSection {
  std::string database;  // file (.tnplace)
  std::string frame = "map";  // the frame the database's poses are in (PlaceMatch, the place pose)
  perception::place::TransitionModel transition;
  double prior_queries = 10.0;
  perception::place::PlaceTaskOptions task;
  int lag = 10;  // frames (docs/place.md "On the robot")
  perception::place::SequenceConfig sequence{10, 5, 5};
  int peak_radius = 50;
  pose::PlaceUseOptions pose;  // pose_measurement and its thresholds
};

// The station task (docs/registration.md "In trailnavd"): a taught station
// file, where its planar scans come from, and where a visit begins.
struct StationSection {
  std::string file;  // trailnav station teach --out
  enum class Input { laserscan, velodyne } input = Input::laserscan;
  dds::LaserScanOptions laser;                    // input: laserscan (topic, max_range, mount)
  perception::registration::RingBand band;        // input: velodyne (rings, ranges, mount)
  bool band_mount_given = false;                  // else the lidar's mount (obstacles.mount)
  perception::registration::StationConfig config; // local_scans, max_points
  perception::registration::StationTaskOptions task;  // start, every, silence_s, arena
  std::string frame = "station";
  bool use_pose = true;  // the pose thread's odometry between scans, when there is a 'pose' section
};

struct DdsSection {
  std::uint32_t domain = 0;
  std::string cyclone_config;  // file; empty: the built-in loopback configuration
  std::string cyclone_xml;     // its text
  dds::PublisherOptions publisher;
  dds::CommandReaderOptions commands;  // topics; frames and zone are set at start-up
};

struct RobotConfig {
  std::string file;
  std::string name;
  RuntimeSettings runtime;
  std::vector<TaskSpec> tasks;
  std::string task_preset;            // the lidar model whose measured table `tasks` came from; empty: written out
  std::vector<std::string> warnings;  // not errors, said at start-up (a budget below what the lidar needs)
  std::optional<LidarSection> lidar;
  std::optional<gps::GpsDriverOptions> gps;
  std::optional<imu::ImuDriverOptions> imu;
  std::array<double, 3> imu_position{0.0, 0.0, 0.0};  // m, robot frame (tf_static only)
  std::optional<CanSection> can;
  std::optional<gpio::GpioDriverOptions> gpio;
  std::optional<drivers::camera::CameraOptions> camera;
  std::optional<PlaceSection> place;
  std::optional<pose::PoseEstimatorOptions> pose;
  std::optional<perception::ObstacleConfig> obstacles;
  bool obstacles_use_pose = true;
  std::optional<perception::TerrainConfig> terrain;
  bool terrain_use_pose = true;
  // The learnt traversability layer in the terrain thread (docs/traversability.md "On the robot").
  std::optional<perception::trav::TraversabilityConfig> traversability;
  perception::PoseWait pose_wait;  // how the obstacle and terrain threads wait for a late pose
  std::optional<nav::NavigationSection> navigation;
  std::optional<slam::MappingOptions> mapping;  // online mapping (docs/slam.md "Online mapping")
  std::optional<StationSection> station;        // localisation relative to moved objects (chapter 4)
  DdsSection dds;

  // The terrain thread registers the points the obstacle thread aligned
  // (RevolutionCloud::hand_over_aligned()) instead of aligning every
  // revolution again: with both maps, both registered with the pose or both
  // without.
  bool terrain_shares_alignment() const noexcept {
    return obstacles.has_value() && terrain.has_value() && obstacles_use_pose == terrain_use_pose;
  }
  // The lidar's revolution readers, one per thread that reads the
  // revolutions itself, in this order: the obstacle thread, the terrain
  // thread (when it does not share the obstacle thread's alignment), the
  // station's ring band, the mapping's loop closures. revolution_reader(r)
  // is r's index when r reads (and the number of readers before it when it
  // does not); revolution_reader(Reader::count) is how many there are.
  enum class Reader { obstacles, terrain, station, mapping, count };
  std::size_t revolution_reader(Reader who) const noexcept {
    const bool reads[] = {obstacles.has_value(), terrain.has_value() && !terrain_shares_alignment(),
                          station.has_value() && station->input == StationSection::Input::velodyne,
                          mapping.has_value() && mapping->loops.has_value()};
    std::size_t i = 0;
    for (std::size_t r = 0; r < static_cast<std::size_t>(who); ++r) i += reads[r] ? 1 : 0;
    return i;
  }
};

// Throws ConfigError. Relative paths are taken from the config file's directory.
RobotConfig parse_robot_config(const ConfigNode& root);

struct RobotConfigResult {
  std::optional<RobotConfig> config;
  std::string error;  // "file:line: key: problem"
};
RobotConfigResult load_robot_config(const std::string& path);

}  // namespace trailnav::daemon
