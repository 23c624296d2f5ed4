// The navigation task's logic on hand-built road networks whose geometry is
// known, and on the real Liechtenstein extract: it plans once the UTM pose is
// there, follows the robot along the route, activates each subgoal in turn
// and reaches the goal; re-plans when the robot takes another road; reports a
// goal it cannot reach; pulls subgoals onto the street the terrain map shows;
// and neither the navigator nor its task allocates after arm.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <functional>

#include "../drivers/test_data.hpp"
#include "trailnav/navigation/navigator/navigation_config.hpp"
#include "trailnav/navigation/navigator/navigation_task.hpp"
#include "trailnav/navigation/navigator/navigator.hpp"
#include "trailnav/navigation/osm/router.hpp"
#include "trailnav/runtime/alloc_guard.hpp"
#include "terrain_paint.hpp"

namespace trailnav::nav {
namespace {

using perception::TerrainClass;
using perception::TerrainClassMap;

constexpr double kE0 = 500000.0, kN0 = 5200000.0;  // zone 32N, near 46.95 N 9 E

// The network, in metres from (kE0, kN0):
//   A(0,0) -- B(100,0) -- C(200,0) -- D(200,200)   the main road
//             B -- S(100,-150)                     a side road
//   E(1000,1000) -- F(1100,1000)                   an island nobody can reach
osm::RoadGraph test_graph() {
  std::vector<osm::RoadVertex> v = {{kE0, kN0, 1},         {kE0 + 100, kN0, 2},        {kE0 + 200, kN0, 3},
                                    {kE0 + 200, kN0 + 200, 4}, {kE0 + 100, kN0 - 150, 5}, {kE0 + 1000, kN0 + 1000, 6},
                                    {kE0 + 1100, kN0 + 1000, 7}};
  std::vector<osm::RoadWay> ways = {{10, "track", "main"}, {11, "track", "side"}, {12, "track", "island"}};
  return osm::RoadGraph::build(32, true, v, ways, {{0, 1, 2, 3}, {1, 4}, {5, 6}}, {0, 0, 0});
}

// The odometry frame: local = R(phi) (utm - utm0) + t.
struct Frames {
  double phi = 0.7, tx = 5.0, ty = -3.0;
  void to_local(double e, double n, double& x, double& y) const {
    const double dx = e - kE0, dy = n - kN0;
    x = tx + std::cos(phi) * dx - std::sin(phi) * dy;
    y = ty + std::sin(phi) * dx + std::cos(phi) * dy;
  }
  void to_utm(double x, double y, double& e, double& n) const {
    const double dx = x - tx, dy = y - ty;
    e = kE0 + std::cos(phi) * dx + std::sin(phi) * dy;
    n = kN0 - std::sin(phi) * dx + std::cos(phi) * dy;
  }
};

// The robot at (e, n) heading `yaw` (grid), at time t seconds.
void poses(const Frames& f, double e, double n, double yaw, double t, pose::LocalPose& local, pose::UtmPose& utm) {
  utm = {};
  utm.position_valid = utm.heading_valid = true;
  utm.zone = 32;
  utm.easting = e;
  utm.northing = n;
  utm.yaw = yaw;
  utm.covariance = Eigen::Matrix3d::Identity() * 0.25;
  local = {};
  local.time_ns = static_cast<std::int64_t>(t * 1e9);
  f.to_local(e, n, local.x, local.y);
  local.yaw = yaw + f.phi;
  local.source = pose::PoseSource::gyro_odometry;
}

NavigatorConfig config_to(const osm::RoadGraph& g, double de, double dn) {
  NavigatorConfig c;
  EXPECT_TRUE(g.to_latlon(kE0 + de, kN0 + dn, c.goal_lat, c.goal_lon));
  return c;
}

// The robot's path: a polyline in metres from (kE0, kN0), walked `step` m at a time.
std::vector<std::array<double, 3>> walk(const std::vector<std::array<double, 2>>& points, double step) {
  std::vector<std::array<double, 3>> out;
  for (std::size_t i = 1; i < points.size(); ++i) {
    const double dx = points[i][0] - points[i - 1][0], dy = points[i][1] - points[i - 1][1];
    const double len = std::hypot(dx, dy), yaw = std::atan2(dy, dx);
    for (double s = 0.0; s < len; s += step) out.push_back({points[i - 1][0] + s * dx / len, points[i - 1][1] + s * dy / len, yaw});
  }
  const auto& last = points.back();
  out.push_back({last[0], last[1], out.back()[2]});
  return out;
}

// A navigator on the test network, its frames and the pose pair it is fed.
class OnTestGraph : public ::testing::Test {
 protected:
  // Heads for (de, dn) metres from (kE0, kN0).
  Navigator& make(double de, double dn, NavigatorConfig c = {}) {
    const NavigatorConfig goal = config_to(g, de, dn);
    c.goal_lat = goal.goal_lat;
    c.goal_lon = goal.goal_lon;
    auto made = Navigator::create(g, c, {});
    EXPECT_TRUE(made.navigator) << made.error;
    navigator = std::move(made.navigator);
    return *navigator;
  }
  // Heading for D, planned and following from 50 m along the main road at t = 1 s.
  bool following_to_d() {
    make(200.0, 200.0);
    if (!navigator) return false;
    at(50.0, 0.0, 0.0, 1.0);
    navigator->step(local, utm, nullptr);
    return navigator->state() == NavState::following;
  }
  // The robot at (de, dn) m heading `yaw` (grid), at time t s.
  void at(double de, double dn, double yaw, double t) { poses(f, kE0 + de, kN0 + dn, yaw, t, local, utm); }

  const osm::RoadGraph g = test_graph();
  const Frames f;
  std::unique_ptr<Navigator> navigator;
  pose::LocalPose local;
  pose::UtmPose utm;
};

TEST(Navigator, ChecksItsConfiguration) {
  NavigatorConfig c;
  EXPECT_EQ(check_navigator_config(c), "");  // no goal: idle until one is ordered
  c.goal_lat = 47.0;
  EXPECT_NE(check_navigator_config(c).find("goal"), std::string::npos);  // half a goal
  c.goal_lat = 95.0;
  c.goal_lon = 9.0;
  EXPECT_NE(check_navigator_config(c).find("goal"), std::string::npos);
  c.goal_lat = 47.0;
  c.goal_lon = 9.0;
  EXPECT_EQ(check_navigator_config(c), "");
  c.reach = 5.0;  // beyond the spacing
  EXPECT_NE(check_navigator_config(c).find("reach"), std::string::npos);
  c = {};
  c.goal_lat = 47.0;
  c.goal_lon = 9.0;
  c.lookahead = 3.0;
  EXPECT_NE(check_navigator_config(c).find("lookahead"), std::string::npos);
  c = {};
  c.goal_lat = 47.0;
  c.goal_lon = 9.0;
  c.aligner.samples = 0;
  EXPECT_NE(check_navigator_config(c).find("samples"), std::string::npos);
  // A goal far from every road.
  const osm::RoadGraph g = test_graph();
  const auto made = Navigator::create(g, config_to(g, 500.0, 500.0), {});
  EXPECT_FALSE(made.navigator);
  EXPECT_NE(made.error.find("max_snap"), std::string::npos) << made.error;
}

TEST_F(OnTestGraph, FollowsTheRouteActivatesEachSubgoalAndReachesTheGoal) {
  Navigator& nav = make(200.0, 200.0);
  ASSERT_TRUE(navigator);
  // No UTM heading yet: nothing is planned.
  at(0.0, 0.0, 0.0, 0.0);
  utm.heading_valid = false;
  nav.step(local, utm, nullptr);
  EXPECT_EQ(nav.state(), NavState::planning);

  const auto path = walk({{0, 0}, {200, 0}, {200, 200}}, 0.5);
  std::size_t reached = 0, last_active = 0;
  double t = 0.0;
  NavigationSnapshot snap(128);
  for (const auto& p : path) {
    at(p[0], p[1], p[2], t += 0.25);
    const StepResult r = nav.step(local, utm, nullptr);
    if (r.reached_end > r.reached_begin) {
      EXPECT_EQ(r.reached_begin, last_active);
    }
    reached += r.reached_end - r.reached_begin;
    ASSERT_GE(nav.active(), last_active);
    last_active = nav.active();
    if (nav.state() == NavState::following) {
      // The active subgoal lies just ahead: more than `reach`, at most a spacing more.
      const double ahead = nav.subgoal_arc(nav.active()) - nav.progress();
      EXPECT_GT(ahead, nav.config().reach - 1e-9);
      EXPECT_LE(ahead, nav.config().reach + nav.config().spacing + 0.5 + 1e-9);
    }
  }
  EXPECT_EQ(nav.state(), NavState::reached);
  EXPECT_EQ(nav.counters().plans, 1u);
  EXPECT_EQ(nav.counters().replans, 0u);
  EXPECT_NEAR(nav.route_length(), 400.0, 1e-6);
  ASSERT_EQ(nav.subgoal_count(), 101u);  // every 4 m, both ends
  for (std::size_t i = 0; i < nav.subgoal_count(); ++i) {
    EXPECT_NEAR(nav.subgoal_arc(i), 4.0 * static_cast<double>(i), 1e-9);
    // Raw subgoals in the odometry frame through the pose pair.
    double x = 0, y = 0;
    f.to_local(nav.subgoal_utm(i).x, nav.subgoal_utm(i).y, x, y);
    EXPECT_NEAR(nav.raw_local(i).x, x, 1e-6);
    EXPECT_NEAR(nav.raw_local(i).y, y, 1e-6);
  }
  EXPECT_EQ(reached, 100u);
  EXPECT_EQ(nav.active(), 100u);
  nav.snapshot(snap);
  EXPECT_EQ(snap.state, NavState::reached);
  EXPECT_TRUE(snap.has_active);
  EXPECT_EQ(snap.path_count, 1u);
  EXPECT_NEAR(snap.active_easting, kE0 + 200.0, 1e-6);
  EXPECT_NEAR(snap.active_northing, kN0 + 200.0, 1e-6);
}

TEST_F(OnTestGraph, PublishesThePathFromTheActiveSubgoal) {
  Navigator& nav = make(200.0, 200.0);
  ASSERT_TRUE(navigator);
  at(150.0, 0.0, 0.0, 1.0);
  nav.step(local, utm, nullptr);
  NavigationSnapshot snap(20);
  nav.snapshot(snap);
  ASSERT_TRUE(snap.has_active);
  EXPECT_EQ(snap.path_count, 20u);
  EXPECT_NEAR(snap.route_length, 250.0, 1e-6);
  // The robot is at the route's start; the active subgoal is the first beyond reach (4 m).
  EXPECT_EQ(snap.active, 1u);
  double x = 0, y = 0;
  f.to_local(kE0 + 154.0, kN0, x, y);
  EXPECT_NEAR(snap.active_pose.x, x, 1e-6);
  EXPECT_NEAR(snap.active_pose.y, y, 1e-6);
  EXPECT_NEAR(snap.active_pose.yaw, f.phi, 1e-9);  // along the road (grid east) in the odometry frame
  for (std::size_t k = 0; k < snap.path_count; ++k) {
    const double a = 154.0 + 4.0 * static_cast<double>(k);  // along the road: east to C, then north
    f.to_local(kE0 + std::min(a, 200.0), kN0 + std::max(a - 200.0, 0.0), x, y);
    EXPECT_NEAR(snap.path[k].x, x, 1e-6);
    EXPECT_NEAR(snap.path[k].y, y, 1e-6);
    EXPECT_FALSE(snap.path[k].corrected);  // no terrain map yet
  }
}

TEST_F(OnTestGraph, ReplansWhenTheRobotTakesAnotherRoad) {
  Navigator& nav = make(200.0, 200.0);
  ASSERT_TRUE(navigator);
  // Along the main road to B, then down the side road.
  const auto path = walk({{0, 0}, {100, 0}, {100, -120}}, 0.5);
  double t = 0.0;
  double off_at = -1.0;
  for (const auto& p : path) {
    at(p[0], p[1], p[2], t += 0.25);
    nav.step(local, utm, nullptr);
    if (off_at < 0.0 && p[1] < -nav.config().leave_distance) off_at = t;
    if (nav.counters().replans > 0) break;
  }
  ASSERT_EQ(nav.counters().replans, 1u);
  EXPECT_EQ(nav.counters().plans, 2u);
  // Re-planned `leave_time` after it left (and not before).
  EXPECT_NEAR(t - off_at, nav.config().leave_time, 0.3);
  // The new route starts where the robot is and leads back up to B, then on to D.
  EXPECT_NEAR(nav.route().front().x, utm.easting, 1e-6);
  EXPECT_NEAR(nav.route().front().y, utm.northing, 1e-6);
  EXPECT_NEAR(nav.route_length(), -(utm.northing - kN0) + 100.0 + 200.0, 1e-6);
  EXPECT_EQ(nav.state(), NavState::following);
  EXPECT_EQ(nav.active(), 1u);  // subgoal 0 is where the robot is
}

TEST_F(OnTestGraph, SaysWhenTheGoalCannotBeReachedAndRetries) {
  NavigatorConfig c;
  c.replan_interval = 5.0;
  Navigator& nav = make(1050.0, 1000.0, c);  // on the island
  ASSERT_TRUE(navigator);
  for (int i = 0; i <= 40; ++i) {  // 10 s
    at(10.0, 0.0, 0.0, 0.25 * i);
    nav.step(local, utm, nullptr);
  }
  EXPECT_EQ(nav.state(), NavState::failed);
  EXPECT_EQ(nav.counters().plan_failures, 3u);  // at 0, 5 and 10 s
  EXPECT_NE(std::string(nav.message()).find("no route"), std::string::npos);
  NavigationSnapshot snap(8);
  nav.snapshot(snap);
  EXPECT_FALSE(snap.has_active);
  EXPECT_EQ(snap.path_count, 0u);
}

// Orders from outside (the DDS goal topics): a goal in each frame, taken
// and planned at the next step; the impossible ones refused with their
// reason while the robot keeps the route it follows.
GoalRequest geo_goal(const osm::RoadGraph& g, double de, double dn) {
  GoalRequest r;
  r.frame = GoalFrame::geographic;
  EXPECT_TRUE(g.to_latlon(kE0 + de, kN0 + dn, r.a, r.b));
  return r;
}

TEST_F(OnTestGraph, WithoutAGoalItIdlesUntilOneIsOrdered) {
  auto made = Navigator::create(g, NavigatorConfig{}, {});
  ASSERT_TRUE(made.navigator) << made.error;
  Navigator& nav = *made.navigator;
  at(10.0, 0.0, 0.0, 1.0);
  nav.step(local, utm, nullptr);
  EXPECT_EQ(nav.state(), NavState::idle);
  NavigationSnapshot snap(8);
  nav.snapshot(snap);
  EXPECT_FALSE(snap.report.has_goal);
  EXPECT_FALSE(snap.has_active);
  ASSERT_TRUE(nav.set_goal(geo_goal(g, 200.0, 200.0)));
  EXPECT_EQ(nav.state(), NavState::planning);
  at(10.5, 0.0, 0.0, 1.1);
  const StepResult r = nav.step(local, utm, nullptr);
  EXPECT_TRUE(r.planned);
  EXPECT_EQ(nav.state(), NavState::following);
  EXPECT_NEAR(nav.route_length(), 190.0 - 0.5 + 200.0, 1e-6);
  nav.snapshot(snap);
  EXPECT_TRUE(snap.report.has_goal);
  EXPECT_NEAR(snap.report.goal_easting, kE0 + 200.0, 1e-6);
  EXPECT_NEAR(snap.report.goal_northing, kN0 + 200.0, 1e-6);
  EXPECT_NEAR(snap.report.remaining, 389.5, 1e-6);
  EXPECT_EQ(snap.counters.goals, 1u);
  EXPECT_EQ(snap.report.refusal[0], '\0');
}

TEST_F(OnTestGraph, ANewGoalReplansAtOnceInEachFrame) {
  ASSERT_TRUE(following_to_d());
  Navigator& nav = *navigator;
  // Geographic: down the side road to S. Planned at the next step, though
  // replan_interval (5 s) has not passed since the first plan.
  ASSERT_TRUE(nav.set_goal(geo_goal(g, 100.0, -150.0)));
  at(51.0, 0.0, 0.0, 1.2);
  EXPECT_TRUE(nav.step(local, utm, nullptr).planned);
  EXPECT_EQ(nav.state(), NavState::following);
  EXPECT_NEAR(nav.route_length(), 49.0 + 150.0, 1e-6);
  EXPECT_NEAR(nav.route().back().x, kE0 + 100.0, 1e-6);
  EXPECT_NEAR(nav.route().back().y, kN0 - 150.0, 1e-6);
  // UTM: back to A.
  GoalRequest u;
  u.frame = GoalFrame::utm;
  u.a = kE0 + 2.0;
  u.b = kN0 + 1.0;  // a metre off the road: projected onto it
  ASSERT_TRUE(nav.set_goal(u));
  at(52.0, 0.0, M_PI, 1.4);
  EXPECT_TRUE(nav.step(local, utm, nullptr).planned);
  EXPECT_NEAR(nav.route().back().x, kE0 + 2.0, 1e-6);
  EXPECT_NEAR(nav.route().back().y, kN0, 1e-6);
  // Odometry frame: C, given in the robot's local frame.
  GoalRequest o;
  o.frame = GoalFrame::odom;
  f.to_local(kE0 + 200.0, kN0, o.a, o.b);
  ASSERT_TRUE(nav.set_goal(o));
  at(52.5, 0.0, 0.0, 1.6);
  EXPECT_TRUE(nav.step(local, utm, nullptr).planned);
  EXPECT_NEAR(nav.route().back().x, kE0 + 200.0, 1e-6);
  EXPECT_NEAR(nav.route().back().y, kN0, 1e-6);
  EXPECT_NEAR(nav.route_length(), 147.5, 1e-6);
  EXPECT_EQ(nav.counters().goals, 4u);  // the config's and three orders
  EXPECT_EQ(nav.counters().goals_refused, 0u);
  EXPECT_EQ(nav.counters().plans, 4u);
}

TEST_F(OnTestGraph, ImpossibleGoalsAreRefusedWithTheirReasonAndTheRouteIsKept) {
  ASSERT_TRUE(following_to_d());
  Navigator& nav = *navigator;
  const double length = nav.route_length();
  NavigationSnapshot snap(8);
  auto refused = [&](const GoalRequest& r, const char* reason) {
    const std::uint64_t revision = [&] { nav.snapshot(snap); return snap.goal_revision; }();
    EXPECT_FALSE(nav.set_goal(r));
    nav.snapshot(snap);
    EXPECT_NE(std::string(snap.report.refusal.data()).find(reason), std::string::npos) << snap.report.refusal.data();
    EXPECT_GT(snap.goal_revision, revision);
    EXPECT_EQ(nav.state(), NavState::following);
    EXPECT_NEAR(nav.route_length(), length, 1e-9);
    EXPECT_NEAR(snap.report.goal_easting, kE0 + 200.0, 1e-6);  // the goal in use is still D
  };
  GoalRequest nan = geo_goal(g, 10.0, 0.0);
  nan.a = std::nan("");
  refused(nan, "not finite");
  GoalRequest inf;
  inf.frame = GoalFrame::odom;
  inf.a = std::numeric_limits<double>::infinity();
  refused(inf, "not finite");
  refused(geo_goal(g, 500.0, 500.0), "max_snap");  // 300 m from the nearest road
  GoalRequest far;  // Sydney: another zone and hemisphere
  far.a = -33.87;
  far.b = 151.21;
  refused(far, "outside the map's UTM zone 32N (it is in 56S)");
  GoalRequest pole;
  pole.a = 89.0;
  pole.b = 9.0;
  refused(pole, "no position UTM covers");
  GoalRequest frame;
  frame.frame = GoalFrame::unknown;
  std::snprintf(frame.frame_id.data(), frame.frame_id.size(), "base_link");
  refused(frame, "frame 'base_link'");
  // The island: valid, near a road, but no route leads there. Refused at
  // the next step, when A* finds no way; the robot keeps following.
  ASSERT_TRUE(nav.set_goal(geo_goal(g, 1050.0, 1000.0)));
  at(51.0, 0.0, 0.0, 1.2);
  EXPECT_FALSE(nav.step(local, utm, nullptr).planned);
  nav.snapshot(snap);
  EXPECT_NE(std::string(snap.report.refusal.data()).find("no route"), std::string::npos) << snap.report.refusal.data();
  EXPECT_EQ(nav.state(), NavState::following);
  EXPECT_NEAR(snap.report.goal_easting, kE0 + 200.0, 1e-6);
  EXPECT_NEAR(nav.route_length(), length, 1e-9);
  EXPECT_EQ(snap.counters.goals, 8u);  // the config's and seven orders
  EXPECT_EQ(snap.counters.goals_refused, 7u);
  EXPECT_TRUE(snap.has_active);
  // A good goal after them clears the refusal.
  ASSERT_TRUE(nav.set_goal(geo_goal(g, 100.0, -150.0)));
  nav.snapshot(snap);
  EXPECT_EQ(snap.report.refusal[0], '\0');
}

TEST_F(OnTestGraph, AnOdometryGoalNeedsAPoseFirst) {
  auto made = Navigator::create(g, NavigatorConfig{}, {});
  ASSERT_TRUE(made.navigator);
  GoalRequest o;
  o.frame = GoalFrame::odom;
  EXPECT_FALSE(made.navigator->set_goal(o));
  EXPECT_NE(std::string(made.navigator->refusal()).find("no UTM pose yet"), std::string::npos);
  EXPECT_EQ(made.navigator->state(), NavState::idle);
}

TEST_F(OnTestGraph, AnUnroutableGoalWithNoRouteToKeepFailsAndIsRetried) {
  auto made = Navigator::create(g, NavigatorConfig{}, {});
  ASSERT_TRUE(made.navigator);
  Navigator& nav = *made.navigator;
  ASSERT_TRUE(nav.set_goal(geo_goal(g, 1050.0, 1000.0)));
  for (int i = 0; i <= 24; ++i) {  // 6 s
    at(10.0, 0.0, 0.0, 1.0 + 0.25 * i);
    nav.step(local, utm, nullptr);
  }
  EXPECT_EQ(nav.state(), NavState::failed);
  EXPECT_EQ(nav.counters().plan_failures, 2u);  // at once, and replan_interval (5 s) later
  NavigationSnapshot snap(8);
  nav.snapshot(snap);
  EXPECT_TRUE(snap.report.has_goal);
  EXPECT_FALSE(snap.has_active);
}

TEST_F(OnTestGraph, CancelDropsTheRouteUntilTheNextGoal) {
  ASSERT_TRUE(following_to_d());
  Navigator& nav = *navigator;
  nav.cancel();
  EXPECT_EQ(nav.state(), NavState::cancelled);
  for (int i = 0; i < 30; ++i) {  // 7.5 s: no re-plan, no subgoal
    at(50.0 + 0.5 * i, 0.0, 0.0, 1.25 + 0.25 * i);
    nav.step(local, utm, nullptr);
  }
  NavigationSnapshot snap(8);
  nav.snapshot(snap);
  EXPECT_EQ(snap.state, NavState::cancelled);
  EXPECT_FALSE(snap.has_active);
  EXPECT_EQ(snap.path_count, 0u);
  EXPECT_EQ(snap.counters.plans, 1u);
  EXPECT_EQ(snap.counters.cancels, 1u);
  ASSERT_TRUE(nav.set_goal(geo_goal(g, 0.0, 0.0)));
  at(65.0, 0.0, M_PI, 9.0);
  EXPECT_TRUE(nav.step(local, utm, nullptr).planned);
  EXPECT_EQ(nav.state(), NavState::following);
  EXPECT_NEAR(nav.route_length(), 65.0, 1e-6);
}

// Street cells where `street(e, n)` (UTM), grass elsewhere, over the map
// centred on the robot (odometry frame).
void paint(TerrainClassMap& map, const Frames& f, double cx, double cy, const std::function<bool(double, double)>& street) {
  test::paint_terrain(map, cx, cy, [&](double x, double y) {
    double e = 0, n = 0;
    f.to_utm(x, y, e, n);
    return street(e, n);
  });
}

TEST_F(OnTestGraph, AlignsTheSubgoalsToTheStreetTheTerrainMapShows) {
  Navigator& nav = make(200.0, 0.0);
  ASSERT_TRUE(navigator);
  // The real street runs 2.5 m north of where OpenStreetMap has it; the
  // robot drives on it.
  auto street = [](double, double n) { return std::abs(n - kN0 - 2.5) < 1.5; };
  TerrainClassMap map;
  double t = 0.0, raw_sq = 0.0, corrected_sq = 0.0;
  std::size_t n_reached = 0;
  std::size_t k = 0;
  for (const auto& p : walk({{0, 2.5}, {190, 2.5}}, 0.5)) {
    at(p[0], p[1], p[2], t += 0.25);
    const bool new_map = k++ % 2 == 0;  // a terrain map every metre
    if (new_map) paint(map, f, local.x, local.y, street);
    const StepResult r = nav.step(local, utm, new_map ? &map : nullptr);
    for (std::size_t i = r.reached_begin; i < r.reached_end; ++i) {
      if (nav.subgoal_arc(i) < 20.0) continue;  // the first window settles
      double e = 0, n = 0;
      const subgoals::Vec2 c = nav.corrected(i);
      f.to_utm(c.x, c.y, e, n);
      corrected_sq += (n - kN0 - 2.5) * (n - kN0 - 2.5);
      raw_sq += (nav.subgoal_utm(i).y - kN0 - 2.5) * (nav.subgoal_utm(i).y - kN0 - 2.5);
      EXPECT_TRUE(nav.is_corrected(i));
      ++n_reached;
    }
  }
  ASSERT_GT(n_reached, 35u);
  const double raw = std::sqrt(raw_sq / static_cast<double>(n_reached));
  const double corrected = std::sqrt(corrected_sq / static_cast<double>(n_reached));
  EXPECT_NEAR(raw, 2.5, 1e-6);
  EXPECT_LT(corrected, 0.6) << "raw " << raw;
  EXPECT_GT(nav.counters().updates, 180u);
  EXPECT_EQ(nav.counters().catch_up_updates, 0u);  // one subgoal joins at a time
}

// Junction (a) of the `junctions` drives: an X crossing whose node
// OpenStreetMap has 7 m too far along the straight-on road, so the mapped way
// runs past the junction and comes back askew to the branch. As the robot
// turns, its place on the mapped route jumps forward and several subgoals
// join the aligner in one step; each push after the first is preceded by an
// update (a catch-up update), so every subgoal leaves the window estimated
// with newer ones after it. The subgoals reached near the junction are all
// corrected, and lie nearer the road the robot takes than the map has them.
TEST(Navigator, CatchesUpWhenSubgoalsJoinTogetherAtAJunctionMappedTooFarAlong) {
  //   A(0,0) -- N(47,1) -- E(90,0)   the straight-on road; N is 7 m too far
  //             N -- P(41,20) -- Q(41,70)   the branch, askew from N
  std::vector<osm::RoadVertex> v = {{kE0, kN0, 1},          {kE0 + 47, kN0 + 1, 2}, {kE0 + 90, kN0, 3},
                                    {kE0 + 41, kN0 + 20, 4}, {kE0 + 41, kN0 + 70, 5}};
  std::vector<osm::RoadWay> ways = {{10, "track", "straight on"}, {11, "track", "branch"}};
  const osm::RoadGraph g = osm::RoadGraph::build(32, true, v, ways, {{0, 1, 2}, {1, 3, 4}}, {0, 0});
  auto made = Navigator::create(g, config_to(g, 41.0, 70.0), {});
  ASSERT_TRUE(made.navigator) << made.error;
  Navigator& nav = *made.navigator;
  const Frames f;
  // The real roads, 3 m wide: along n = 0, and north along e = 40.
  auto roads = [](double e, double n) {
    return std::abs(n - kN0) < 1.5 || (std::abs(e - kE0 - 40.0) < 1.5 && n > kN0 - 1.5);
  };
  const auto off_route = [](double e, double n) {
    const double x = e - kE0, y = n - kN0;
    const double east = x <= 40.0 ? std::abs(y) : std::hypot(x - 40.0, y);
    const double north = y >= 0.0 ? std::abs(x - 40.0) : std::hypot(x - 40.0, y);
    return std::min(east, north);
  };
  TerrainClassMap map;
  pose::LocalPose local;
  pose::UtmPose utm;
  double t = 0.0, worst = 0.0, worst_raw = 0.0;
  std::size_t near_junction = 0, most_reached = 0;
  for (const auto& p : walk({{0, 0}, {40, 0}, {40, 75}}, 0.5)) {
    poses(f, kE0 + p[0], kN0 + p[1], p[2], t += 0.25, local, utm);
    paint(map, f, local.x, local.y, roads);  // a terrain map every half metre, the terrain thread's step
    const StepResult r = nav.step(local, utm, &map);
    most_reached = std::max(most_reached, r.reached_end - r.reached_begin);
    for (std::size_t i = r.reached_begin; i < r.reached_end; ++i) {
      if (p[0] < 32.0 || p[1] > 12.0) continue;  // the robot 8 m before to 12 m after the junction
      EXPECT_TRUE(nav.is_corrected(i)) << i;
      double e = 0, n = 0;
      const subgoals::Vec2 q = nav.corrected(i);
      f.to_utm(q.x, q.y, e, n);
      worst = std::max(worst, off_route(e, n));
      worst_raw = std::max(worst_raw, off_route(nav.subgoal_utm(i).x, nav.subgoal_utm(i).y));
      ++near_junction;
    }
  }
  std::printf("near the junction: %zu subgoals, farthest %.2f m from the route (raw %.2f m); %llu catch-up updates\n",
              near_junction, worst, worst_raw, static_cast<unsigned long long>(nav.counters().catch_up_updates));
  EXPECT_EQ(nav.state(), NavState::reached);
  EXPECT_GE(near_junction, 5u);
  EXPECT_GE(most_reached, 3u);  // the jump: several subgoals passed in one step
  EXPECT_GT(nav.counters().catch_up_updates, 0u);
  EXPECT_GT(worst_raw, 5.0);
  EXPECT_LT(worst, 3.0);
}

TEST(NavigationTask, PlansAlignsAndPublishesWithoutAllocating) {
  ASSERT_TRUE(alloc_guard::hook_installed());
  const osm::RoadGraph g = test_graph();
  auto made = Navigator::create(g, config_to(g, 200.0, 200.0), {});
  ASSERT_TRUE(made.navigator) << made.error;
  Mailbox<pose::PoseSnapshot> poses_in;
  Broadcast<TerrainClassMap> maps(1, perception::TerrainMapShape{});
  Mailbox<NavigationSnapshot> out(made.navigator->config().path_poses);
  NavigationTask task(*made.navigator, poses_in, &maps.reader(0), out);
  const Frames f;
  auto street = [](double e, double n) {
    return (std::abs(n - kN0 - 1.0) < 1.5 && e < kE0 + 201.5) || (std::abs(e - kE0 - 201.0) < 1.5 && n > kN0 - 0.5);
  };
  TerrainClassMap map;
  const auto path = walk({{0, 1}, {201, 1}, {201, 200}}, 0.5);

  alloc_guard::set_fatal(false);
  alloc_guard::reset_counters();
  alloc_guard::mark_realtime_thread("navigation-test");
  ASSERT_TRUE(alloc_guard::arm());
  double t = 0.0;
  std::uint64_t published = 0, last_plan = 0;
  std::size_t last_active = 0;
  for (std::size_t k = 0; k < path.size(); ++k) {
    const auto& p = path[k];
    pose::PoseSnapshot& s = poses_in.write_slot();
    poses(f, kE0 + p[0], kN0 + p[1], p[2], t += 0.25, s.local, s.utm);
    const double lx = s.local.x, ly = s.local.y;
    poses_in.publish();
    if (k % 2 == 0) {  // a terrain map every metre, as the terrain thread would publish it
      paint(map, f, lx, ly, street);
      maps.write_slot().copy_from(map);
      maps.publish();
    }
    task.run({});
    if (const NavigationSnapshot* n = out.try_read()) {
      ++published;
      last_plan = n->plan;
      EXPECT_GE(n->active, last_active);
      last_active = n->active;
    }
  }
  alloc_guard::disarm();
  alloc_guard::unmark_current_thread();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
  const NavigationTaskStatus st = task.status();
  EXPECT_EQ(st.state, NavState::reached);
  EXPECT_EQ(last_plan, 1u);
  EXPECT_EQ(last_active, 100u);
  EXPECT_GT(published, 100u);
  EXPECT_GT(st.navigator.updates, 350u);
  EXPECT_EQ(st.poses, path.size());
}

TEST(Navigator, PlansOnLiechtensteinLikeTheRouter) {
  auto loaded = osm::load_road_graph(test::shared_data("osm/osm2pgsql_liechtenstein-2013-08-03.osm.pbf"));
  ASSERT_TRUE(loaded.graph) << loaded.error;
  const osm::RoadGraph& g = *loaded.graph;
  NavigatorConfig c;
  c.goal_lat = 47.1660;
  c.goal_lon = 9.5100;
  auto made = Navigator::create(g, c, {});
  ASSERT_TRUE(made.navigator) << made.error;
  double e = 0, n = 0;
  ASSERT_TRUE(g.to_utm(47.1410, 9.5209, e, n));
  pose::LocalPose local;
  local.time_ns = 1;
  pose::UtmPose utm;
  utm.position_valid = utm.heading_valid = true;
  utm.easting = e;
  utm.northing = n;
  made.navigator->step(local, utm, nullptr);
  ASSERT_EQ(made.navigator->state(), NavState::following);
  // The same route and subgoals as the router and subsample_path give.
  osm::Router router(g);
  std::vector<osm::Point2> route, goals;
  double ge = 0, gn = 0;
  ASSERT_TRUE(g.to_utm(c.goal_lat, c.goal_lon, ge, gn));
  const osm::RouteStats st = router.route(*g.project(e, n), *g.project(ge, gn), route);
  ASSERT_TRUE(st.found);
  osm::subsample_path(route, 4.0, goals);
  EXPECT_NEAR(made.navigator->route_length(), st.length, 1e-6);
  ASSERT_EQ(made.navigator->subgoal_count(), goals.size());
  for (std::size_t i = 0; i < goals.size(); ++i) {
    EXPECT_EQ(made.navigator->subgoal_utm(i).x, goals[i].x);
    EXPECT_EQ(made.navigator->subgoal_utm(i).y, goals[i].y);
  }
  EXPECT_NEAR(st.length, 3787.2, 0.1);
}

TEST(NavigationSection, ParsesAndRejectsWithFileAndLine) {
  const std::string osm = std::filesystem::absolute(test::shared_data("osm/osm2pgsql_liechtenstein-2013-08-03.osm.pbf")).string();
  const ConfigNode ok = ConfigNode::parse("osm: " + osm + "\ngoal: [47.166, 9.51]\nhighways: [track, path]\nspacing: 3\n"
                                          "aligner: {samples: 5000, sequence: 3, unknown_cells: known-only, along_prior: 0, corner_sigma: 4, corner_turn: 0.1, separation: 0.5}\n",
                                          "nav.yaml");
  const NavigationSection s = parse_navigation_section(ok);
  EXPECT_EQ(s.osm, osm);
  EXPECT_EQ(s.profile.highways, (std::vector<std::string>{"track", "path"}));
  EXPECT_EQ(s.navigator.spacing, 3.0);
  EXPECT_EQ(s.navigator.aligner.samples, 5000u);
  EXPECT_EQ(s.navigator.aligner.sequence, 3);
  EXPECT_TRUE(s.navigator.aligner.known_cells_only);
  EXPECT_EQ(s.navigator.aligner.along_prior, 0.0);
  EXPECT_EQ(s.navigator.aligner.corner_sigma, 4.0);
  EXPECT_EQ(s.navigator.aligner.corner_turn, 0.1);
  EXPECT_EQ(s.navigator.aligner.separation, 0.5);
  auto error_of = [&](const std::string& text) -> std::string {
    try {
      parse_navigation_section(ConfigNode::parse(text, "nav.yaml"));
    } catch (const ConfigError& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(error_of("osm: /nonexistent.osm.pbf\ngoal: [47, 9]\n").find("no such file"), std::string::npos);
  const std::string bad_goal = error_of("osm: " + osm + "\ngoal: [47]\n");
  EXPECT_NE(bad_goal.find("nav.yaml:2"), std::string::npos) << bad_goal;
  EXPECT_NE(error_of("osm: " + osm + "\ngoal: [47, 9]\nreach: 9\n").find("reach"), std::string::npos);
  EXPECT_NE(error_of("osm: " + osm + "\ngoal: [47, 9]\naligner: {samples: 60000}\n").find("samples"), std::string::npos);
  EXPECT_NE(error_of("osm: " + osm + "\ngoal: [47, 9]\naligner: {corner_sigma: -1}\n").find("corner_sigma"), std::string::npos);
  EXPECT_NE(error_of("osm: " + osm + "\ngoal: [47, 9]\naligner: {separation: 5}\n").find("separation"), std::string::npos);
  EXPECT_NE(error_of("osm: " + osm + "\ngoal: [47, 9]\naligner: {corner_turn: 2}\n").find("corner_turn"), std::string::npos);
  EXPECT_NE(error_of("osm: " + osm + "\ngoal: [47, 9]\nlookahed: 3\n").find("lookahed"), std::string::npos);
}

}  // namespace
}  // namespace trailnav::nav

namespace trailnav::nav {
namespace {

// Orders through the task's queue, as the DDS command reader hands them
// over: taken before the step, answered in the published snapshot, and no
// heap use on the task's thread.
TEST(NavigationTask, TakesOrdersFromItsQueueWithoutAllocating) {
  ASSERT_TRUE(alloc_guard::hook_installed());
  const osm::RoadGraph g = test_graph();
  auto made = Navigator::create(g, NavigatorConfig{}, {});  // no goal: idle
  ASSERT_TRUE(made.navigator) << made.error;
  Mailbox<pose::PoseSnapshot> poses_in;
  Mailbox<NavigationSnapshot> out(made.navigator->config().path_poses);
  NavCommandQueue commands;
  NavigationTask task(*made.navigator, poses_in, nullptr, out);
  task.set_commands(&commands);
  const Frames f;
  NavCommand go;
  go.goal = geo_goal(g, 200.0, 200.0);
  NavCommand bad;
  bad.goal.a = std::nan("");
  NavCommand stop;
  stop.kind = NavCommand::Kind::cancel;

  alloc_guard::set_fatal(false);
  alloc_guard::reset_counters();
  alloc_guard::mark_realtime_thread("navigation-orders-test");
  ASSERT_TRUE(alloc_guard::arm());
  auto run_at = [&](double e, double t) {
    pose::PoseSnapshot& s = poses_in.write_slot();
    poses(f, kE0 + e, kN0, 0.0, t, s.local, s.utm);
    poses_in.publish();
    task.run({});
  };
  run_at(10.0, 1.0);
  const NavState idle = task.status().state;  // nothing changed: nothing published
  EXPECT_TRUE(commands.try_push(go));
  run_at(10.5, 1.1);
  const NavState following = out.try_read() != nullptr ? out.last_read().state : NavState::idle;
  EXPECT_TRUE(commands.try_push(bad));
  run_at(11.0, 1.2);
  const bool refused = out.try_read() != nullptr && out.last_read().report.refusal[0] != '\0';
  const NavState still = out.last_read().state;
  EXPECT_TRUE(commands.try_push(stop));
  task.run({});  // an order alone, without a new pose, is answered too
  const NavState cancelled = out.try_read() != nullptr ? out.last_read().state : NavState::idle;
  alloc_guard::disarm();
  alloc_guard::unmark_current_thread();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
  EXPECT_EQ(idle, NavState::idle);
  EXPECT_EQ(following, NavState::following);
  EXPECT_TRUE(refused);
  EXPECT_EQ(still, NavState::following);
  EXPECT_EQ(cancelled, NavState::cancelled);
  EXPECT_EQ(task.status().commands, 3u);
}

}  // namespace
}  // namespace trailnav::nav
