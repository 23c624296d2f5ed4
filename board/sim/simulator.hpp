// `trailnav sim`: builds a scenario's world, drives the robot through it and
// writes a bench recording of the bytes its sensors would send, plus the
// ground truth (docs/simulator.md).
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "camera.hpp"
#include "trailnav/drivers/velodyne/model.hpp"

namespace trailnav::sim {

struct SimOptions {
  std::string scenario = "urban";  // built-in name or YAML file
  std::uint64_t seed = 1;
  double duration = 0.0;           // s; 0: the scenario's, else until the route ends
  std::string lidar;               // model override ("VLP-16", "VLP-32C", "HDL-32E", "HDL-64E")
  std::string calibration;         // calibration file override
  std::string out;                 // output directory
  bool truth = true;               // write DIR/truth/
  bool lidar_packets = true;       // false: no lidar streams' packets (GPS, IMU, CAN and GPIO only; fast)
  bool camera = false;             // an image stream `camera` of rendered frames (camera.hpp; simulated)
  Season season = Season::summer;
  CameraSpec camera_spec;
  // Called now and then with the simulated time done and the total.
  std::function<void(double done, double total)> progress;
};

struct SimReport {
  std::string error;  // empty on success
  std::string scenario;
  std::string lidar_model;
  std::string calibration;
  double sim_seconds = 0.0;
  double world_seconds = 0.0;  // wall time to build the world
  double lidar_seconds = 0.0;  // wall time to ray-cast and encode the lidar
  double total_seconds = 0.0;  // wall time of the whole run
  double route_length = 0.0;
  std::uint64_t lidar_packets = 0;
  std::uint64_t position_packets = 0;
  std::uint64_t rays = 0;
  std::uint64_t returns = 0;
  std::uint64_t nmea_sentences = 0;
  std::uint64_t imu_messages = 0;
  std::uint64_t can_frames = 0;
  std::uint64_t gpio_levels = 0;
  std::uint64_t camera_frames = 0;
  std::uint64_t camera_rays = 0;
  double camera_seconds = 0.0;  // wall time to render them
};

SimReport run_simulation(const SimOptions& options);

// The calibration file the simulator uses for a model when the scenario names
// none (from ../shared/data/velodyne/calibration/); empty when not found.
std::string default_calibration_file(velodyne::Model model);

// The DBC describing the simulated robot's CAN messages (board/sim/trailnav-robot.dbc).
const char* robot_dbc_text() noexcept;

}  // namespace trailnav::sim
