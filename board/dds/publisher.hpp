// The publisher thread: the only thread of trailnavd that calls DDS. Real-time
// tasks publish snapshots into mailboxes and post a Wakeup; this thread takes
// the newest snapshot, fills the preallocated sample and writes it. Cyclone
// allocates inside dds_write (serialisation), on this thread only.
//
// Obstacle maps go out as soon as they are made, stamped (source time) with
// the receive time of the lidar packet that completed their revolution, so a
// subscriber measures the whole latency. Poses go out at `pose_rate_hz`,
// terrain-class maps and their cost layer after each terrain step (reliable,
// transient-local: a late joiner gets the newest), the active subgoal when it
// changes and the corrected path when it changes (both reliable,
// transient-local, odometry frame), health every
// `health_period`. When the lidar falls silent for
// `stale_after`, the last map is sent again once a second with its free cells
// turned unknown: a planner never keeps driving on old free space.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "dds.hpp"
#include "messages.hpp"
#include "trailnav/navigation/navigator/navigation_task.hpp"
#include "trailnav/navigation/navigator/navigator.hpp"
#include "trailnav/navigation/pose/pose_estimator.hpp"
#include "trailnav/navigation/slam/mapping_task.hpp"
#include "trailnav/perception/obstacle_task.hpp"
#include "trailnav/perception/terrain_class_map.hpp"
#include "trailnav/runtime/broadcast.hpp"
#include "trailnav/runtime/clock.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/wakeup.hpp"

namespace trailnav::dds {

struct TopicNames {
  std::string obstacle_map = "trailnav/obstacle_map";
  std::string terrain_map = "trailnav/terrain_map";
  std::string terrain_cost = "trailnav/terrain_cost";
  std::string traversability = "trailnav/traversability";  // the learnt layer (nav_msgs/OccupancyGrid)
  std::string pose = "trailnav/pose";
  std::string utm_pose = "trailnav/utm_pose";
  std::string fix = "trailnav/fix";
  std::string subgoal = "trailnav/subgoal";
  std::string subgoal_path = "trailnav/subgoal_path";
  std::string health = "diagnostics";
  std::string tf = "tf";                // tf2's topics: rt/tf and rt/tf_static
  std::string tf_static = "tf_static";
  std::string odometry = "odom";        // nav_msgs/Odometry, Nav2's default
  std::string navigation_status = "trailnav/navigation_status";
  std::string coarse_map = "trailnav/obstacle_map_coarse";
  std::string points = "trailnav/points";
  std::string keyframe_path = "trailnav/keyframe_path";  // the mapping thread's optimised keyframes
  std::string place_match = "trailnav/place_match";      // trailnav_msgs/PlaceMatch
  std::string place_pose = "trailnav/place_pose";        // geometry_msgs/PoseWithCovarianceStamped
  std::string station_fix = "trailnav/station";          // trailnav_msgs/StationFix
  // geometry_msgs/PoseWithCovarianceStamped per body of the station: this and its name
  // (trailnav/station/surroundings, trailnav/station/<object>).
  std::string station_pose_prefix = "trailnav/station/";
};

// REP 105 frame names (docs/dds.md, "Frames"). `map`: the frame of the GPS
// alignment; "utm" names it after the zone (utm_32N), anything else is used
// as it is (e.g. map).
struct FrameNames {
  std::string map = "utm";
  std::string base_link = "base_link";
  std::string lidar = "velodyne";
  std::string imu = "imu_link";
};

// A sensor's place on the robot: published once on tf_static, base_link -> frame.
struct StaticFrame {
  std::string frame;
  RigidTransform transform;
};

struct PublisherOptions {
  TopicNames topics;
  std::string odom_frame = "odom";
  std::string fix_frame = "gps";        // the GPS antenna's frame (NavSatFix)
  std::string place_frame = "map";      // the place database's poses (PlaceMatch, the place pose)
  // The station (trailnavd sets them from the station file and station.frame).
  std::string station_name;
  std::string station_frame = "station";
  std::vector<std::string> station_bodies;  // [0]: surroundings
  FrameNames frames;
  bool publish_tf = true;               // rt/tf, rt/tf_static and odometry
  // Each obstacle map's own odom -> base_link (the pose it was placed with, at
  // its stamp) also goes out on tf; only when the map moves with the pose.
  bool map_instant_tf = false;
  std::vector<StaticFrame> static_frames;  // set by trailnavd from the config's mounts
  double pose_rate_hz = 20.0;
  double health_period = 1.0;  // s
  double stale_after = 0.5;    // s without a new obstacle map before the lidar counts as silent
  int occupied_percent = 50;
  // The coarse obstacle map (topics.coarse_map): `coarse_factor` cells per
  // block side (0: not published), over a window of `coarse_window` m
  // around the robot (0: the whole map).
  int coarse_factor = 0;
  double coarse_window = 0.0;
  double map_resolution = 0.1;  // m, of the obstacle map (set by trailnavd from the config)
  double points_rate_hz = 0.0;  // revolutions a second on topics.points (0: off); the obstacle task hands them over
};

struct PublisherInputs {
  Mailbox<perception::ObstacleSnapshot>* obstacles = nullptr;  // its slots give the map's size
  Mailbox<pose::PoseSnapshot>* poses = nullptr;
  // The terrain thread's class maps (its slots give the map's size) and the
  // class costs of the cost layer.
  Broadcast<perception::TerrainClassMap>::Reader* terrain = nullptr;
  std::array<float, perception::kTerrainClasses> terrain_cost{0.1f, 0.2f, 0.4f, 0.8f, 1.0f};
  float unknown_cost = 1.0f;
  // The class maps carry the learnt traversability layer (TerrainCell::traversable): published on
  // topics.traversability.
  bool traversability = false;
  // The navigation thread's snapshots (their path capacity gives the Path's).
  Mailbox<nav::NavigationSnapshot>* navigation = nullptr;
  // Revolutions as points for viewers (its slots give the capacity), may be null.
  Mailbox<perception::PointsSnapshot>* points = nullptr;
  // The mapping thread's snapshots (their path capacity gives the Path's), may be null.
  Mailbox<slam::MappingSnapshot>* mapping = nullptr;
  // The place task's answers, may be null.
  Mailbox<perception::place::PlaceSnapshot>* place = nullptr;
  // The station task's fixes, may be null (PublisherOptions::station_bodies names their bodies).
  Mailbox<perception::registration::StationSnapshot>* station = nullptr;
  // The navigation task's answer to each order (a status each), may be null.
  nav::NavStatusQueue* navigation_answers = nullptr;
  // Fills the health statuses (called on the publisher thread before each health sample).
  std::function<void(DiagnosticsMessage&, Nanos now)> health;
};

struct PublisherStats {
  std::uint64_t maps = 0, stale_maps = 0, terrain_maps = 0, poses = 0, fixes = 0, health = 0, write_failures = 0;
  std::uint64_t subgoals = 0, paths = 0;
  std::uint64_t transforms = 0, odometry = 0;  // TFMessages on rt/tf, Odometry samples
  std::uint64_t statuses = 0;                  // navigation status samples
  std::uint64_t point_clouds = 0;
  std::uint64_t keyframe_paths = 0;  // the mapping thread's paths
  std::uint64_t place_matches = 0;   // PlaceMatch samples (each with its place pose)
  std::uint64_t station_fixes = 0;   // StationFix samples (each with a pose per body)
  std::uint64_t traversability_maps = 0;
  bool lidar_stale = false;
};

class DdsPublisher {
 public:
  struct Created;
  static Created create(const Domain& domain, Clock& clock, const PublisherOptions& options, PublisherInputs inputs);
  ~DdsPublisher();
  DdsPublisher(const DdsPublisher&) = delete;
  DdsPublisher& operator=(const DdsPublisher&) = delete;

  Wakeup& wakeup() noexcept { return wakeup_; }
  void start();
  void stop();
  PublisherStats stats() const noexcept;

 private:
  DdsPublisher(Clock& clock, const PublisherOptions& options, PublisherInputs inputs);
  void loop() noexcept;
  void publish_health(Nanos now) noexcept;
  void publish_navigation(const nav::NavigationSnapshot& snapshot) noexcept;
  void publish_status(const nav::NavigationStatusReport& report) noexcept;
  void publish_pose(const pose::PoseSnapshot& p) noexcept;
  void publish_map_instant(const perception::ObstacleSnapshot& s) noexcept;
  void publish_static_frames() noexcept;
  void publish_mapping(const slam::MappingSnapshot& m) noexcept;
  void count(bool written, std::atomic<std::uint64_t>& counter) noexcept;

  Clock& clock_;
  PublisherOptions options_;
  PublisherInputs inputs_;
  Wakeup wakeup_;
  std::unique_ptr<Writer> map_writer_, terrain_writer_, cost_writer_, trav_writer_, pose_writer_, utm_writer_, fix_writer_, health_writer_;
  std::unique_ptr<Writer> subgoal_writer_, path_writer_;
  std::unique_ptr<Writer> tf_writer_, tf_static_writer_, odometry_writer_, status_writer_;
  NavigationStatusMessage status_msg_;
  nav::NavigationStatusReport answer_;
  TfMessage tf_msg_{2};
  std::optional<TfMessage> tf_static_msg_;
  std::optional<OdometryMessage> odometry_msg_;
  std::array<char, 64> map_frame_{};  // the GPS alignment's frame
  std::optional<OccupancyGridMessage> grid_, coarse_;
  std::unique_ptr<Writer> coarse_writer_, points_writer_;
  std::optional<PointCloudMessage> points_msg_;
  void publish_coarse(const perception::ObstacleSnapshot& snapshot, bool stale) noexcept;
  std::optional<TerrainClassMapMessage> terrain_msg_;
  std::optional<OccupancyGridMessage> cost_msg_, trav_msg_;
  PoseStampedMessage pose_msg_;
  PoseStampedMessage subgoal_msg_;
  std::optional<PathMessage> path_msg_;
  // The mapping thread's path, and, for a map without GPS, its map -> odom
  // (docs/slam.md "Online mapping"; a map with GPS corrects the UTM poses).
  std::unique_ptr<Writer> place_match_writer_, place_pose_writer_;
  std::optional<PlaceMessages> place_msg_;
  std::atomic<std::uint64_t> place_matches_{0};
  std::unique_ptr<Writer> station_writer_;
  std::vector<std::unique_ptr<Writer>> station_pose_writers_;
  std::optional<StationMessages> station_msg_;
  std::atomic<std::uint64_t> station_fixes_{0};
  std::unique_ptr<Writer> keyframe_path_writer_;
  std::optional<PathMessage> keyframe_path_msg_;
  struct OdomParent {
    bool valid = false;  // a map without GPS: its map -> odom replaces the alignment's
    RigidTransform transform;
    std::array<char, 64> frame{};
  } odom_parent_;
  std::uint64_t last_active_revision_ = 0, last_path_revision_ = 0;
  UtmFixMessages utm_msg_;
  DiagnosticsMessage health_msg_;
  bool health_overflow_said_ = false;  // publisher thread only
  std::atomic<bool> running_{false};
  std::thread thread_;
  // Publisher thread's state, copied out under the atomics below.
  std::atomic<std::uint64_t> trav_maps_{0};
  std::atomic<std::uint64_t> maps_{0}, stale_maps_{0}, terrain_maps_{0}, poses_{0}, fixes_{0}, health_{0}, failures_{0};
  std::atomic<std::uint64_t> subgoals_{0}, paths_{0}, transforms_{0}, odometry_{0}, statuses_{0}, point_clouds_{0};
  std::atomic<std::uint64_t> keyframe_paths_{0};
  std::atomic<bool> lidar_stale_{false};
};

struct DdsPublisher::Created {
  std::unique_ptr<DdsPublisher> publisher;
  std::string error;
};

}  // namespace trailnav::dds
