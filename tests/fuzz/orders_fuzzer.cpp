// Fuzzes what trailnavd does with orders from outside: any sequence of goals
// (geographic, UTM, odometry frame or an unknown frame, with any bit pattern
// as coordinates), cancels and navigation steps (the robot anywhere, at any
// time) on a small road network. Never a crash; every goal is taken or
// refused with a reason; the counts add up; the route, the subgoals and the
// published path stay finite and within their buffers.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <vector>

#include "check.hpp"

#include "trailnav/navigation/navigator/navigator.hpp"
#include "trailnav/navigation/osm/road_graph.hpp"

using namespace trailnav;

namespace {

constexpr double kE0 = 500000.0, kN0 = 5200000.0;  // zone 32N

// A main road with a side road and an island nobody can reach.
const osm::RoadGraph& graph() {
  static const osm::RoadGraph g = [] {
    std::vector<osm::RoadVertex> v = {{kE0, kN0, 1},           {kE0 + 100, kN0, 2},        {kE0 + 200, kN0, 3},
                                      {kE0 + 200, kN0 + 200, 4}, {kE0 + 100, kN0 - 150, 5}, {kE0 + 1000, kN0 + 1000, 6},
                                      {kE0 + 1100, kN0 + 1000, 7}};
    std::vector<osm::RoadWay> ways = {{10, "track", "main"}, {11, "track", "side"}, {12, "track", "island"}};
    return osm::RoadGraph::build(32, true, v, ways, {{0, 1, 2, 3}, {1, 4}, {5, 6}}, {0, 0, 0});
  }();
  return g;
}

struct Reader {
  const std::uint8_t* p;
  std::size_t n;
  bool empty() const { return n == 0; }
  std::uint8_t byte() {
    if (n == 0) return 0;
    --n;
    return *p++;
  }
  double any_double() {
    std::uint64_t bits = 0;
    for (int i = 0; i < 8; ++i) bits = (bits << 8) | byte();
    double d;
    std::memcpy(&d, &bits, sizeof d);
    return d;
  }
  // Mostly near the network, sometimes anything at all.
  double coordinate(double centre) {
    const std::uint8_t mode = byte();
    if (mode < 64) return any_double();
    return centre + (static_cast<double>(byte()) * 256.0 + byte() - 32768.0) * 0.05;
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  nav::NavigatorConfig config;
  if (size > 0 && data[0] % 2 == 0) {  // half the runs start with the config's goal
    graph().to_latlon(kE0 + 200.0, kN0 + 200.0, config.goal_lat, config.goal_lon);
  }
  auto made = nav::Navigator::create(graph(), config, {});
  check(made.navigator != nullptr);
  nav::Navigator& navigator = *made.navigator;
  nav::NavigationSnapshot snap(16);
  Reader in{data, size};
  double t = 0.0;
  std::uint64_t offered = std::isnan(config.goal_lat) ? 0 : 1, refused_now = 0;
  while (!in.empty()) {
    const std::uint8_t op = in.byte() % 6;
    if (op <= 3) {
      nav::GoalRequest g;
      g.frame = static_cast<nav::GoalFrame>(op);
      if (g.frame == nav::GoalFrame::geographic) {
        g.a = in.coordinate(46.95);
        g.b = in.coordinate(9.0);
      } else {
        g.a = in.coordinate(g.frame == nav::GoalFrame::utm ? kE0 + 100.0 : 0.0);
        g.b = in.coordinate(g.frame == nav::GoalFrame::utm ? kN0 : 0.0);
      }
      for (std::size_t i = 0; i + 1 < g.frame_id.size(); ++i) g.frame_id[i] = static_cast<char>(in.byte());
      ++offered;
      const std::uint64_t before = navigator.counters().goals_refused;
      const bool taken = navigator.set_goal(g);
      const bool refused = navigator.counters().goals_refused == before + 1;
      check(taken != refused);
      check(taken || navigator.refusal()[0] != '\0');
      refused_now += refused ? 1 : 0;
    } else if (op == 4) {
      navigator.cancel();
    } else {
      // A step: the robot somewhere, heading anywhere, some time later.
      pose::LocalPose local;
      pose::UtmPose utm;
      utm.position_valid = utm.heading_valid = in.byte() != 0;
      utm.zone = 32;
      utm.easting = in.coordinate(kE0 + 100.0);
      utm.northing = in.coordinate(kN0);
      utm.yaw = in.coordinate(0.0);
      utm.covariance = Eigen::Matrix3d::Identity() * (in.byte() / 16.0);
      t += in.byte() * 0.05;
      local.time_ns = static_cast<std::int64_t>(t * 1e9);
      local.x = in.coordinate(0.0);
      local.y = in.coordinate(0.0);
      local.yaw = in.coordinate(0.0);
      local.source = pose::PoseSource::gyro_odometry;
      navigator.step(local, utm, nullptr);
    }
    navigator.snapshot(snap);
    check(snap.path_count <= snap.path.size());
    check(snap.report.refusal.back() == '\0' || std::memchr(snap.report.refusal.data(), '\0', snap.report.refusal.size()));
    check(std::isfinite(navigator.route_length()));
    if (snap.has_active) check(snap.active < navigator.subgoal_count());
    for (std::size_t i = 0; i < snap.path_count; ++i) check(std::isfinite(snap.path[i].x) && std::isfinite(snap.path[i].y));
  }
  // Routes found later may refuse more (no route from the robot), never fewer.
  check(navigator.counters().goals == offered);
  check(navigator.counters().goals_refused >= refused_now);
  return 0;
}
