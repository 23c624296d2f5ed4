// The navigation task's logic (thesis ch. 8): plan on the OpenStreetMap road
// network from the robot's UTM position to the goal, follow the robot along
// the planned route, hand the subgoals ahead to the aligner, and say which
// corrected subgoal the robot should drive to now.
//
//   plan      once the UTM pose is known (position and heading, sigma below
//             max_position_sigma): the robot projected onto the nearest
//             routable way (§8.1.1), A* to the goal's projection, subgoals
//             every `spacing` metres along the path (g_0 .. g_n, UTM)
//   follow    every step: the robot's arc along the route is its nearest
//             point within a window around the last one (a route passing a
//             place twice is not jumped along); subgoals up to `lookahead`
//             metres ahead are pushed to the aligner in the local odometry
//             frame (q_local = P_local * P_utm^-1 * q_utm, both poses of the
//             same instant); with a new terrain-class map the aligner updates
//   activate  the active subgoal is the first one more than `reach` metres
//             ahead along the route: when the robot almost reaches it, the
//             next one (corrected) becomes active
//   re-plan   when the robot is more than `leave_distance` from the route for
//             `leave_time` seconds (it took another way), from where it is
//             now; at most every `replan_interval` seconds
//   goal      within `goal_tolerance` of the route's end: reached
//   orders    a new goal (geographic, UTM or in the odometry frame) is
//             checked at once (finite, within a zone of the map's, within
//             `max_snap` of a routable way) and planned at the next step;
//             one that cannot be routed from the robot is refused there. A
//             refused goal leaves the robot on its current route (or, with
//             none, idle); `cancel` drops the route and the robot stops.
//             Without a goal in the config the navigator starts idle.
//
// Everything is allocated by create(): the router's work arrays, the route
// and subgoal buffers sized by the network's total length, the aligner.
// step() and snapshot() never allocate, so the navigation task may call them
// on a real-time thread after arm.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "trailnav/navigation/osm/road_graph.hpp"
#include "trailnav/navigation/osm/router.hpp"
#include "trailnav/navigation/pose/gyro_odometry.hpp"
#include "trailnav/navigation/pose/utm_alignment.hpp"
#include "trailnav/navigation/subgoals/subgoal_aligner.hpp"
#include "trailnav/perception/terrain_class_map.hpp"

namespace trailnav::nav {

struct NavigatorConfig {
  double goal_lat = std::numeric_limits<double>::quiet_NaN();  // degrees WGS84
  double goal_lon = std::numeric_limits<double>::quiet_NaN();
  double spacing = 4.0;             // m between subgoals (§8.1.1)
  double lookahead = 12.0;          // m: subgoals this far ahead along the route are aligned
  double reach = 2.0;               // m: a subgoal this close ahead along the route is reached
  double goal_tolerance = 2.0;      // m before the route's end: the goal is reached
  double max_snap = 200.0;          // m: farthest the robot or the goal may be from a routable way
  double leave_distance = 20.0;     // m off the route ...
  double leave_time = 3.0;          // s ... for this long: re-plan from where the robot is
  double replan_interval = 5.0;     // s, at least, between two plans
  double max_position_sigma = 15.0; // m: plan only with a UTM position this certain
  std::size_t path_poses = 128;     // subgoals in the published corrected path (from the active one)
  subgoals::AlignerConfig aligner;  // its max_subgoals is set from the network by create()
};

// Empty when usable, else what is wrong. The goal may be absent (both NaN).
std::string check_navigator_config(const NavigatorConfig& config);

// The navigation status' states, by these names on DDS (docs/dds.md):
//   idle       no goal
//   planning   a goal, waiting for a UTM pose certain enough to plan from
//   following  a route to the goal
//   reached    within goal_tolerance of the route's end
//   failed     the goal cannot be routed from where the robot is (re-tried every replan_interval)
//   cancelled  the route was cancelled: no subgoal
enum class NavState : std::uint8_t { idle, planning, following, reached, failed, cancelled };
const char* nav_state_name(NavState state) noexcept;

// A goal as it arrives from outside (DDS): in degrees WGS84, or metres in the
// map's UTM zone, or metres in the odometry frame (converted through the
// newest pose pair).
// `unknown`: a frame neither of these (refused, naming `frame_id`).
enum class GoalFrame : std::uint8_t { geographic, utm, odom, unknown };
struct GoalRequest {
  GoalFrame frame = GoalFrame::geographic;
  double a = 0.0, b = 0.0;  // latitude, longitude (deg) | easting, northing (m) | x, y (m)
  std::array<char, 48> frame_id{};  // as it arrived (for the refusal of an unknown frame)
};
const char* goal_frame_name(GoalFrame frame) noexcept;

struct NavigationCounters {
  std::uint64_t steps = 0;
  std::uint64_t plans = 0;          // successful plans (the first and every re-plan)
  std::uint64_t replans = 0;        // of them, because the robot left the route
  std::uint64_t plan_failures = 0;
  std::uint64_t updates = 0;        // aligner updates (one per new terrain map)
  std::uint64_t catch_up_updates = 0;  // extra ones, between subgoals joining together
  std::uint64_t subgoals_reached = 0;
  std::uint64_t last_plan_expanded = 0;  // A*'s settled vertices
  double last_plan_ms = 0.0;
  std::uint64_t goals = 0;          // goals offered (config and orders)
  std::uint64_t goals_refused = 0;  // of them, refused (invalid, off the network, not routable)
  std::uint64_t cancels = 0;
};

// One subgoal of the published path, in the local odometry frame.
struct PathPose {
  double x = 0.0, y = 0.0, yaw = 0.0;
  bool corrected = false;  // the aligner's estimate (else the raw OSM position)
};

// The navigation status as trailnavd publishes it (trailnav_msgs/NavigationStatus):
// with every snapshot, and once for every order taken, so that each refusal
// is seen even when several orders arrive between two snapshots.
struct NavigationStatusReport {
  std::int64_t time_ns = 0;        // the pose's time
  NavState state = NavState::idle;
  bool has_goal = false;           // the goal in use (after a cancel: the cancelled one)
  double goal_easting = 0.0, goal_northing = 0.0;  // UTM, as given (before projection onto the network)
  double goal_lat = 0.0, goal_lon = 0.0;
  double remaining = 0.0;          // m along the route to its end (0 unless following)
  double route_length = 0.0;       // m
  std::size_t subgoals = 0, active = 0;
  int zone = 0;
  bool north = true;
  NavigationCounters counters;
  const char* message = "";        // why planning failed, or "" (a literal)
  std::array<char, 160> refusal{};  // why the newest goal was refused, or empty (a copy: other threads read it)
};

// What the navigation task hands the publisher. Constructed with the path's
// capacity at start-up (a Mailbox slot); snapshot() fills it without allocating.
struct NavigationSnapshot {
  explicit NavigationSnapshot(std::size_t path_capacity = 0) : path(path_capacity) {}

  NavState state = NavState::planning;
  std::int64_t time_ns = 0;        // the pose's time
  pose::LocalPose robot;           // the odometry pose the subgoals were placed from (robot.time_ns == time_ns)
  std::uint64_t plan = 0;          // number of the plan the subgoals belong to
  std::uint64_t active_revision = 0;  // changes whenever the active subgoal or its position changes
  std::uint64_t path_revision = 0;    // changes whenever the path changes
  std::size_t subgoals = 0;        // of the plan
  std::size_t active = 0;          // index of the active subgoal
  bool has_active = false;
  PathPose active_pose;            // odometry frame
  std::uint64_t goal_revision = 0; // changes with every goal offered, accepted or not, and every cancel
  NavigationStatusReport report;
  double active_easting = 0.0, active_northing = 0.0;  // its raw OSM position, UTM
  int zone = 0;
  bool north = true;
  double route_length = 0.0;       // m
  double progress = 0.0;           // m along the route
  double cross_track = 0.0;        // m, robot (UTM estimate) to the route
  std::vector<PathPose> path;      // capacity = path_poses; path_count used
  std::size_t path_count = 0;
  NavigationCounters counters;
  const char* message = "";        // the last plan failure, or ""
};

// What one step did: subgoals [reached_begin, reached_end) were reached.
struct StepResult {
  std::size_t reached_begin = 0, reached_end = 0;
  bool planned = false;
  bool updated = false;
};

class Navigator {
 public:
  struct Created;
  // Projects the goal onto `graph` (which must outlive the navigator) and
  // allocates everything; an error when the config is unusable or the goal
  // lies farther than max_snap from every routable way.
  static Created create(const osm::RoadGraph& graph, const NavigatorConfig& config,
                        const perception::TerrainMapShape& map_shape);

  // One step with the robot's pose in both frames (of the same instant) and,
  // when the terrain thread made one since the last step, its class map (in
  // the odometry frame); nullptr otherwise. Never allocates.
  StepResult step(const pose::LocalPose& local, const pose::UtmPose& utm, const perception::TerrainClassMap* map) noexcept;

  // Fills `out` (its path capacity is honoured). Never allocates.
  void snapshot(NavigationSnapshot& out) const noexcept;
  void report(NavigationStatusReport& out) const noexcept;

  // A new goal: checked now (false and refusal() says why: the current
  // route stays), planned at the next step. Never allocates.
  bool set_goal(const GoalRequest& goal) noexcept;
  // Drops the route: no subgoal until the next goal.
  void cancel() noexcept;
  const char* refusal() const noexcept { return refusal_text_; }

  NavState state() const noexcept { return state_; }
  const NavigationCounters& counters() const noexcept { return counters_; }
  const NavigatorConfig& config() const noexcept { return config_; }
  const osm::RoadGraph& graph() const noexcept { return graph_; }
  double goal_x() const noexcept { return goal_x_; }
  double goal_y() const noexcept { return goal_y_; }

  // The current plan.
  std::size_t subgoal_count() const noexcept { return subgoals_.size(); }
  const osm::Point2& subgoal_utm(std::size_t i) const noexcept { return subgoals_[i]; }
  double subgoal_arc(std::size_t i) const noexcept { return subgoal_arc_[i]; }
  std::span<const osm::Point2> route() const noexcept { return route_; }
  double route_length() const noexcept { return route_arc_.empty() ? 0.0 : route_arc_.back(); }
  double progress() const noexcept { return robot_arc_; }
  std::size_t active() const noexcept { return active_; }
  // Subgoal i in the odometry frame: raw (its OSM position through the
  // latest pose) and corrected (the aligner's estimate, raw before one).
  subgoals::Vec2 raw_local(std::size_t i) const noexcept;
  subgoals::Vec2 to_local(const osm::Point2& utm) const noexcept;  // through this step's pose
  subgoals::Vec2 corrected(std::size_t i) const noexcept;
  bool is_corrected(std::size_t i) const noexcept { return i < aligner_->count() && aligner_->estimated(i); }
  const subgoals::SubgoalAligner& aligner() const noexcept { return *aligner_; }
  const char* message() const noexcept { return message_; }

 private:
  Navigator(const osm::RoadGraph& graph, const NavigatorConfig& config, const perception::TerrainMapShape& shape,
            std::size_t subgoal_capacity);
  bool plan(const pose::UtmPose& utm, std::int64_t now, const osm::RoadProjection& goal) noexcept;
  void clear_route() noexcept;
  void refuse(const char* why) noexcept;
  // Distance of (x, y) to the route and its arc, over route segments whose
  // arcs meet [lo, hi].
  double nearest_on_route(double x, double y, double lo, double hi, double& arc) const noexcept;

  const osm::RoadGraph& graph_;
  NavigatorConfig config_;
  osm::Router router_;
  std::unique_ptr<subgoals::SubgoalAligner> aligner_;
  osm::RoadProjection goal_;
  double goal_x_ = 0.0, goal_y_ = 0.0;

  NavState state_ = NavState::planning;
  bool has_goal_ = false;
  bool have_pose_ = false;       // a pose pair has been seen (for odometry-frame goals)
  bool replan_now_ = false;      // a new goal: plan at the next step whatever replan_interval says
  std::vector<osm::Point2> candidate_;  // a new goal's route, kept apart until it is found
  osm::RoadProjection pending_goal_;
  double pending_x_ = 0.0, pending_y_ = 0.0, pending_lat_ = 0.0, pending_lon_ = 0.0;
  double goal_lat_ = 0.0, goal_lon_ = 0.0;
  std::uint64_t goal_revision_ = 0;
  char refusal_text_[160] = {};
  std::vector<osm::Point2> route_;
  std::vector<double> route_arc_;
  std::vector<osm::Point2> subgoals_;
  std::vector<double> subgoal_arc_;
  std::vector<subgoals::Vec2> raw_;  // odometry-frame positions handed to the aligner
  std::array<subgoals::Vec2, subgoals::SubgoalAligner::kShapePoints> shape_points_{};  // route vertices near the window
  std::array<double, subgoals::SubgoalAligner::kShapePoints> shape_arc_{};
  std::size_t active_ = 0;
  double robot_arc_ = 0.0;
  double cross_track_ = 0.0;
  std::int64_t last_plan_ns_ = 0;
  std::int64_t off_route_since_ = -1;
  std::uint64_t active_revision_ = 0, path_revision_ = 0;
  // The latest pose pair: odometry = rotate(utm - utm_origin) + local_origin.
  pose::LocalPose local_;  // the odometry pose of the latest step (its time is the navigator's)
  double utm_e_ = 0.0, utm_n_ = 0.0, cos_ = 1.0, sin_ = 0.0, rot_ = 0.0;
  const char* message_ = "";
  NavigationCounters counters_;
};

struct Navigator::Created {
  std::unique_ptr<Navigator> navigator;
  std::string error;
};

}  // namespace trailnav::nav
