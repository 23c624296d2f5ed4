// trailnavd's robot config: the shipped examples are valid, and every kind of
// mistake is one error naming the file, the line and the key.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iterator>
#include <fstream>
#include <string>

#include "daemon.hpp"
#include "robot_config.hpp"
#include "task_presets.hpp"

using namespace trailnav;
namespace fs = std::filesystem;

namespace {

const char* kMinimal =
    "runtime: {realtime: off}\n"
    "lidar: {model: VLP-16, data: 127.0.0.1:2368}\n"
    "obstacles: {model: PC}\n"
    "dds: {domain: 3}\n"
    "tasks:\n"
    "  - {name: lidar, kind: periodic, rate_hz: 1000, budget_ms: 0.5}\n"
    "  - {name: obstacles, kind: event, budget_ms: 20}\n";

// The GPS, IMU and pose sections and their tasks: what navigation and mapping build on.
const char* kPoseTasks =
    "  - {name: gps, kind: periodic, rate_hz: 50, budget_ms: 1}\n"
    "  - {name: imu, kind: periodic, rate_hz: 400, budget_ms: 1}\n"
    "  - {name: pose, kind: periodic, rate_hz: 100, budget_ms: 1}\n";
const char* kPoseSections =
    "gps: {link: 'udp:127.0.0.1:10110'}\nimu: {link: 'udp:127.0.0.1:10111', protocol: line}\npose: {antenna: [0, 0, 1]}\n";

// Writes `text` next to the repository's board/robots (so relative paths resolve the same way).
std::string load_error(const std::string& text) {
  const fs::path p = fs::path("board/robots") / ("test-" + std::to_string(::getpid()) + ".yaml");
  { std::ofstream(p) << text; }
  const auto r = daemon::load_robot_config(p.string());
  fs::remove(p);
  return r.config ? std::string() : r.error;
}

// A file's text (the shipped configs).
std::string text_of(const std::string& path) {
  std::ifstream in(path);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// `text` with its first `from` replaced by `to` (which must be there).
std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

daemon::RobotConfigResult load(const std::string& text) {
  const fs::path p = fs::path("board/robots") / ("test-" + std::to_string(::getpid()) + ".yaml");
  { std::ofstream(p) << text; }
  auto r = daemon::load_robot_config(p.string());
  fs::remove(p);
  return r;
}

}  // namespace

TEST(RobotConfig, ShippedExamplesAreValid) {
  for (const char* f : {"board/robots/bench.yaml", "board/robots/robot-example.yaml", "board/robots/bench-hdl64e.yaml",
                        "board/robots/robot-example-hdl64e.yaml"}) {
    const auto r = daemon::load_robot_config(f);
    ASSERT_TRUE(r.config) << r.error;
    EXPECT_TRUE(r.config->lidar.has_value()) << f;
    EXPECT_TRUE(r.config->obstacles.has_value()) << f;
    EXPECT_TRUE(r.config->pose.has_value()) << f;
    EXPECT_TRUE(r.config->terrain.has_value()) << f;
    EXPECT_TRUE(fs::exists(r.config->terrain->model)) << f;
    // The obstacle thread alone: the terrain thread takes the points it aligned.
    EXPECT_TRUE(r.config->terrain_shares_alignment()) << f;
    EXPECT_EQ(r.config->lidar->driver.revolution_readers, 1) << f;
    EXPECT_EQ(r.config->tasks.size(), r.config->mapping ? 9u : 8u) << f;
    EXPECT_EQ(r.config->task_preset, velodyne::model_info(r.config->lidar->model).name) << f;
    // Every preset's budgets cover what its tasks were measured to need: nothing said at start.
    EXPECT_TRUE(r.config->warnings.empty()) << f << ": " << (r.config->warnings.empty() ? "" : r.config->warnings[0]);
  }
  const auto bench = daemon::load_robot_config("board/robots/bench.yaml");
  EXPECT_NE(bench.config->dds.cyclone_xml.find("<AllowMulticast>false</AllowMulticast>"), std::string::npos);
  EXPECT_NE(bench.config->dds.cyclone_xml.find("127.0.0.1"), std::string::npos);
  EXPECT_TRUE(fs::exists(bench.config->can->dbc));
}

TEST(RobotConfig, MinimalLidarAndObstacleConfigIsValid) {
  EXPECT_EQ(load_error(kMinimal), "");
}

TEST(RobotConfig, TerrainNeedsAModelThatLoadsAndItsTask) {
  const std::string task = "  - {name: terrain, kind: periodic, rate_hz: 20, budget_ms: 30}\n";
  EXPECT_EQ(load_error(std::string(kMinimal) + task + "terrain: {model: ../models/terrain-sim.tnrf}\n"), "");
  std::string e = load_error(std::string(kMinimal) + task + "terrain: {min_points: 20}\n");
  EXPECT_NE(e.find("model"), std::string::npos) << e;
  e = load_error(std::string(kMinimal) + task + "terrain: {model: ../sim/trailnav-robot.dbc}\n");
  EXPECT_NE(e.find(":9:"), std::string::npos) << e;  // the line of the terrain section
  EXPECT_NE(e.find("not a trailnav terrain model"), std::string::npos) << e;
  e = load_error(std::string(kMinimal) + "terrain: {model: ../models/terrain-sim.tnrf}\n");
  EXPECT_NE(e.find("terrain"), std::string::npos) << e;  // no task for it
  // The shipped model learnt a VLP-16's remissions: refused for an HDL-64E.
  std::string hdl = std::string(kMinimal) + task + "terrain: {model: ../models/terrain-sim.tnrf}\n";
  hdl.replace(hdl.find("VLP-16"), 6,
              "HDL-64E, calibration: " +
                  fs::absolute("../shared/data/velodyne/calibration/ros_velodyne_64e_s2.1-sztaki.yaml").string());
  e = load_error(hdl);
  EXPECT_NE(e.find(":9:"), std::string::npos) << e;
  EXPECT_NE(e.find("trained on VLP-16 returns, this lidar is HDL-64E"), std::string::npos) << e;
  // The terrain registers the points the obstacle pipeline aligned: its range lies within theirs.
  e = load_error(std::string(kMinimal) + task + "terrain: {model: ../models/terrain-sim.tnrf, max_range: 45}\n");
  EXPECT_NE(e.find(":9: 'terrain': min_range..max_range 1..45 m reaches outside the 1..40 m of obstacles.features"),
            std::string::npos)
      << e;
  // The model learnt cells of at least 15 points: a config of 10 is refused, naming both.
  e = load_error(std::string(kMinimal) + task + "terrain: {model: ../models/terrain-sim.tnrf, min_points: 10}\n");
  EXPECT_NE(e.find(":9:"), std::string::npos) << e;
  EXPECT_NE(e.find("learnt the features of cells of 0.2 m with at least 15 points, returns from 1 to 30 m; this "
                   "config makes cells of 0.2 m with at least 10 points"),
            std::string::npos)
      << e;
  std::string narrow = std::string(kMinimal) + task + "terrain: {model: ../models/terrain-sim.tnrf}\n";
  narrow.replace(narrow.find("obstacles: {model: PC}"), 22, "obstacles: {model: PC, features: {max_range: 25}}");
  e = load_error(narrow);
  EXPECT_NE(e.find("1..30 m reaches outside the 1..25 m"), std::string::npos) << e;
}

TEST(RobotConfig, TheTerrainSharesTheObstacleAlignmentWhenBothUseThePoseAlike) {
  const std::string task = "  - {name: terrain, kind: periodic, rate_hz: 20, budget_ms: 30}\n";
  const std::string base = std::string(kMinimal) + task + "terrain: {model: ../models/terrain-sim.tnrf}\n";
  auto r = load(base);
  ASSERT_TRUE(r.config) << r.error;
  EXPECT_TRUE(r.config->terrain_shares_alignment());
  EXPECT_EQ(r.config->lidar->driver.revolution_readers, 1);
  // The obstacle map with poses, the terrain map without: each aligns its own.
  r.config->terrain_use_pose = false;
  EXPECT_FALSE(r.config->terrain_shares_alignment());
  r = load(std::string(kMinimal));
  ASSERT_TRUE(r.config) << r.error;
  EXPECT_FALSE(r.config->terrain_shares_alignment());
}

TEST(RobotConfig, NavigationNeedsTheUtmPoseAndItsTask) {
  const std::string osm = fs::absolute("../shared/data/osm/osm2pgsql_liechtenstein-2013-08-03.osm.pbf").string();
  const std::string nav = "navigation: {osm: " + osm + ", goal: [47.166, 9.51]}\n";
  const std::string task = "  - {name: navigation, kind: periodic, rate_hz: 10, budget_ms: 20}\n";
  const std::string pose_tasks = kPoseTasks, pose = kPoseSections;
  EXPECT_EQ(load_error(std::string(kMinimal) + task + pose_tasks + pose + nav), "");
  // Its task is required.
  std::string e = load_error(std::string(kMinimal) + pose_tasks + pose + nav);
  EXPECT_NE(e.find("navigation"), std::string::npos) << e;
  // Without GPS and pose: one error naming the navigation section.
  e = load_error(std::string(kMinimal) + task + nav);
  EXPECT_NE(e.find("navigation"), std::string::npos) << e;
  EXPECT_NE(e.find("'pose' and 'gps'"), std::string::npos) << e;
  // A goal that is not [lat, lon], with its line.
  e = load_error(std::string(kMinimal) + task + "navigation: {osm: " + osm + ", goal: [47.166]}\n");
  EXPECT_NE(e.find(":9:"), std::string::npos) << e;
  EXPECT_NE(e.find("latitude"), std::string::npos) << e;
  // A missing map file.
  e = load_error(std::string(kMinimal) + task + "navigation: {osm: nowhere.osm.pbf, goal: [47.166, 9.51]}\n");
  EXPECT_NE(e.find("no such file"), std::string::npos) << e;
}

// The mapping section: its task, the pose it is built from, GPS or not said
// in so many words, and its numbers in range, each mistake with its line.
TEST(RobotConfig, MappingNeedsThePoseItsTaskAndSaysWhetherItUsesGps) {
  const std::string task = "  - {name: mapping, kind: periodic, rate_hz: 2, budget_ms: 450}\n";
  const std::string pose_tasks = kPoseTasks, pose = kPoseSections;
  const auto ok = load(std::string(kMinimal) + task + pose_tasks + pose + "mapping: {max_keyframes: 1000, max_part: 200}\n");
  ASSERT_TRUE(ok.config) << ok.error;
  ASSERT_TRUE(ok.config->mapping.has_value());
  EXPECT_TRUE(ok.config->mapping->use_gps);  // a gps section: the map is tied to it
  EXPECT_EQ(ok.config->mapping->keyframes.max_keyframes, 1000u);
  EXPECT_EQ(ok.config->mapping->max_part, 200);
  // Its task is required.
  std::string e = load_error(std::string(kMinimal) + pose_tasks + pose + "mapping: {}\n");
  EXPECT_NE(e.find("mapping"), std::string::npos) << e;
  // Without the pose.
  e = load_error(std::string(kMinimal) + task + "mapping: {}\n");
  EXPECT_NE(e.find("'pose' section"), std::string::npos) << e;
  // Without GPS the map says so; with GPS it may not leave it out.
  const std::string no_gps_pose = "imu: {link: 'udp:127.0.0.1:10111', protocol: line}\npose: {}\n";
  const std::string no_gps_tasks =
      "  - {name: imu, kind: periodic, rate_hz: 400, budget_ms: 1}\n"
      "  - {name: pose, kind: periodic, rate_hz: 100, budget_ms: 1}\n";
  e = load_error(std::string(kMinimal) + task + no_gps_tasks + no_gps_pose + "mapping: {use_gps: true}\n");
  EXPECT_NE(e.find("use_gps"), std::string::npos) << e;
  const auto odometry_only = load(std::string(kMinimal) + task + no_gps_tasks + no_gps_pose + "mapping: {}\n");
  ASSERT_TRUE(odometry_only.config) << odometry_only.error;
  EXPECT_FALSE(odometry_only.config->mapping->use_gps);
  e = load_error(std::string(kMinimal) + task + pose_tasks + pose + "mapping: {use_gps: false}\n");
  EXPECT_NE(e.find("second parent"), std::string::npos) << e;
  // Numbers out of range and unknown keys, with the line.
  e = load_error(std::string(kMinimal) + task + pose_tasks + pose + "mapping: {max_part: 3}\n");
  EXPECT_NE(e.find(":15: 'mapping.max_part'"), std::string::npos) << e;
  e = load_error(std::string(kMinimal) + task + pose_tasks + pose + "mapping: {spacing: 2}\n");
  EXPECT_NE(e.find("spacing"), std::string::npos) << e;
  // Loop closures: trailnavd's defaults with `{}`, each key in its units,
  // the lidar's revolution reader counted, and nothing without a Velodyne.
  const auto loops = load(std::string(kMinimal) + task + pose_tasks + pose +
                          "mapping: {loops: {radius_m: 6, max_jump_deg: 10, points: 1500}}\n");
  ASSERT_TRUE(loops.config) << loops.error;
  ASSERT_TRUE(loops.config->mapping->loops.has_value());
  const auto& lc = *loops.config->mapping->loops;
  EXPECT_FALSE(lc.planar);
  EXPECT_DOUBLE_EQ(lc.search_radius, 6.0);
  EXPECT_NEAR(lc.max_jump_rad, 10.0 * 3.14159265358979 / 180.0, 1e-9);
  EXPECT_EQ(lc.max_points, 1500u);
  EXPECT_EQ(lc.capacity, loops.config->mapping->keyframes.max_keyframes);
  EXPECT_EQ(loops.config->lidar->driver.revolution_readers, 2);  // the obstacle thread's and the mapping's
  e = load_error(std::string(kMinimal) + task + pose_tasks + pose + "mapping: {loops: {min_overlap: 0}}\n");
  EXPECT_NE(e.find("mapping.loops.min_overlap"), std::string::npos) << e;
  e = load_error(std::string(kMinimal) + task + pose_tasks + pose + "mapping: {loops: {radius: 6}}\n");
  EXPECT_NE(e.find("radius"), std::string::npos) << e;
}

// trailnavd --check goes as far as start-up with the navigation section: the
// real Liechtenstein extract loads and the goal is placed on it; a goal far
// from every routable way is refused with its distance.
TEST(RobotConfig, CheckLoadsTheMapAndPlacesTheGoal) {
  const std::string osm = fs::absolute("../shared/data/osm/osm2pgsql_liechtenstein-2013-08-03.osm.pbf").string();
  const std::string rest =
      "  - {name: navigation, kind: periodic, rate_hz: 10, budget_ms: 20}\n"
      "  - {name: gps, kind: periodic, rate_hz: 50, budget_ms: 1}\n"
      "  - {name: imu, kind: periodic, rate_hz: 400, budget_ms: 1}\n"
      "  - {name: pose, kind: periodic, rate_hz: 100, budget_ms: 1}\n"
      "gps: {link: 'udp:127.0.0.1:10110'}\nimu: {link: 'udp:127.0.0.1:10111', protocol: line}\npose: {antenna: [0, 0, 1]}\n";
  auto r = load(std::string(kMinimal) + rest + "navigation: {osm: " + osm + ", goal: [47.166, 9.51]}\n");
  ASSERT_TRUE(r.config) << r.error;
  auto check = daemon::Daemon::check_navigation(*r.config);
  EXPECT_EQ(check.error, "");
  EXPECT_NE(check.summary.find("UTM zone 32N"), std::string::npos) << check.summary;
  EXPECT_NE(check.summary.find("vertices"), std::string::npos) << check.summary;

  r = load(std::string(kMinimal) + rest + "navigation: {osm: " + osm + ", goal: [47.5, 9.9]}\n");  // 40 km away
  ASSERT_TRUE(r.config) << r.error;
  check = daemon::Daemon::check_navigation(*r.config);
  EXPECT_NE(check.error.find("from the nearest routable way"), std::string::npos) << check.error;

  // Without a navigation section there is nothing to check.
  r = load(kMinimal);
  ASSERT_TRUE(r.config) << r.error;
  EXPECT_EQ(daemon::Daemon::check_navigation(*r.config).error, "");
}

TEST(RobotConfig, MistakesNameFileLineAndKey) {
  std::string e = load_error(std::string(kMinimal) + "lidr: {model: VLP-16}\n");
  EXPECT_NE(e.find("test-"), std::string::npos) << e;
  EXPECT_NE(e.find(":8:"), std::string::npos) << e;
  EXPECT_NE(e.find("lidr"), std::string::npos) << e;

  std::string text = kMinimal;
  text.replace(text.find("VLP-16"), 6, "VLP-99");
  e = load_error(text);
  EXPECT_NE(e.find(":2:"), std::string::npos) << e;
  EXPECT_NE(e.find("unknown lidar model 'VLP-99'"), std::string::npos) << e;

  text = kMinimal;
  text.replace(text.find("127.0.0.1:2368"), 14, "localhost");
  e = load_error(text);
  EXPECT_NE(e.find("lidar.data"), std::string::npos) << e;

  text = kMinimal;
  text.replace(text.find("kind: event"), 11, "kind: periodic, rate_hz: 10");
  e = load_error(text);
  EXPECT_NE(e.find("task 'obstacles' must be event-driven"), std::string::npos) << e;

  e = load_error(std::string(kMinimal) + "  - {name: gps, kind: periodic, rate_hz: 50, budget_ms: 1}\n");
  EXPECT_NE(e.find("task 'gps' has nothing to run"), std::string::npos) << e;

  e = load_error(std::string(kMinimal) + "gps: {link: 'serial:/dev/ttyUSB0@115200'}\n");
  EXPECT_NE(e.find("'gps'"), std::string::npos) << e;  // the task table lacks it

  e = load_error(std::string(kMinimal) +
                 "can: {transport: tunnel, dbc: no-such.dbc, left: A.B, right: A.C, track: 0.5}\n");
  EXPECT_NE(e.find("can.dbc"), std::string::npos) << e;
  EXPECT_NE(e.find("no such file"), std::string::npos) << e;

  e = load_error(std::string(kMinimal) +
                 "can: {transport: tunnel, dbc: ../sim/trailnav-robot.dbc, left: SpeedLeft, right: A.C, track: 0.5}\n");
  EXPECT_NE(e.find("MESSAGE.Signal"), std::string::npos) << e;

  text = kMinimal;
  text.replace(text.find("dds: {domain: 3}"), 16, "dds: {domain: 3, cyclone_config: missing.xml}");
  e = load_error(text);
  EXPECT_NE(e.find("cannot read the Cyclone DDS configuration"), std::string::npos) << e;

  text = kMinimal;
  text.replace(text.find("dds: {domain: 3}"), 16, "dds: {domain: 3, topics: {obstacle_map: /abs}}");
  e = load_error(text);
  EXPECT_NE(e.find("not a topic name"), std::string::npos) << e;
}

// The task presets: the lidar's measured table for the parts configured,
// rows changed by name, and a warning for a written-out budget below what
// the lidar needs.
TEST(RobotConfig, TaskPresetIsTheLidarsMeasuredTableForThePartsConfigured) {
  const std::string head =
      "runtime: {realtime: off}\n"
      "lidar: {model: HDL-64E, calibration: ../../../shared/data/velodyne/calibration/ros_velodyne_64e_s2.1-sztaki.yaml, "
      "data: 127.0.0.1:2368}\n"
      "obstacles: {model: PC}\n"
      "dds: {domain: 3}\n";
  if (!fs::exists("../shared/data/velodyne/calibration/ros_velodyne_64e_s2.1-sztaki.yaml")) {
    GTEST_SKIP() << "../shared/data is not here";
  }
  auto r = load(head + "tasks: {preset: auto}\n");
  ASSERT_TRUE(r.config) << r.error;
  EXPECT_EQ(r.config->task_preset, "HDL-64E");
  ASSERT_EQ(r.config->tasks.size(), 2u);  // lidar and obstacles: nothing else is configured
  const auto rows = daemon::task_preset(velodyne::Model::hdl64e);
  for (const TaskSpec& t : r.config->tasks) {
    const auto row = std::find_if(rows.begin(), rows.end(), [&](const daemon::PresetRow& p) { return p.name == t.name; });
    ASSERT_NE(row, rows.end()) << t.name;
    EXPECT_EQ(t.budget, static_cast<Nanos>(row->budget_ms * 1e6 + 0.5)) << t.name;
    // Budget: the need with its margin, or 90 % of the period where that is less.
    const double cap = row->kind == TaskKind::periodic ? 0.9 * 1000.0 / row->rate_hz : 1e9;
    EXPECT_GE(row->budget_ms + 1e-9, std::min(row->need_ms, cap)) << t.name;
    EXPECT_LE(row->budget_ms, cap + 1e-9) << t.name;
    EXPECT_GT(row->need_ms, 0.0) << t.name << ": a preset row without a measurement";
    EXPECT_EQ(t.priority, row->priority) << t.name;
  }
  EXPECT_TRUE(r.config->warnings.empty());  // the preset's budgets cover the needs
  // Another model's table by name; a row changed.
  r = load(head + "tasks:\n  preset: VLP-16\n  change:\n    - {name: lidar, cpu: 0, budget_ms: 0.9}\n");
  ASSERT_TRUE(r.config) << r.error;
  EXPECT_EQ(r.config->task_preset, "VLP-16");
  EXPECT_EQ(r.config->tasks[0].name, "lidar");
  EXPECT_EQ(r.config->tasks[0].cpu, 0);
  EXPECT_EQ(r.config->tasks[0].budget, 900'000);
  // A budget below what an HDL-64E needs: warned, not refused; one above it is not warned about.
  const double need = std::find_if(rows.begin(), rows.end(), [](const daemon::PresetRow& p) { return p.name == "lidar"; })->need_ms;
  r = load(head + "tasks:\n  - {name: lidar, kind: periodic, rate_hz: 500, budget_ms: " + std::to_string(need * 0.5) +
           "}\n  - {name: obstacles, kind: event, budget_ms: 500}\n");
  ASSERT_TRUE(r.config) << r.error;
  ASSERT_EQ(r.config->warnings.size(), 1u);
  EXPECT_NE(r.config->warnings[0].find("task 'lidar'"), std::string::npos) << r.config->warnings[0];
  EXPECT_NE(r.config->warnings[0].find("HDL-64E"), std::string::npos) << r.config->warnings[0];
  r = load(head + "tasks:\n  - {name: lidar, kind: periodic, rate_hz: 200, budget_ms: " + std::to_string(need * 1.01) +
           "}\n  - {name: obstacles, kind: event, budget_ms: 500}\n");
  ASSERT_TRUE(r.config) << r.error;
  EXPECT_TRUE(r.config->warnings.empty());
  // Mistakes.
  EXPECT_NE(load_error(head + "tasks: {preset: VLP-99}\n").find("unknown preset 'VLP-99'"), std::string::npos);
  EXPECT_NE(load_error(head + "tasks:\n  preset: auto\n  change:\n    - {name: terrain, budget_ms: 9}\n")
                .find("no task 'terrain' to change (it has lidar, obstacles)"),
            std::string::npos);
  EXPECT_NE(load_error(head + "tasks:\n  preset: auto\n  change:\n    - {name: obstacles, rate_hz: 9}\n").find("event-driven"),
            std::string::npos);
  EXPECT_NE(load_error(head + "tasks:\n  preset: auto\n  chnage: []\n").find("unknown key"), std::string::npos);
  // Only periodic tasks share a thread.
  const std::string e = load_error(head + "tasks:\n  - {name: lidar, kind: periodic, rate_hz: 1000, budget_ms: 0.5, thread: all}\n"
                        "  - {name: obstacles, kind: event, budget_ms: 20, thread: all}\n");
  EXPECT_NE(e.find("only periodic tasks share a thread"), std::string::npos) << e;
}

// The presets put the IMU, CAN and GPS readers and the pose estimator on one
// thread; a row changed to another rate must leave it.
TEST(RobotConfig, ThePresetsSensorsShareAThreadAndAChangedRateMustLeaveIt) {
  const std::string bench = text_of("board/robots/bench.yaml");
  ASSERT_NE(bench.find("  preset: auto\n"), std::string::npos);
  auto r = load(bench);
  ASSERT_TRUE(r.config) << r.error;
  for (const TaskSpec& t : r.config->tasks) {
    const bool sensor = t.name == "imu" || t.name == "can" || t.name == "gps" || t.name == "pose";
    EXPECT_EQ(t.thread, sensor ? "sensors" : "") << t.name;
    if (sensor) {
      EXPECT_EQ(t.rate_hz, 100.0) << t.name;
    }
  }
  std::string changed = bench;
  changed.replace(changed.find("  preset: auto\n"), 15, "  preset: auto\n  change:\n    - {name: gps, rate_hz: 50}\n");
  std::string e = load_error(changed);
  EXPECT_NE(e.find("task 'gps': thread 'sensors' runs task 'imu' at 100 Hz, priority 65, cpu -1; a task sharing it "
                   "needs the same (this one: 50 Hz, priority 65, cpu -1)"),
            std::string::npos)
      << e;
  changed = bench;
  changed.replace(changed.find("  preset: auto\n"), 15,
                  "  preset: auto\n  change:\n    - {name: gps, rate_hz: 50, thread: \"\"}\n");
  r = load(changed);
  ASSERT_TRUE(r.config) << r.error;
}

// Every preset's budgets follow the stated rule from the measured needs:
// need x 1.5 rounded up to 0.1 ms, at least 1 ms (the machine's interference
// charged to a run), at most 90 % of the period.
TEST(RobotConfig, EveryPresetsBudgetIsItsNeedWithTheStatedMargin) {
  for (const auto model : {velodyne::Model::vlp16, velodyne::Model::vlp32c, velodyne::Model::hdl32e, velodyne::Model::hdl64e}) {
    const auto rows = daemon::task_preset(model);
    ASSERT_EQ(rows.size(), 14u);  // the eleven and the camera, place and station tasks
    for (const daemon::PresetRow& r : rows) {
      const double cap = r.kind == TaskKind::periodic ? 0.9 * 1000.0 / r.rate_hz : 1e9;
      const double expected = std::min(cap, std::max(1.0, std::ceil(r.need_ms * 15.0 - 1e-9) / 10.0));
      EXPECT_NEAR(r.budget_ms, expected, 1e-9) << velodyne::model_info(model).name << " " << r.name;
      EXPECT_GT(r.need_ms, 0.0) << velodyne::model_info(model).name << " " << r.name;
    }
  }
}

namespace {

// The traversability section: the shipped examples' (bench: the built-in
// model; the robot example's, commented out, as a robot would uncomment it),
// its checks (a terrain section, the pose for a demonstration, its task, the
// aligner's learnt cost only with it) and the task table's new row.
TEST(RobotConfig, TheTraversabilitySectionAndItsChecks) {
  const auto bench = daemon::load_robot_config("board/robots/bench.yaml");
  ASSERT_TRUE(bench.config) << bench.error;
  ASSERT_TRUE(bench.config->traversability.has_value());
  EXPECT_TRUE(fs::exists(bench.config->traversability->model));
  EXPECT_FALSE(bench.config->traversability->demonstration);

  std::string example = text_of("board/robots/robot-example.yaml");
  for (const char* line : {"# traversability:\n", "#   model: ", "#   method: ", "#   demonstration: "}) {
    const std::size_t at = example.find(line);
    ASSERT_NE(at, std::string::npos) << line;
    example.erase(at, 2);
  }
  const auto robot = load(example);
  ASSERT_TRUE(robot.config) << robot.error;
  ASSERT_TRUE(robot.config->traversability.has_value());
  EXPECT_TRUE(robot.config->traversability->demonstration);
  EXPECT_EQ(robot.config->traversability->profile, "large");
  EXPECT_DOUBLE_EQ(robot.config->traversability->footprint.length, 1.2);
  const auto demo_task = std::find_if(robot.config->tasks.begin(), robot.config->tasks.end(),
                                      [](const TaskSpec& t) { return t.name == "demonstration"; });
  ASSERT_NE(demo_task, robot.config->tasks.end()) << "the preset gives the demonstration its task";
  EXPECT_EQ(demo_task->priority, 0);

  const std::string bench_text = text_of("board/robots/bench.yaml");
  std::string e = load_error(replaced(replaced(bench_text, "feed_terrain: true", "feed_terrain: false"), "  local_map_m: 20",
                                      "  local_map_m: 20\n  demonstration: {profile: large}"));
  EXPECT_NE(e.find("feed_terrain: true"), std::string::npos) << e;
  e = load_error(replaced(bench_text, "trav-large.tntrav", "nothing-here.tntrav"));
  EXPECT_NE(e.find("no such file"), std::string::npos) << e;
  e = load_error(replaced(bench_text, "  method: pnb", "  method: svm"));
  EXPECT_NE(e.find("method"), std::string::npos) << e;
  EXPECT_NE(e.find("test-"), std::string::npos) << "names the file: " << e;
}

}  // namespace

namespace {

// The camera and place sections (issue 41): read with the preset's tasks on
// one thread of normal scheduling; a place without a camera, a reduced frame
// larger than the camera's and an unknown format are refused by key.
TEST(RobotConfig, TheCameraAndPlaceSectionsAndTheirChecks) {
  const auto ok = load(
      "runtime: {realtime: off}\n"
      "camera: {input: tunnel, tunnel_port: 29538, width: 320, height: 240, out_width: 64, out_height: 32, format: grey}\n"
      "place: {database: summer.tnplace, frame: map, window: 8, yaw_floor_deg: 5, transition: {f: 6, c_f: 400}}\n"
      "dds: {domain: 0}\n"
      "tasks: {preset: auto}\n");
  ASSERT_TRUE(ok.config) << ok.error;
  const auto& c = *ok.config;
  ASSERT_TRUE(c.camera && c.place);
  EXPECT_EQ(c.camera->input, drivers::camera::CameraInput::tunnel);
  EXPECT_EQ(c.camera->format, drivers::camera::PixelFormat::grey);
  EXPECT_EQ(c.camera->out_width, 64);
  EXPECT_EQ(c.place->transition.f, 6);
  EXPECT_DOUBLE_EQ(c.place->transition.c_f, 400.0);
  EXPECT_EQ(c.place->task.window, 8);
  EXPECT_NEAR(c.place->task.yaw_floor_rad, 5.0 * 3.14159265358979 / 180.0, 1e-9);
  for (const char* name : {"camera", "place"}) {
    const auto t = std::find_if(c.tasks.begin(), c.tasks.end(), [&](const TaskSpec& s) { return s.name == name; });
    ASSERT_NE(t, c.tasks.end()) << name;
    EXPECT_EQ(t->priority, 0) << name;
    EXPECT_EQ(t->thread, "place") << name;
  }
  // The robot example's, commented out, as a robot would uncomment it.
  std::string example = text_of("board/robots/robot-example.yaml");
  for (const char* line : {"# camera:\n", "#   device: ", "#   format: ", "#   width: ", "#   height: ", "#   fps: ",
                           "#   out_width: ", "#   out_height: ", "# place:\n", "#   database: /var/lib/trailnav/route",
                           "#   frame: map", "#   lag: ", "#   pose_measurement: "}) {
    const std::size_t at = example.find(line);
    ASSERT_NE(at, std::string::npos) << line;
    example.erase(at, 2);
  }
  const auto robot = load(example);
  ASSERT_TRUE(robot.config) << robot.error;
  ASSERT_TRUE(robot.config->camera && robot.config->place);
  EXPECT_EQ(robot.config->camera->format, drivers::camera::PixelFormat::yuyv);
  EXPECT_EQ(robot.config->place->database, "/var/lib/trailnav/route.tnplace");
  EXPECT_EQ(robot.config->place->pose.use, pose::PlaceUse::gps_poor);
  const auto no_camera = load("runtime: {realtime: off}\nplace: {database: x.tnplace}\ndds: {domain: 0}\ntasks: {preset: auto}\n");
  EXPECT_NE(no_camera.error.find("add a 'camera' section"), std::string::npos) << no_camera.error;
  const auto too_big = load("runtime: {realtime: off}\ncamera: {width: 64, height: 32, out_width: 128}\ndds: {domain: 0}\n"
                            "tasks: {preset: auto}\n");
  EXPECT_NE(too_big.error.find("out_width"), std::string::npos) << too_big.error;
  const auto format = load("runtime: {realtime: off}\ncamera: {format: rgb24}\ndds: {domain: 0}\ntasks: {preset: auto}\n");
  EXPECT_NE(format.error.find("format"), std::string::npos) << format.error;
  // The fixed lag, the online sequence test and the pose thread's use of
  // the answers; defaults as docs/place.md gives them.
  EXPECT_EQ(c.place->lag, 10);
  EXPECT_EQ(c.place->sequence.min_length, 10);
  EXPECT_EQ(c.place->pose.use, pose::PlaceUse::off);
  const std::string cam = "runtime: {realtime: off}\ncamera: {input: tunnel, width: 64, height: 32}\n";
  const auto tuned = load(cam +
                          "place: {database: x.tnplace, lag: 4, min_sequence: 12, row_gap: 3, pose_measurement: gps_poor, "
                          "min_probability: 0.4, gps_poor_after_s: 5}\nimu: {link: 'udp:127.0.0.1:10111', protocol: line}\n"
                          "pose: {}\ndds: {domain: 0}\ntasks: {preset: auto}\n");
  ASSERT_TRUE(tuned.config) << tuned.error;
  EXPECT_EQ(tuned.config->place->lag, 4);
  EXPECT_EQ(tuned.config->place->sequence.min_length, 12);
  EXPECT_EQ(tuned.config->place->sequence.row_gap, 3);
  EXPECT_EQ(tuned.config->place->pose.use, pose::PlaceUse::gps_poor);
  EXPECT_DOUBLE_EQ(tuned.config->place->pose.min_probability, 0.4);
  EXPECT_DOUBLE_EQ(tuned.config->place->pose.gps_poor_after_s, 5.0);
  const auto no_pose = load(cam + "place: {database: x.tnplace, pose_measurement: always}\ndds: {domain: 0}\ntasks: {preset: auto}\n");
  EXPECT_NE(no_pose.error.find("add a 'pose' section"), std::string::npos) << no_pose.error;
  const auto bad_use = load(cam + "place: {database: x.tnplace, pose_measurement: sometimes}\npose: {}\ndds: {domain: 0}\n"
                                  "tasks: {preset: auto}\n");
  EXPECT_NE(bad_use.error.find("pose_measurement"), std::string::npos) << bad_use.error;
  const auto bad_lag = load(cam + "place: {database: x.tnplace, lag: -1}\ndds: {domain: 0}\ntasks: {preset: auto}\n");
  EXPECT_NE(bad_lag.error.find("lag"), std::string::npos) << bad_lag.error;
}

}  // namespace

// The station section (docs/registration.md "In trailnavd"): the robot
// example's, commented out, as a robot would uncomment it; the task preset's
// row for it; the laser's mount and a visit's start read in their units.
TEST(RobotConfig, TheStationSectionAsTheRobotExampleGivesIt) {
  std::string example = text_of("board/robots/robot-example.yaml");
  const std::size_t section = example.find("# station:\n");
  ASSERT_NE(section, std::string::npos);
  for (const char* line : {"# station:\n", "#   file: ", "#   input: ", "#   topic: ", "#   mount: ", "#   start: ",
                           "#   local_scans: "}) {
    const std::size_t at = example.find(line, section);
    ASSERT_NE(at, std::string::npos) << line;
    example.erase(at, 2);
  }
  const auto robot = load(example);
  ASSERT_TRUE(robot.config) << robot.error;
  ASSERT_TRUE(robot.config->station.has_value());
  const daemon::StationSection& s = *robot.config->station;
  EXPECT_EQ(s.file, "/var/lib/trailnav/dock.tnstation");
  EXPECT_EQ(s.input, daemon::StationSection::Input::laserscan);
  EXPECT_EQ(s.laser.topic, "scan");
  EXPECT_DOUBLE_EQ(s.laser.mount_x, 0.25);
  EXPECT_NEAR(s.task.start.translation().x(), 1.5, 1e-12);
  EXPECT_NEAR(std::atan2(s.task.start.linear()(1, 0), s.task.start.linear()(0, 0)), 3.14159265358979, 1e-9);
  EXPECT_EQ(s.config.local_scans, 10);
  const auto task = std::find_if(robot.config->tasks.begin(), robot.config->tasks.end(),
                                 [](const TaskSpec& t) { return t.name == "station"; });
  ASSERT_NE(task, robot.config->tasks.end());
  EXPECT_EQ(task->priority, 0);  // normal scheduling: its registrations take what the real-time threads leave
  EXPECT_DOUBLE_EQ(task->rate_hz, 10.0);
  // Without the section the table has no such row, and a row without the section is refused.
  const auto bench = daemon::load_robot_config("board/robots/bench.yaml");
  ASSERT_TRUE(bench.config) << bench.error;
  EXPECT_FALSE(bench.config->station.has_value());
  const std::string e = load_error(std::string(kMinimal) + "  - {name: station, kind: periodic, rate_hz: 10, budget_ms: 50}\n");
  EXPECT_NE(e.find("task 'station' has nothing to run"), std::string::npos) << e;
}

// The lidar's revolution readers: one per thread that reads the revolutions
// itself, in a fixed order, counted in the driver's options by the same rule
// the daemon hands them out by.
TEST(RobotConfig, EachRevolutionReaderHasItsPlace) {
  const std::string task = "  - {name: mapping, kind: periodic, rate_hz: 2, budget_ms: 450}\n";
  const auto r = load(std::string(kMinimal) + task + kPoseTasks + kPoseSections + "mapping: {loops: {}}\n");
  ASSERT_TRUE(r.config) << r.error;
  using R = daemon::RobotConfig::Reader;
  const daemon::RobotConfig& c = *r.config;
  EXPECT_EQ(c.revolution_reader(R::obstacles), 0u);
  EXPECT_EQ(c.revolution_reader(R::mapping), 1u);  // no terrain thread, no station band before it
  EXPECT_EQ(c.revolution_reader(R::count), 2u);
  EXPECT_EQ(c.lidar->driver.revolution_readers, 2);
  const auto plain = load(kMinimal);
  ASSERT_TRUE(plain.config) << plain.error;
  EXPECT_EQ(plain.config->revolution_reader(R::count), 1u);
  EXPECT_EQ(plain.config->lidar->driver.revolution_readers, 1);
}
