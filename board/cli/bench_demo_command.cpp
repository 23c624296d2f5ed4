// `trailnav demo`: the whole bench in one command. It makes a simulated
// recording, starts trailnavd on the bench robot config (loopback only),
// replays the recording into it in real time — lidar and e-stop over UDP,
// GPS and IMU through pseudo-terminals, wheel speeds through the CAN tunnel —
// and listens on DDS like a planner: obstacle maps (saved as PNG), terrain
// maps, poses, health, the corrected subgoals of the navigation task
// (planned on the recording's world.osm to where the drive ends), each
// checked against the simulated trail, and the online map's optimised
// keyframes (checked against the simulated trajectory). It ends with what arrived, the
// latency, and trailnavd's own report.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <span>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bench_config.hpp"
#include "builtin_models.hpp"
#include "commands.hpp"
#include "dds.hpp"
#include "diagnostic_msgs.h"
#include "geometry_msgs.h"
#include "nav_msgs.h"
#include "map_png.hpp"
#include "replayer.hpp"
#include "sim_truth.hpp"
#include "simulator.hpp"
#include "subscriber.hpp"
#include "terminal.hpp"
#include "trailnav/drivers/velodyne/model.hpp"
#include "trailnav/perception/random_forest.hpp"
#include "trailnav/runtime/histogram.hpp"
#include "trailnav/runtime/spawn.hpp"

namespace trailnav::cli {
namespace {

namespace fs = std::filesystem;

struct BenchDemoOptions {
  std::string scenario = "urban";
  std::string lidar = "VLP-16";
  double seconds = 30.0;
  std::string out = "build/demo";
  std::string png;
  int png_every = 20;
  unsigned domain = 0;
  // Soak: the recording replayed again and again for this long, with the
  // daemon's figures sampled every `sample_every` seconds (0: one replay).
  double soak_minutes = 0.0;
  double sample_every = 10.0;
};

// What the kernel says of a process: resident memory, open descriptors,
// threads, CPU time.
struct ProcessFigures {
  long rss_kb = 0;
  long fds = 0;
  long threads = 0;
  double cpu_s = 0.0;
};

ProcessFigures process_figures(pid_t pid) {
  ProcessFigures f;
  const std::string dir = "/proc/" + std::to_string(pid);
  std::ifstream status(dir + "/status");
  for (std::string line; std::getline(status, line);) {
    if (line.rfind("VmRSS:", 0) == 0) f.rss_kb = std::atol(line.c_str() + 6);
    if (line.rfind("Threads:", 0) == 0) f.threads = std::atol(line.c_str() + 8);
  }
  std::error_code ec;
  for (auto it = fs::directory_iterator(dir + "/fd", ec); !ec && it != fs::directory_iterator(); it.increment(ec)) ++f.fds;
  std::ifstream stat(dir + "/stat");
  std::string text((std::istreambuf_iterator<char>(stat)), std::istreambuf_iterator<char>());
  // Fields after the command's closing parenthesis; utime and stime are the 14th and 15th of the line.
  const std::size_t close = text.rfind(')');
  if (close != std::string::npos) {
    std::istringstream rest(text.substr(close + 2));
    std::string field;
    double ticks = 0.0;
    for (int i = 3; i <= 15 && rest >> field; ++i) {
      if (i == 14 || i == 15) ticks += std::atof(field.c_str());
    }
    f.cpu_s = ticks / static_cast<double>(sysconf(_SC_CLK_TCK));
  }
  return f;
}

void replace_all(std::string& text, const std::string& from, const std::string& to) {
  for (std::size_t at = text.find(from); at != std::string::npos; at = text.find(from, at + to.size())) {
    text.replace(at, from.size(), to);
  }
}

std::string sibling_binary(const char* name) {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  return ec ? std::string(name) : (self.parent_path() / name).string();
}

// trailnavd's own report after SIGTERM: its warnings and errors, and its
// closing figures (each task's runs, overruns, execution and CPU time).
void print_daemon_report(const std::string& report) {
  std::printf("5. trailnavd after SIGTERM:\n");
  std::istringstream lines(report);
  for (std::string line; std::getline(lines, line);) {
    if (line.find("info") == std::string::npos || line.find("stopped") != std::string::npos) std::printf("   %s\n", line.c_str());
  }
}

// The soak's verdict, from its samples: RSS and descriptors constant after the
// first minute, no real-time allocation, no overrun, map latency p99 at most
// 5 ms in every window.
template <class Row>
int soak_summary(const std::vector<Row>& rows, const DurationSummary& all, const std::string& report, const fs::path& csv) {
  if (rows.empty()) {
    std::fprintf(stderr, "trailnav demo: no soak sample was taken\n");
    return 1;
  }
  long rss_min = std::numeric_limits<long>::max(), rss_max = 0, fds_min = rss_min, fds_max = 0, threads_min = rss_min,
       threads_max = 0;
  double worst_p99 = 0.0;
  for (const Row& r : rows) {
    worst_p99 = std::max(worst_p99, nanos_to_seconds(r.latency.p99) * 1e3);
    if (r.t < 60.0) continue;  // the first minute: discovery, the maps' first fill
    rss_min = std::min(rss_min, r.p.rss_kb);
    rss_max = std::max(rss_max, r.p.rss_kb);
    fds_min = std::min(fds_min, r.p.fds);
    fds_max = std::max(fds_max, r.p.fds);
    threads_min = std::min(threads_min, r.p.threads);
    threads_max = std::max(threads_max, r.p.threads);
  }
  const Row& last = rows.back();
  const bool after_minute = rss_max > 0;
  std::printf("4. soak: %.0f s, %zu samples in %s\n", last.t, rows.size(), csv.c_str());
  if (after_minute) {
    std::printf("   after the first minute: RSS %ld..%ld kB (%+ld kB), fds %ld..%ld, threads %ld..%ld\n", rss_min, rss_max,
                rss_max - rss_min, fds_min, fds_max, threads_min, threads_max);
  }
  std::printf("   CPU %.1f s in %.0f s (%.1f %% of one core); overruns %llu; real-time allocations %llu\n", last.p.cpu_s, last.t,
              100.0 * last.p.cpu_s / last.t, static_cast<unsigned long long>(last.overruns),
              static_cast<unsigned long long>(last.rt_allocations));
  std::printf("   map latency over the whole soak p50 %.2f ms, p99 %.2f ms, max %.2f ms; worst window p99 %.2f ms\n",
              nanos_to_seconds(all.p50) * 1e3, nanos_to_seconds(all.p99) * 1e3, nanos_to_seconds(all.max) * 1e3, worst_p99);
  // RSS may move by a page or two of stack and allocator slack; more than
  // 1 MB after the first minute is growth.
  const bool ok = after_minute && rss_max - rss_min <= 1024 && fds_max == fds_min && threads_max == threads_min &&
                  last.overruns == 0 && last.rt_allocations == 0 && nanos_to_seconds(all.p99) * 1e3 <= 5.0;
  std::printf("   %s\n", ok ? "soak goals met: RSS and fds constant after the first minute, 0 real-time allocations, "
                               "0 overruns, map latency p99 <= 5 ms"
                             : "SOAK GOALS NOT MET (RSS or fds not constant after the first minute, real-time "
                               "allocations, overruns, or map latency p99 above 5 ms)");
  print_daemon_report(report);
  return ok ? 0 : 1;
}

int run_bench_demo(const BenchDemoOptions& o) {
  const fs::path out = fs::absolute(o.out);
  std::error_code ec;
  fs::create_directories(out / "maps", ec);
  if (ec) {
    std::fprintf(stderr, "trailnav demo: cannot create %s: %s\n", out.c_str(), ec.message().c_str());
    return 1;
  }
  // 1. The recording.
  const auto lidar = velodyne::parse_model(o.lidar);
  // The terrain model trained on this lidar's simulated remissions.
  const std::span<const std::uint8_t> terrain_model = lidar ? builtin_terrain_model(*lidar) : std::span<const std::uint8_t>();
  if (terrain_model.empty()) {
    std::fprintf(stderr, "trailnav demo: --lidar %s: no terrain model for it in board/models/ (VLP-16, VLP-32C, HDL-32E, "
                         "HDL-64E; trailnav terrain-train makes one)\n", o.lidar.c_str());
    return 2;
  }
  std::string calibration;  // the one the simulator used, for trailnavd too
  sim::SimOptions so;
  so.scenario = o.scenario;
  so.lidar = o.lidar;
  so.duration = o.seconds;
  so.out = (out / "recording").string();
  {
    ProgressBar bar("simulate " + o.scenario, o.seconds, "s");
    so.progress = [&](double done, double) { bar.update(done); };
    const sim::SimReport sr = sim::run_simulation(so);
    bar.finish();
    if (!sr.error.empty()) {
      std::fprintf(stderr, "trailnav demo: %s\n", sr.error.c_str());
      return 1;
    }
    std::printf("1. recording: scenario %s, %.0f s, %s -> %s\n", o.scenario.c_str(), sr.sim_seconds, sr.lidar_model.c_str(),
                so.out.c_str());
    calibration = sr.calibration;
  }
  // 2. trailnavd on the bench config, its pseudo-terminals and DBC in OUT.
  std::string config = kBenchRobotConfig;
  replace_all(config, "/tmp/trailnav-bench/", (out / "").string());
  replace_all(config, "../sim/trailnav-robot.dbc", "trailnav-robot.dbc");
  replace_all(config, "../models/terrain-sim.tnrf", "terrain-sim.tnrf");
  {
    std::ofstream file(out / "terrain-sim.tnrf", std::ios::binary);
    file.write(reinterpret_cast<const char*>(terrain_model.data()), static_cast<std::streamsize>(terrain_model.size()));
  }
  // The cells the terrain model learnt from, as its file says (trailnavd
  // refuses others): the HDL-64E's are not the bench config's VLP-16 cells.
  if (const auto parsed = perception::RandomForest::parse(terrain_model, "built-in terrain model");
      parsed.forest && parsed.forest->feature_settings().said()) {
    const perception::FeatureSettings& s = parsed.forest->feature_settings();
    const std::string line = "  min_points: 15          # minPoints per cell";
    if (config.find(line) == std::string::npos || config.find("    resolution: 0.2       # m") == std::string::npos ||
        s.resolution != 0.2f) {
      std::fprintf(stderr, "trailnav demo: the built-in bench config's terrain section (board/robots/bench.yaml) no longer "
                           "has the lines this command sets the model's cells in, or the model's cells are not 0.2 m\n");
      return 1;
    }
    char keys[160];
    std::snprintf(keys, sizeof keys, "  min_points: %u\n  min_range: %.9g\n  max_range: %.9g", s.min_points,
                  static_cast<double>(s.min_range), static_cast<double>(s.max_range));
    replace_all(config, line, keys);
  }
  // The traversability layer's model was learnt from a VLP-16's demonstration
  // (its remission words are that lidar's): with another lidar the demo runs
  // without the layer.
  const bool traversability = *lidar == velodyne::Model::vlp16;
  if (traversability) {
    replace_all(config, "../models/trav-large.tntrav", "trav-large.tntrav");
    const std::span<const std::uint8_t> trav = builtin_traversability_model();
    std::ofstream file(out / "trav-large.tntrav", std::ios::binary);
    file.write(reinterpret_cast<const char*>(trav.data()), static_cast<std::streamsize>(trav.size()));
  } else {
    const std::size_t from = config.find("\ntraversability:");
    const std::size_t to = from == std::string::npos ? from : config.find("\n\n", from + 1);
    if (from != std::string::npos && to != std::string::npos) config.erase(from + 1, to - from);
  }
  if (*lidar != velodyne::Model::vlp16) {
    // The lidar the recording has, and the calibration it was simulated with.
    replace_all(config, "  model: VLP-16", "  model: " + std::string(velodyne::model_info(*lidar).name));
    if (fs::is_regular_file(calibration)) {
      replace_all(config, "  calibration: builtin", "  calibration: " + fs::absolute(calibration).string());
    }
  }
  replace_all(config, "  domain: 0", "  domain: " + std::to_string(o.domain));
  replace_all(config, "  log_sink: auto ", "  log_sink: stderr");
  // Navigation: plan on the recording's OpenStreetMap to where the drive ends.
  auto truth = eval::load_sim_truth(so.out + "/truth");
  sim::Polyline trail;
  std::string trail_error = truth.truth ? eval::load_true_route(so.out + "/truth", trail) : truth.error;
  if (!trail_error.empty() || truth.truth->trajectory.empty() || std::isnan(truth.truth->trajectory.back().lat)) {
    std::fprintf(stderr, "trailnav demo: the recording's truth: %s\n", trail_error.empty() ? "no trajectory" : trail_error.c_str());
    return 1;
  }
  const eval::TruthPose& start = truth.truth->trajectory.front();
  const eval::TruthPose& end = truth.truth->trajectory.back();
  {
    char section[600];
    std::snprintf(section, sizeof section,
                  "\nnavigation:\n"
                  "  osm: %s\n"
                  "  goal: [%.8f, %.8f]\n",
                  (fs::path(so.out) / "world.osm").c_str(), end.lat, end.lon);
    // The section goes before the task table (its preset has the navigation task's row).
    const auto tasks = config.find("\ntasks:\n");
    if (tasks == std::string::npos) {
      std::fprintf(stderr, "trailnav demo: the built-in bench config (board/robots/bench.yaml) has no task table\n");
      return 1;
    }
    config.insert(tasks, section);
  }
  std::ofstream(out / "trailnav-robot.dbc") << sim::robot_dbc_text();
  std::ofstream(out / "bench.yaml") << config;
  const std::string daemon_log = (out / "trailnavd.log").string();
  std::string spawn_error;
  const pid_t pid = spawn_process({sibling_binary("trailnavd"), "--config", (out / "bench.yaml").string()},
                                  {.stdout_path = "/dev/null", .stderr_path = daemon_log}, spawn_error);
  if (pid < 0) {
    std::fprintf(stderr, "trailnav demo: %s\n", spawn_error.c_str());
    return 1;
  }
  std::printf("2. trailnavd started (pid %d): %s, log %s\n", static_cast<int>(pid), (out / "bench.yaml").c_str(),
              daemon_log.c_str());
  auto stop_daemon = [&]() -> std::string {
    ::kill(pid, SIGTERM);
    int status = 0;
    ::waitpid(pid, &status, 0);
    std::ifstream in(daemon_log);
    std::stringstream text;
    text << in.rdbuf();
    return text.str();
  };

  // 3. The planner's side: DDS on loopback.
  auto domain = dds::Domain::create(o.domain, dds::loopback_config());
  if (!domain.domain) {
    std::fprintf(stderr, "trailnav demo: %s\n%s", domain.error.c_str(), stop_daemon().c_str());
    return 1;
  }
  auto maps = dds::Subscriber::create(*domain.domain, "trailnav/obstacle_map", &nav_msgs_msg_dds__OccupancyGrid__desc, 0);
  auto poses = dds::Subscriber::create(*domain.domain, "trailnav/pose", &geometry_msgs_msg_dds__PoseStamped__desc, 0);
  auto health = dds::Subscriber::create(*domain.domain, "diagnostics", &diagnostic_msgs_msg_dds__DiagnosticArray__desc, 0);
  auto terrain = dds::Subscriber::create(*domain.domain, "trailnav/terrain_map", &trailnav_msgs_msg_dds__TerrainClassMap__desc, 0);
  auto subgoal = dds::Subscriber::create(*domain.domain, "trailnav/subgoal", &geometry_msgs_msg_dds__PoseStamped__desc, 0, true);
  auto subgoal_path = dds::Subscriber::create(*domain.domain, "trailnav/subgoal_path", &nav_msgs_msg_dds__Path__desc, 0);
  auto keyframe_path = dds::Subscriber::create(*domain.domain, "trailnav/keyframe_path", &nav_msgs_msg_dds__Path__desc, 0, true);
  auto trav = dds::Subscriber::create(*domain.domain, "trailnav/traversability", &nav_msgs_msg_dds__OccupancyGrid__desc, 0);
  if (!maps.subscriber || !poses.subscriber || !health.subscriber || !terrain.subscriber || !subgoal.subscriber ||
      !subgoal_path.subscriber || !keyframe_path.subscriber || !trav.subscriber) {
    std::fprintf(stderr, "trailnav demo: cannot subscribe\n%s", stop_daemon().c_str());
    return 1;
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));  // trailnavd opens its links; discovery settles
  if (::waitpid(pid, nullptr, WNOHANG) == pid) {
    std::ifstream in(daemon_log);
    std::stringstream text;
    text << in.rdbuf();
    std::fprintf(stderr, "trailnav demo: trailnavd stopped at start-up:\n%s", text.str().c_str());
    return 1;
  }

  // 4. Replay in real time while listening.
  replay::ReplayOptions ro;
  ro.serial_links["gps"] = (out / "gps").string();
  ro.serial_links["imu"] = (out / "imu").string();
  const bool soak = o.soak_minutes > 0.0;
  std::atomic<bool> stop_replay{false};
  if (soak) {
    ro.loops = 0;
    ro.stop = &stop_replay;
  }
  std::atomic<std::int64_t> replay_start_ns{0};  // wall clock when the replay began (read by the replayer)
  ro.started = [&replay_start_ns] { replay_start_ns = wall_clock_ns(); };
  auto replayer = replay::Replayer::create(so.out, ro);
  if (!replayer.replayer) {
    std::fprintf(stderr, "trailnav demo: %s\n%s", replayer.error.c_str(), stop_daemon().c_str());
    return 1;
  }
  std::printf("3. replaying into trailnavd in real time; listening on DDS (loopback) like a planner\n");
  std::atomic<bool> playing{true};
  std::int64_t replay_late_ns = 0;                // its worst send, late by (read after the join)
  // trailnavd's CPU time over the replay alone (not its start-up: the
  // terrain model, the road network).
  const double cpu_before = process_figures(pid).cpu_s;
  const auto wall_before = std::chrono::steady_clock::now();
  std::thread player([&] {
    replay_late_ns = replayer.replayer->run().send_error.max;
    playing = false;
  });
  const double total_s = soak ? o.soak_minutes * 60.0 : o.seconds;
  ProgressBar bar(soak ? "soak" : "replay", total_s, "s");
  std::uint64_t n_maps = 0, n_stale = 0, n_poses = 0, n_health = 0, pngs = 0, n_terrain = 0;
  std::string terrain_summary;
  std::uint64_t n_trav = 0;
  std::string trav_summary;
  std::string driving_health;
  DurationHistogram latency;  // ns, within 3 %
  DurationHistogram window_latency;  // the soak's sample window
  std::uint64_t window_maps = 0;
  std::map<std::string, std::map<std::string, std::string>> health_values;  // the newest, by status name
  std::vector<std::int8_t> last_map;
  nav_msgs_msg_dds__OccupancyGrid_ last_header{};
  std::string last_pose, last_health;
  // Subgoals arrive in the odometry frame: they are checked against the
  // simulated trail through the robot's odometry and true poses of their
  // instant, once everything has arrived.
  struct Stamped {
    std::int64_t t;
    double x, y;
  };
  std::vector<Stamped> subgoals_received;
  eval::TrailCheck trail_check(*truth.truth, trail, 0);
  std::uint64_t n_paths = 0;
  std::size_t last_path_poses = 0;
  // The online map's newest keyframe path (its frame and, per keyframe, stamp and UTM position).
  std::uint64_t n_keyframe_paths = 0;
  std::string keyframe_frame;
  std::vector<eval::StampedPosition> keyframes;
  auto stamp_ns = [](const auto& header) {
    return static_cast<std::int64_t>(header.stamp.sec) * 1'000'000'000 + static_cast<std::int64_t>(header.stamp.nanosec);
  };
  const auto t0 = std::chrono::steady_clock::now();
  auto listen = [&](double wait) {
    maps.subscriber->take(wait, [&](const dds::ReceivedSample& r) {
      const auto& g = *static_cast<const nav_msgs_msg_dds__OccupancyGrid_*>(r.sample);
      if (n_maps > 0 && g.header.stamp.sec == last_header.header.stamp.sec &&
          g.header.stamp.nanosec == last_header.header.stamp.nanosec) {
        ++n_stale;  // the last map again, free cells unknown: the lidar has gone quiet
        return;
      }
      ++n_maps;
      latency.record(r.receive_ns - r.source_ns);
      window_latency.record(r.receive_ns - r.source_ns);
      ++window_maps;
      last_map.assign(g.data._buffer, g.data._buffer + g.data._length);
      last_header = g;
      last_header.data = {};
      if (o.png_every > 0 && n_maps % static_cast<std::uint64_t>(o.png_every) == 0) {
        char name[48];
        std::snprintf(name, sizeof name, "obstacle_map-%04llu.png", static_cast<unsigned long long>(n_maps));
        if (write_occupancy_png((out / "maps" / name).string(), g, "trailnav/obstacle_map")) ++pngs;
      }
    });
    terrain.subscriber->take(0.0, [&](const dds::ReceivedSample& r) {
      const auto& t = *static_cast<const trailnav_msgs_msg_dds__TerrainClassMap_*>(r.sample);
      ++n_terrain;
      std::array<std::uint64_t, 6> count{};
      for (std::uint32_t i = 0; i < t.class_id._length; ++i) ++count[std::min<std::size_t>(t.class_id._buffer[i], 5)];
      char text[200];
      std::snprintf(text, sizeof text, "street %llu, dirt %llu, grass %llu, vegetation %llu, other %llu cells",
                    static_cast<unsigned long long>(count[0]), static_cast<unsigned long long>(count[1]),
                    static_cast<unsigned long long>(count[2]), static_cast<unsigned long long>(count[3]),
                    static_cast<unsigned long long>(count[4]));
      terrain_summary = text;
      if (write_terrain_png((out / "maps" / "terrain_map.png").string(), t, "trailnav/terrain_map")) ++pngs;
    });
    trav.subscriber->take(0.0, [&](const dds::ReceivedSample& r) {
      const auto& g = *static_cast<const nav_msgs_msg_dds__OccupancyGrid_*>(r.sample);
      ++n_trav;
      std::uint64_t known = 0, traversable = 0;
      for (std::uint32_t i = 0; i < g.data._length; ++i) {
        if (g.data._buffer[i] < 0) continue;
        ++known;
        traversable += g.data._buffer[i] < 50 ? 1u : 0u;
      }
      char text[160];
      std::snprintf(text, sizeof text, "%llu cells with evidence, %llu of them traversable",
                    static_cast<unsigned long long>(known), static_cast<unsigned long long>(traversable));
      trav_summary = text;
      if (write_cost_png((out / "maps" / "traversability.png").string(), g,
                         "trailnav/traversability (learnt from demo-large)", "100 (1 - P(trav)) of the learnt layer",
                         "0: traversable", "100: not traversable")) {
        ++pngs;
      }
    });
    subgoal.subscriber->take(0.0, [&](const dds::ReceivedSample& r) {
      const auto& p = *static_cast<const geometry_msgs_msg_dds__PoseStamped_*>(r.sample);
      subgoals_received.push_back({stamp_ns(p.header), p.pose.position.x, p.pose.position.y});
    });
    subgoal_path.subscriber->take(0.0, [&](const dds::ReceivedSample& r) {
      ++n_paths;
      last_path_poses = static_cast<const nav_msgs_msg_dds__Path_*>(r.sample)->poses._length;
    });
    keyframe_path.subscriber->take(0.0, [&](const dds::ReceivedSample& r) {
      const auto& path = *static_cast<const nav_msgs_msg_dds__Path_*>(r.sample);
      ++n_keyframe_paths;
      keyframe_frame = path.header.frame_id;
      keyframes.clear();
      for (std::uint32_t i = 0; i < path.poses._length; ++i) {
        const auto& k = path.poses._buffer[i];
        keyframes.push_back({stamp_ns(k.header), k.pose.position.x, k.pose.position.y});
      }
    });
    poses.subscriber->take(0.0, [&](const dds::ReceivedSample& r) {
      const auto& p = *static_cast<const geometry_msgs_msg_dds__PoseStamped_*>(r.sample);
      ++n_poses;
      trail_check.add_odometry_pose(stamp_ns(p.header), p.pose.position.x, p.pose.position.y,
                                    2.0 * std::atan2(p.pose.orientation.z, p.pose.orientation.w));
      char text[128];
      std::snprintf(text, sizeof text, "x %.2f m, y %.2f m in %s", p.pose.position.x, p.pose.position.y, p.header.frame_id);
      last_pose = text;
    });
    health.subscriber->take(0.0, [&](const dds::ReceivedSample& r) {
      const auto& a = *static_cast<const diagnostic_msgs_msg_dds__DiagnosticArray_*>(r.sample);
      ++n_health;
      static const char* const kLevels[] = {"OK", "WARN", "ERROR", "STALE"};
      last_health.clear();
      for (std::uint32_t i = 0; i < a.status._length; ++i) {
        const auto& s = a.status._buffer[i];
        auto& values = health_values[s.name];
        for (std::uint32_t k = 0; k < s.values._length; ++k) values[s.values._buffer[k].key] = s.values._buffer[k].value;
        if (std::string_view(s.name).find("task ") != std::string_view::npos) continue;
        last_health += std::string("     ") + (s.level < 4 ? kLevels[s.level] : "?") + "  " + s.name + ": " + s.message + "\n";
      }
    });
  };
  // The soak's samples: every `sample_every` s the daemon's memory, descriptors,
  // threads and CPU, its overruns and real-time allocations (health), and the
  // maps' latency over the window.
  std::ofstream soak_csv;
  struct SoakRow {
    double t;
    ProcessFigures p;
    std::uint64_t overruns, rt_allocations, maps;
    DurationSummary latency;
  };
  std::vector<SoakRow> soak_rows;
  if (soak) {
    soak_csv.open(out / "soak.csv");
    soak_csv << "elapsed_s,rss_kb,fds,threads,cpu_s,overruns,rt_allocations,maps,map_latency_p50_ms,map_latency_p99_ms,"
                "map_latency_max_ms\n";
  }
  auto health_sum = [&](const std::string& prefix, const std::string& key) {
    std::uint64_t sum = 0;
    for (const auto& [name, values] : health_values) {
      if (name.rfind(prefix, 0) != 0) continue;
      if (auto it = values.find(key); it != values.end()) sum += std::strtoull(it->second.c_str(), nullptr, 10);
    }
    return sum;
  };
  double next_sample = o.sample_every;
  while (playing) {
    listen(0.05);
    driving_health = last_health;
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    bar.update(std::min(elapsed, total_s));
    if (soak && elapsed >= next_sample) {
      next_sample += o.sample_every;
      SoakRow row{elapsed, process_figures(pid), health_sum("trailnavd: task ", "overruns"),
                  health_sum("trailnavd: memory", "rt_allocations"), window_maps, window_latency.summary()};
      char line[256];
      std::snprintf(line, sizeof line, "%.1f,%ld,%ld,%ld,%.2f,%llu,%llu,%llu,%.3f,%.3f,%.3f\n", row.t, row.p.rss_kb, row.p.fds,
                    row.p.threads, row.p.cpu_s, static_cast<unsigned long long>(row.overruns),
                    static_cast<unsigned long long>(row.rt_allocations), static_cast<unsigned long long>(row.maps),
                    nanos_to_seconds(row.latency.p50) * 1e3, nanos_to_seconds(row.latency.p99) * 1e3,
                    nanos_to_seconds(row.latency.max) * 1e3);
      soak_csv << line;
      soak_csv.flush();
      soak_rows.push_back(row);
      window_latency.reset();
      window_maps = 0;
      if (::waitpid(pid, nullptr, WNOHANG) == pid) {
        std::fprintf(stderr, "\ntrailnav demo: trailnavd stopped during the soak\n");
        stop_replay = true;
      }
    }
    if (soak && elapsed >= total_s) stop_replay = true;
  }
  bar.finish();
  player.join();
  const double replay_cpu_s = process_figures(pid).cpu_s - cpu_before;
  const double replay_wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_before).count();
  for (int i = 0; i < 5; ++i) listen(0.1);
  const std::string report = stop_daemon();

  const DurationSummary lat = latency.summary();
  if (soak) return soak_summary(soak_rows, lat, report, out / "soak.csv");
  std::printf("4. received: %llu obstacle maps (latency from the revolution's last packet: p50 %.2f ms, p99 %.2f ms), "
              "%llu poses (last: %s), %llu health messages\n",
              static_cast<unsigned long long>(n_maps), nanos_to_seconds(lat.p50) * 1e3, nanos_to_seconds(lat.p99) * 1e3, static_cast<unsigned long long>(n_poses),
              last_pose.c_str(), static_cast<unsigned long long>(n_health));
  std::printf("   %llu terrain-class maps (last: %s; picture %s)\n", static_cast<unsigned long long>(n_terrain),
              terrain_summary.c_str(), (out / "maps" / "terrain_map.png").c_str());
  if (traversability) {
    std::printf("   %llu traversability layers (last: %s; picture %s)\n", static_cast<unsigned long long>(n_trav),
                trav_summary.c_str(), (out / "maps" / "traversability.png").c_str());
  }
  std::vector<double> subgoal_errors;
  {
    // Distance of each active subgoal from the trail's centre: on it within
    // half the width of the scenario's narrowest street or track.
    double half_width = std::numeric_limits<double>::max();
    for (const auto& t : truth.truth->scenario.trails) half_width = std::min(half_width, 0.5 * t.width);
    trail_check.set_offset(replay_start_ns - start.utc_ns);
    trail_check.set_past_end_tolerance(replay_late_ns + eval::kDaemonStallTolerance_ns);
    std::ofstream csv(out / "subgoals.csv");
    csv << "stamp_s,odom_x,odom_y,trail_distance\n";
    for (const Stamped& g : subgoals_received) {
      const double d = trail_check.distance(g.t, g.x, g.y);
      char row[120];
      std::snprintf(row, sizeof row, "%.3f,%.3f,%.3f,%.3f\n", static_cast<double>(g.t) * 1e-9, g.x, g.y, d);
      csv << row;
      if (!std::isnan(d)) subgoal_errors.push_back(d);
    }
    const std::size_t n = subgoal_errors.size(), half = n / 2;
    double first = 0.0, second = 0.0, second_max = 0.0;
    std::size_t on_trail = 0;
    for (std::size_t i = 0; i < n; ++i) {
      (i < half ? first : second) += subgoal_errors[i];
      if (i >= half) second_max = std::max(second_max, subgoal_errors[i]);
      if (subgoal_errors[i] <= half_width) ++on_trail;
    }
    std::printf("   %zu active subgoals (corrected, odometry frame) over %.0f m of simulated trail, %zu of them on it "
                "(within %.1f m of its centre); distance from its centre: first %.2f m (OpenStreetMap, before any terrain map), first half mean %.2f m, "
                "second half mean %.2f m, max %.2f m (each in %s); %llu corrected paths (last: %zu poses)\n",
                n, end.arc - start.arc, on_trail, half_width, n ? subgoal_errors.front() : 0.0, half ? first / static_cast<double>(half) : 0.0,
                n > half ? second / static_cast<double>(n - half) : 0.0, second_max, (out / "subgoals.csv").c_str(),
                static_cast<unsigned long long>(n_paths),
                last_path_poses);
  }
  {
    // The online map's keyframes against the simulated truth at their
    // stamps, in UTM: the offset common to all of them is the simulated
    // GPS's wandering bias (board/sim/scenario.hpp), which no map tied to GPS
    // can see; what is left is the map's own error.
    const std::vector<std::array<double, 2>> errors =
        eval::utm_errors(truth.truth->trajectory, keyframe_frame, keyframes, trail_check.offset_ns());
    std::ofstream csv(out / "keyframes.csv");
    csv << "stamp_s,easting,northing,true_easting,true_northing\n";  // nan: no true pose at that time
    for (std::size_t i = 0; i < keyframes.size() && i < errors.size(); ++i) {
      const eval::StampedPosition& k = keyframes[i];
      char row[160];
      std::snprintf(row, sizeof row, "%.3f,%.3f,%.3f,%.3f,%.3f\n", static_cast<double>(k.t) * 1e-9, k.east, k.north,
                    k.east - errors[i][0], k.north - errors[i][1]);
      csv << row;
    }
    const eval::CommonOffset split = eval::split_common_offset(errors);
    std::printf("   %llu optimised keyframe paths of the online map (%s); the last one's %zu keyframes against the "
                "simulated truth: %.2f m east, %.2f m north common to all (the simulated GPS's bias), %.2f m mean and "
                "%.2f m max beyond it (%s)\n",
                static_cast<unsigned long long>(n_keyframe_paths), keyframe_frame.empty() ? "none" : keyframe_frame.c_str(),
                split.count, split.east, split.north, split.mean, split.max, (out / "keyframes.csv").c_str());
  }
  std::printf("   health while driving:\n%s", driving_health.c_str());
  std::printf("   after the recording ended: the last map resent %llu time(s) as stale (free cells unknown); health then:\n%s",
              static_cast<unsigned long long>(n_stale), last_health.c_str());
  std::printf("   %llu map PNGs in %s\n", static_cast<unsigned long long>(pngs), (out / "maps").c_str());
  if (!o.png.empty() && !last_map.empty()) {
    last_header.data._buffer = last_map.data();
    last_header.data._length = static_cast<std::uint32_t>(last_map.size());
    if (Status st = write_occupancy_png(o.png, last_header, "trailnav/obstacle_map, the last received"); st) {
      std::printf("   last obstacle map: %s\n", o.png.c_str());
    } else {
      std::fprintf(stderr, "trailnav demo: %s\n", st.message().c_str());
    }
  }
  std::printf("   trailnavd's CPU over the replay: %.2f s in %.1f s, %.1f %% of one core (%s, %s)\n", replay_cpu_s,
              replay_wall_s, replay_wall_s > 0.0 ? 100.0 * replay_cpu_s / replay_wall_s : 0.0, o.lidar.c_str(),
              o.scenario.c_str());
  print_daemon_report(report);
  return n_maps > 0 && n_poses > 0 && n_health > 0 && !subgoals_received.empty() && n_keyframe_paths > 0 ? 0 : 1;
}

}  // namespace

void add_bench_demo_command(CLI::App& app) {
  auto o = std::make_shared<BenchDemoOptions>();
  auto* cmd = app.add_subcommand(
      "demo",
      "The bench demo: simulate a recording, start trailnavd on the bench config (board/robots/bench.yaml, all on\n"
      "loopback), replay the recording into it in real time and receive its DDS topics like a planner: obstacle\n"
      "maps (saved as PNG), terrain maps, poses, health, and the corrected subgoals of the navigation task, planned on\n"
      "the recording's OpenStreetMap to where the drive ends and checked against the simulated trail. Prints what\n"
      "arrived, the latency and trailnavd's report.");
  cmd->add_option("--scenario", o->scenario, "Simulator scenario (docs/simulator.md)")->capture_default_str();
  cmd->add_option("--lidar", o->lidar,
                  "Lidar model the drive is simulated with and trailnavd configured for: VLP-16, VLP-32C, HDL-32E or\n"
                  "HDL-64E (the thesis' lidar). The calibration is the simulator's (the real file in\n"
                  "../shared/data/velodyne/calibration/), the terrain model the one trained for that lidar\n"
                  "(board/models/), the task table its preset (docs/performance.md \"Task presets\")")
      ->capture_default_str()
      ->check([](const std::string& v) {
        return velodyne::parse_model(v) ? std::string()
                                         : "unknown lidar model '" + v + "' (VLP-16, VLP-16-HiRes, VLP-32C, HDL-32E, HDL-64E)";
      });
  cmd->add_option("--seconds", o->seconds, "Seconds to drive (and replay)")->capture_default_str()->check(CLI::Range(2.0, 600.0));
  cmd->add_option("--out", o->out, "Directory for the recording, the config, trailnavd's log and the map PNGs")->capture_default_str();
  cmd->add_option("--png", o->png, "Also write the last obstacle map received to this PNG file");
  cmd->add_option("--png-every", o->png_every, "Save every Nth map received in OUT/maps (0: none)")->capture_default_str()->check(CLI::NonNegativeNumber);
  cmd->add_option("--domain", o->domain, "DDS domain id")->capture_default_str()->check(CLI::Range(0, 232));
  cmd->add_option("--soak-minutes", o->soak_minutes,
                  "Soak: replay the recording again and again for this many minutes, sampling trailnavd's RSS,\n"
                  "descriptors, threads, CPU, overruns, real-time allocations and map latency into OUT/soak.csv;\n"
                  "exits 1 unless RSS and fds stay constant after the first minute, with 0 real-time\n"
                  "allocations, 0 overruns and map latency p99 <= 5 ms (toolchain/soak.sh)")
      ->check(CLI::Range(0.0, 24.0 * 60.0));
  cmd->add_option("--sample-every", o->sample_every, "Soak: seconds between samples")->capture_default_str()->check(
      CLI::Range(1.0, 600.0));
  cmd->callback([o] {
    const int rc = run_bench_demo(*o);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });
}

}  // namespace trailnav::cli
