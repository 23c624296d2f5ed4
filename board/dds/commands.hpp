// Orders in: the DDS readers of goals and cancels, on a plain thread of
// their own (never a real-time one). Each sample is turned into a
// NavCommand by the pure functions below and handed to the navigation task
// through its queue (try_push: a full queue drops the order and counts it);
// the navigation task checks the goal and answers on the navigation status
// topic. Nothing that arrives can stop this thread: a sample Cyclone cannot
// deserialise never reaches it, and any values at all make a command the
// navigator either takes or refuses with its reason.
//
//   trailnav/goal       geometry_msgs/PoseStamped   x, y in the odometry frame or the map (UTM) frame, by header.frame_id
//   trailnav/geo_goal   geographic_msgs/GeoPoseStamped  latitude, longitude (WGS84 degrees)
//   trailnav/cancel     std_msgs/Empty              drop the route: the robot stops at no subgoal
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <thread>

#include "dds.hpp"
#include "geographic_msgs.h"
#include "geometry_msgs.h"
#include "std_msgs.h"
#include "trailnav/navigation/navigator/navigation_task.hpp"

namespace trailnav::dds {

struct CommandTopics {
  std::string goal = "trailnav/goal";
  std::string geo_goal = "trailnav/geo_goal";
  std::string cancel = "trailnav/cancel";
};

struct CommandReaderOptions {
  CommandTopics topics;
  std::string odom_frame = "odom";
  // The frame names a PoseStamped goal may carry for UTM: the map frame's
  // configured name (dds.frames.map, when not "utm") and utm_<zone><N|S>.
  std::string map_frame = "utm";
  int zone = 0;
  bool north = true;
};

// The goal a PoseStamped names: odometry frame, UTM, or unknown (refused by
// the navigator, naming the frame).
nav::NavCommand goal_from_pose(const geometry_msgs_msg_dds__PoseStamped_& sample, const CommandReaderOptions& options) noexcept;
nav::NavCommand goal_from_geo_pose(const geographic_msgs_msg_dds__GeoPoseStamped_& sample) noexcept;

struct CommandReaderStats {
  std::uint64_t goals = 0, geo_goals = 0, cancels = 0;  // samples taken
  std::uint64_t queue_full = 0;                         // orders dropped: the navigation task had 16 waiting
};

class CommandReader {
 public:
  struct Created;
  static Created create(const Domain& domain, const CommandReaderOptions& options, nav::NavCommandQueue& queue);
  ~CommandReader();
  CommandReader(const CommandReader&) = delete;
  CommandReader& operator=(const CommandReader&) = delete;

  void start();
  void stop();
  CommandReaderStats stats() const noexcept;

 private:
  CommandReader(const CommandReaderOptions& options, nav::NavCommandQueue& queue) : options_(options), queue_(queue) {}
  void loop() noexcept;
  void take_all() noexcept;
  void push(const nav::NavCommand& command) noexcept;

  CommandReaderOptions options_;
  nav::NavCommandQueue& queue_;
  dds_entity_t goal_topic_ = 0, geo_topic_ = 0, cancel_topic_ = 0;
  dds_entity_t goal_reader_ = 0, geo_reader_ = 0, cancel_reader_ = 0;
  dds_entity_t waitset_ = 0;
  geometry_msgs_msg_dds__PoseStamped_ goal_sample_{};
  geographic_msgs_msg_dds__GeoPoseStamped_ geo_sample_{};
  std_msgs_msg_dds__Empty_ cancel_sample_{};
  std::atomic<bool> running_{false};
  std::thread thread_;
  std::atomic<std::uint64_t> goals_{0}, geo_goals_{0}, cancels_{0}, queue_full_{0};
};

struct CommandReader::Created {
  std::unique_ptr<CommandReader> reader;
  std::string error;
};

}  // namespace trailnav::dds
