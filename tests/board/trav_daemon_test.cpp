// trailnavd's traversability layer (issue 38, docs/traversability.md "On the
// robot"), end to end over loopback DDS:
//   1. a demonstration: the `demo-large` drive (street, then the dirt road)
//      replayed into a trailnavd whose config names a model file that does not
//      exist yet; the footprint's cells train it online, the layer switches to
//      each newer model, `trailnav/traversability` carries the layer, health
//      counts the local maps, and on stop the model is on disk (saved
//      atomically: no temporary file left);
//   2. the next start, on a held-out drive (`mixed-route`), loads that file:
//      the layer classifies from its first step, and the file is not touched.
// The path the robot drove (its odometry, in the grid's frame) is ground the
// large robot may cross: with the finished model most of its cells must be
// called traversable.
#include <gtest/gtest.h>

#include <signal.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <vector>

#include "bench_daemon.hpp"
#include "dds.hpp"
#include "diagnostic_msgs.h"
#include "geometry_msgs.h"
#include "nav_msgs.h"
#include "subscriber.hpp"
#include "trailnav/perception/trav_model_file.hpp"

using namespace trailnav;
namespace fs = std::filesystem;

namespace {

struct LayerRun {
  int exit_code = -1;
  std::string stderr_text;
  std::size_t grids = 0;
  std::size_t first_grid_known = 0;       // known cells of the first grid received
  std::size_t last_known = 0;             // of the last one
  std::size_t path_cells = 0, path_traversable = 0;  // the last grid's known cells under the driven path
  std::size_t recent_cells = 0, recent_traversable = 0;  // ... under its last 12 m
  std::size_t other_cells = 0, other_traversable = 0;
  std::map<std::string, std::string> first_health, last_health;  // "trailnavd: traversability"
  int first_level = -1;
  double number(const std::string& key) const {
    const auto it = last_health.find(key);
    return it == last_health.end() ? std::nan("") : std::atof(it->second.c_str());
  }
};

LayerRun run_layer(const std::string& scenario, double seconds, const std::string& section, const std::string& tag) {
  LayerRun out;
  test::BenchDaemonOptions bo;
  bo.scenario = scenario;
  bo.seconds = seconds;
  bo.tag = tag;
  bo.feed_pose = true;
  bo.serial_over_udp = true;  // see trailnavd_e2e_test.cpp: the pose must not starve on a loaded machine
  bo.traversability = section;
  std::string error;
  auto bench = test::BenchDaemon::start(TRAILNAVD_BINARY, bo, error);
  EXPECT_TRUE(bench) << error;
  if (!bench) return out;
  auto domain = dds::Domain::create(bench->domain(), dds::loopback_config());
  EXPECT_TRUE(domain.domain) << domain.error;
  if (!domain.domain) return out;
  auto grids = dds::Subscriber::create(*domain.domain, "trailnav/traversability", &nav_msgs_msg_dds__OccupancyGrid__desc, 0);
  auto poses = dds::Subscriber::create(*domain.domain, "trailnav/pose", &geometry_msgs_msg_dds__PoseStamped__desc, 0,
                                       false, 1000);
  auto health = dds::Subscriber::create(*domain.domain, "diagnostics", &diagnostic_msgs_msg_dds__DiagnosticArray__desc, 0);
  EXPECT_TRUE(grids.subscriber && poses.subscriber && health.subscriber);
  if (!(grids.subscriber && poses.subscriber && health.subscriber)) return out;

  auto take_health = [&](double wait) {
    bool any = false;
    health.subscriber->take(wait, [&](const dds::ReceivedSample& r) {
      any = true;
      const auto& a = *static_cast<const diagnostic_msgs_msg_dds__DiagnosticArray_*>(r.sample);
      for (std::uint32_t i = 0; i < a.status._length; ++i) {
        const auto& s = a.status._buffer[i];
        if (std::strcmp(s.name, "trailnavd: traversability") != 0) continue;
        std::map<std::string, std::string> v;
        for (std::uint32_t k = 0; k < s.values._length; ++k) v[s.values._buffer[k].key] = s.values._buffer[k].value;
        if (out.first_level < 0) {
          out.first_level = s.level;
          out.first_health = v;
        }
        out.last_health = std::move(v);
      }
    });
    return any;
  };
  EXPECT_TRUE(bench->wait_until_up(take_health)) << "no health from trailnavd within 60 s of its start";
  bench->start_replay(0.5);
  std::vector<std::pair<double, double>> path;  // odometry positions
  struct Grid {
    double ox = 0, oy = 0, res = 0;
    std::uint32_t w = 0, h = 0;
    std::vector<std::int8_t> data;
  } last;
  auto take_all = [&](double wait) {
    take_health(wait);
    poses.subscriber->take(0.0, [&](const dds::ReceivedSample& r) {
      const auto& p = *static_cast<const geometry_msgs_msg_dds__PoseStamped_*>(r.sample);
      path.emplace_back(p.pose.position.x, p.pose.position.y);
    });
    grids.subscriber->take(0.0, [&](const dds::ReceivedSample& r) {
      const auto& g = *static_cast<const nav_msgs_msg_dds__OccupancyGrid_*>(r.sample);
      ++out.grids;
      last = {g.info.origin.position.x, g.info.origin.position.y, g.info.resolution, g.info.width, g.info.height,
              std::vector<std::int8_t>(g.data._buffer, g.data._buffer + g.data._length)};
      const auto known = static_cast<std::size_t>(std::count_if(last.data.begin(), last.data.end(), [](std::int8_t c) { return c >= 0; }));
      if (out.grids == 1) out.first_grid_known = known;
      out.last_known = known;
    });
  };
  while (bench->replaying()) take_all(0.05);
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(2);
  while (std::chrono::steady_clock::now() < until) take_all(0.05);
  bench->join_replay();
  out.exit_code = bench->stop();
  out.stderr_text = bench->stderr_text();

  // The last grid's known cells: under the driven path (within 0.3 m of an
  // odometry position) or elsewhere.
  // 1: on the path, 2: on its last 12 m.
  std::vector<char> on_path(last.data.size(), 0);
  std::vector<double> arc(path.size(), 0.0);
  for (std::size_t k = 1; k < path.size(); ++k) {
    arc[k] = arc[k - 1] + std::hypot(path[k].first - path[k - 1].first, path[k].second - path[k - 1].second);
  }
  for (std::size_t k = 0; k < path.size(); ++k) {
    const auto [x, y] = path[k];
    const char mark = arc[k] >= arc.back() - 12.0 ? 2 : 1;
    for (double dy = -0.3; dy <= 0.3; dy += last.res) {
      for (double dx = -0.3; dx <= 0.3; dx += last.res) {
        const auto cx = static_cast<long>(std::floor((x + dx - last.ox) / last.res));
        const auto cy = static_cast<long>(std::floor((y + dy - last.oy) / last.res));
        if (cx < 0 || cy < 0 || cx >= static_cast<long>(last.w) || cy >= static_cast<long>(last.h)) continue;
        char& m = on_path[static_cast<std::size_t>(cy) * last.w + static_cast<std::size_t>(cx)];
        m = std::max(m, mark);
      }
    }
  }
  for (std::size_t i = 0; i < last.data.size(); ++i) {
    if (last.data[i] < 0) continue;
    const bool traversable = last.data[i] < 50;
    if (on_path[i] != 0) {
      ++out.path_cells;
      out.path_traversable += traversable ? 1u : 0u;
      if (on_path[i] == 2) {
        ++out.recent_cells;
        out.recent_traversable += traversable ? 1u : 0u;
      }
    } else {
      ++out.other_cells;
      out.other_traversable += traversable ? 1u : 0u;
    }
  }
  // The terrain and demonstration tasks' rows of trailnavd's report (docs/traversability.md quotes them).
  for (std::size_t a = 0; a < out.stderr_text.size();) {
    std::size_t b = out.stderr_text.find('\n', a);
    if (b == std::string::npos) b = out.stderr_text.size();
    const std::string line = out.stderr_text.substr(a, b - a);
    if (line.find("  terrain ") == 0 || line.find("  demonstration ") == 0) std::printf("[ trav-daemon ] %s\n", line.c_str());
    a = b + 1;
  }
  std::printf("[ trav-daemon ] %s: %zu grids (first with %zu known cells, last %zu); driven path %zu of %zu cells "
              "traversable (its last 12 m %zu of %zu), elsewhere %zu of %zu\n",
              scenario.c_str(), out.grids, out.first_grid_known, out.last_known, out.path_traversable, out.path_cells,
              out.recent_traversable, out.recent_cells, out.other_traversable, out.other_cells);
  return out;
}

std::vector<char> bytes_of(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

TEST(TrailnavdTraversability, ADemonstrationTrainsOnlineSavesAndTheNextStartClassifiesWithIt) {
  const fs::path dir = fs::temp_directory_path() / ("trailnav-trav-daemon-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string model = (dir / "large.tntrav").string();

  // 1. The demonstration: 20 s at up to 1.2 m/s (about 21 m), local maps of 6 m.
  const LayerRun demo = run_layer("demo-large", 20.0,
                                  "{model: " + model + ", local_map_m: 6, demonstration: {profile: large}}", "trav-demo");
  EXPECT_EQ(demo.exit_code, 0) << demo.stderr_text;
  // The terrain thread's layer and recorder, and the training thread's learning and saving, never touched the heap.
  EXPECT_NE(demo.stderr_text.find(" 0 real-time allocations"), std::string::npos) << demo.stderr_text;
  EXPECT_EQ(demo.first_level, 1) << "a new model: health warns that every cell is unknown until a local map is learnt";
  EXPECT_GE(demo.number("trained"), 2.0);
  EXPECT_EQ(demo.number("lost"), 0.0);
  EXPECT_EQ(demo.number("save_failures"), 0.0);
  EXPECT_GE(demo.number("saves"), demo.number("trained"));
  EXPECT_GE(demo.number("model_updates"), 1.0);
  EXPECT_GE(demo.grids, 5u);
  EXPECT_GT(demo.last_known, 2000u);
  // While it drives, the layer classifies with the models of the local maps
  // finished so far — the first of 6 m of street is a weak model, and a cell
  // keeps its answer until it is observed again (the cells around and under
  // the robot, in the lidar's blind circle, are not) — so the demonstrated
  // ground is not yet called traversable everywhere, but far more often than
  // the rest of the map (walls, a van, a pole, the meadow beside the street).
  ASSERT_GT(demo.path_cells, 100u);
  const double demo_path = static_cast<double>(demo.path_traversable) / static_cast<double>(demo.path_cells);
  const double demo_other = static_cast<double>(demo.other_traversable) / static_cast<double>(demo.other_cells);
  EXPECT_GT(demo_path, 2.0 * demo_other);
  EXPECT_FALSE(fs::exists(model + ".tmp"));
  const auto loaded = perception::trav::load_trav_model(model);
  ASSERT_TRUE(loaded.model) << loaded.error;
  EXPECT_EQ(loaded.model->profile, "large");
  ASSERT_NE(loaded.model->set(perception::trav::FeatureSet::full), nullptr);
  const std::size_t models = loaded.model->set(perception::trav::FeatureSet::full)->models.size();
  EXPECT_GE(models, 1u);

  // 2. The next start, without demonstration, on a held-out drive (a street
  // across a plaza of bare ground: both the large robot's): the finished
  // model calls most of the path traversable.
  const std::vector<char> before = bytes_of(model);
  const LayerRun next = run_layer("mixed-route", 8.0, "{model: " + model + "}", "trav-next");
  EXPECT_EQ(next.exit_code, 0) << next.stderr_text;
  EXPECT_EQ(next.first_level, 0) << "the loaded model classifies from the start";
  ASSERT_EQ(next.first_health.count("models"), 1u);
  EXPECT_EQ(std::stoul(next.first_health.at("models")), models);
  EXPECT_EQ(next.last_health.count("trained"), 0u);  // no demonstration: no training statuses
  EXPECT_GE(next.grids, 3u);
  ASSERT_GT(next.path_cells, 50u);
  // (20 m of street taught it; 0.88 measured: the plaza's bare ground beside the path is not quite street.)
  EXPECT_GT(static_cast<double>(next.path_traversable) / static_cast<double>(next.path_cells), 0.8);
  EXPECT_EQ(bytes_of(model), before) << "a run without demonstration must not write the model";
  fs::remove_all(dir);
}

}  // namespace
