// trailnavd's body: everything a robot config names, created and allocated at
// start-up, run on the runtime's scheduler, published over DDS.
//
//   drivers (lidar, gps, imu, can, gpio)  -- real-time tasks
//   pose                                  -- real-time task: IMU + wheels + GPS
//   obstacles                             -- real-time task, woken per revolution
//   terrain                               -- real-time task: the terrain-class map and the
//                                            learnt traversability layer (docs/traversability.md)
//   navigation                            -- real-time task: route, subgoals, alignment
//   mapping                               -- task on normal scheduling: keyframes, GPS
//                                            constraints, SMF solves (docs/slam.md)
//   demonstration                         -- task on normal scheduling: the traversability
//                                            model trained from a driven demonstration, saved
//   station                               -- task on normal scheduling: planar scans against a
//                                            taught station, a pose per object (chapter 4)
//   laser scan reader                     -- plain thread: sensor_msgs/LaserScan in (station.input: laserscan)
//   publisher                             -- plain thread, the only one that writes to DDS
//   command reader                        -- plain thread: goals and cancels in (DDS readers),
//                                            queued for the navigation task
//
// Real-time tasks hand snapshots through mailboxes and queues and never
// allocate once the runtime is armed; the publisher may (Cyclone serialises
// into its own buffers).
#pragma once

#include <atomic>
#include <memory>
#include <optional>
#include <string>

#include "cloud_reader.hpp"
#include "commands.hpp"
#include "dds.hpp"
#include "publisher.hpp"
#include "robot_config.hpp"
#include "trailnav/navigation/navigator/navigation_task.hpp"
#include "trailnav/navigation/osm/road_graph.hpp"
#include "trailnav/navigation/slam/mapping_task.hpp"
#include "trailnav/drivers/camera/camera_driver.hpp"
#include "trailnav/perception/obstacle_pipeline.hpp"
#include "trailnav/perception/place/database.hpp"
#include "trailnav/perception/place/online.hpp"
#include "trailnav/perception/place/place_task.hpp"
#include "trailnav/perception/obstacle_task.hpp"
#include "trailnav/perception/random_forest.hpp"
#include "trailnav/perception/registration/station_task.hpp"
#include "trailnav/perception/terrain_task.hpp"
#include "trailnav/perception/trav_online.hpp"
#include "trailnav/runtime/broadcast.hpp"
#include "trailnav/runtime/clock.hpp"
#include "trailnav/runtime/scheduler.hpp"

namespace trailnav::daemon {

struct DaemonSummary {
  std::uint64_t revolutions = 0;
  std::uint64_t maps_published = 0;
  std::uint64_t overruns = 0;  // runs over their CPU budget, all tasks
  std::uint64_t stalls = 0;    // runs kept off their core past the budget, all tasks
  std::uint64_t rt_allocations = 0;
  bool realtime = false;
  bool memory_locked = false;
};

class Daemon {
 public:
  struct Created;
  // Opens every port and socket and allocates everything; an error says
  // which part failed and why.
  static Created create(const RobotConfig& config);
  // For `trailnavd --check`: what start-up would do with the navigation
  // section short of starting (the map loads, the goal lies near a routable
  // way). Empty `error` when fine; `summary` says what was found.
  struct NavigationCheck {
    std::string error;
    std::string summary;
  };
  static NavigationCheck check_navigation(const RobotConfig& config);
  ~Daemon();
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  // Starts the publisher and the tasks, then arms the allocation guard.
  Status start();
  void stop();

  // One line for systemd's STATUS= and the log.
  std::string status_line() const;
  // False when a task has stopped making progress (for the watchdog).
  bool alive() noexcept;
  // The camera's image tunnel port (input: tunnel; chosen by the kernel when
  // the config says 0); 0 without one.
  std::uint16_t camera_tunnel_port() const noexcept { return camera_ ? camera_->status().tunnel_port : 0; }
  // The place task's counters (frames taken, answers); zeros without one.
  perception::place::PlaceCounters place_counters() const noexcept { return place_ ? place_->counters() : perception::place::PlaceCounters{}; }
  // The station task's counters; zeros without one.
  perception::registration::StationCounters station_counters() const noexcept {
    return station_task_ ? station_task_->counters() : perception::registration::StationCounters{};
  }
  DaemonSummary summary() const;
  // Task statistics, one line per task.
  std::string task_report() const;
  // One task's statistics and its budget (ms); nullopt for a task not in the table.
  struct TaskFigures {
    TaskStats stats;
    double budget_ms = 0.0;
  };
  std::optional<TaskFigures> task_figures(std::string_view name) const;

 private:
  explicit Daemon(const RobotConfig& config);
  void fill_health(dds::DiagnosticsMessage& msg, Nanos now) const;

  RobotConfig config_;
  MonotonicClock clock_;
  std::unique_ptr<Scheduler> scheduler_;
  std::unique_ptr<velodyne::VelodyneDriver> lidar_;
  velodyne::RangeImageShape lidar_shape() const noexcept {
    return lidar_ ? lidar_->revolution_shape() : cloud_reader_->revolution_shape();
  }
  Broadcast<velodyne::RangeImage>::Reader& lidar_revolutions(std::size_t reader) noexcept {
    return lidar_ ? lidar_->revolutions(reader) : cloud_reader_->revolutions(reader);
  }
  TaskEvent revolution_event_;
  std::unique_ptr<gps::GpsDriver> gps_;
  std::unique_ptr<imu::ImuDriver> imu_;
  std::optional<can::Dbc> dbc_;
  std::unique_ptr<can::CanDriver> can_;
  std::unique_ptr<gpio::GpioDriver> gpio_;
  std::unique_ptr<drivers::camera::CameraDriver> camera_;
  std::unique_ptr<perception::place::OnlinePlace> place_online_;
  std::unique_ptr<Mailbox<perception::place::PlaceSnapshot>> place_out_;
  std::unique_ptr<Mailbox<perception::place::PlaceSnapshot>> place_pose_in_;  // the pose thread's (place.pose_measurement)
  std::unique_ptr<perception::place::PlaceTask> place_;
  std::unique_ptr<pose::PoseTask> pose_;
  std::unique_ptr<perception::PoseQueue> pose_queue_;
  std::unique_ptr<perception::ObstaclePipeline> pipeline_;
  std::unique_ptr<Mailbox<perception::ObstacleSnapshot>> obstacle_out_;
  std::unique_ptr<Mailbox<perception::PointsSnapshot>> points_out_;
  std::unique_ptr<perception::ObstacleTask> obstacles_;
  std::optional<perception::RandomForest> forest_;
  std::unique_ptr<perception::TerrainMapper> terrain_mapper_;
  std::unique_ptr<perception::PoseQueue> terrain_pose_queue_;
  std::unique_ptr<Mailbox<perception::AlignedRevolution>> aligned_;  // obstacle thread -> terrain thread
  std::unique_ptr<Broadcast<perception::TerrainClassMap>> terrain_out_;
  std::unique_ptr<perception::TerrainTask> terrain_;
  // The traversability layer (the terrain mapper's sums sink) and the demonstration's training.
  std::unique_ptr<perception::trav::TravModels> trav_models_;
  std::unique_ptr<perception::trav::TravLayer> trav_layer_;
  std::unique_ptr<perception::trav::TravRecorder> trav_recorder_;
  std::unique_ptr<Mailbox<perception::trav::LocalMapWords>> trav_local_maps_;  // terrain thread -> training
  std::unique_ptr<Mailbox<perception::trav::TravModels>> trav_models_out_;     // training -> terrain thread
  std::unique_ptr<perception::trav::TravOnline> trav_online_;
  std::unique_ptr<perception::trav::TravTrainer> trav_trainer_;
  std::unique_ptr<perception::trav::TravTrainingTask> trav_training_;
  std::optional<osm::RoadGraph> graph_;
  std::unique_ptr<nav::Navigator> navigator_;
  std::unique_ptr<Mailbox<nav::NavigationSnapshot>> navigation_out_;
  std::unique_ptr<nav::NavigationTask> navigation_;
  std::unique_ptr<perception::PoseQueue> mapping_poses_;
  std::unique_ptr<pose::MappingFixQueue> mapping_fixes_;
  std::unique_ptr<Mailbox<slam::MappingSnapshot>> mapping_out_;
  std::unique_ptr<Mailbox<pose::MapCorrection>> map_corrections_;  // mapping thread -> pose thread
  std::unique_ptr<slam::MappingTask> mapping_;
  // The station: its bodies (the task keeps a reference), scans in, fixes out.
  std::optional<perception::registration::Station> station_;
  std::string station_name_;
  std::unique_ptr<Mailbox<perception::registration::PlanarScan>> station_scans_;
  std::unique_ptr<Mailbox<perception::registration::StationSnapshot>> station_out_;
  std::unique_ptr<perception::PoseQueue> station_poses_;
  std::unique_ptr<perception::registration::StationTask> station_task_;
  std::unique_ptr<dds::Domain> domain_;
  std::unique_ptr<dds::DdsPublisher> publisher_;
  std::unique_ptr<nav::NavCommandQueue> commands_;
  std::unique_ptr<nav::NavStatusQueue> answers_;
  std::unique_ptr<dds::CommandReader> command_reader_;
  // lidar.input: pointcloud2 (else lidar_). After domain_: its readers go before the domain does.
  std::unique_ptr<dds::CloudReader> cloud_reader_;
  // station.input: laserscan. After domain_, as the cloud reader.
  std::unique_ptr<dds::LaserScanReader> scan_reader_;
  std::vector<std::uint64_t> last_runs_;
  // Set on the main thread after the publisher has started; its health reads it.
  std::atomic<bool> armed_{false};
};

struct Daemon::Created {
  std::unique_ptr<Daemon> daemon;
  std::string error;
};

}  // namespace trailnav::daemon
