#include "bench_daemon.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <sstream>
#include <vector>

#include "simulator.hpp"
#include "trailnav/drivers/velodyne/model.hpp"
#include "trailnav/navigation/osm/road_graph.hpp"
#include "trailnav/navigation/osm/router.hpp"
#include "trailnav/perception/random_forest.hpp"
#include "trailnav/runtime/clock.hpp"
#include "trailnav/runtime/spawn.hpp"

namespace trailnav::test {

namespace fs = std::filesystem;

namespace {
// The terrain section's cell settings as the model's file says it learnt
// them (trailnavd refuses others), as YAML keys after a comma; "" when the
// file does not say them.
std::string terrain_cells(const std::string& model) {
  const auto loaded = perception::RandomForest::load(model);
  if (!loaded.forest || !loaded.forest->feature_settings().said()) return {};
  const perception::FeatureSettings& s = loaded.forest->feature_settings();
  std::ostringstream out;
  out.precision(9);
  out << ", map: {resolution: " << s.resolution << "}, min_points: " << s.min_points << ", min_range: " << s.min_range
      << ", max_range: " << s.max_range;
  return out.str();
}
}  // namespace

bool far_routable_goal(const std::string& recording, FarGoal& out, std::string& error) {
  auto loaded = eval::load_sim_truth(recording + "/truth");
  if (!loaded.truth || loaded.truth->trajectory.empty()) {
    error = "truth: " + loaded.error;
    return false;
  }
  auto graph = osm::load_road_graph(recording + "/world.osm");
  if (!graph.graph) {
    error = "world.osm: " + graph.error;
    return false;
  }
  const osm::RoadGraph& g = *graph.graph;
  double se = 0.0, sn = 0.0;
  g.to_utm(loaded.truth->trajectory.front().lat, loaded.truth->trajectory.front().lon, se, sn);
  const auto start = g.project(se, sn);
  if (!start) {
    error = "the drive starts off the network";
    return false;
  }
  osm::Router router(g);
  std::vector<osm::Point2> path;
  out.distance = -1.0;
  for (const osm::RoadVertex& v : g.vertices()) {
    const double d = std::hypot(v.x - se, v.y - sn);
    const auto to = g.project(v.x, v.y);
    if (d <= out.distance || !to || !router.route(*start, *to, path).found) continue;
    out.distance = d;
    out.easting = v.x;
    out.northing = v.y;
    out.on_network_e = to->x;
    out.on_network_n = to->y;
  }
  if (out.distance < 0.0) {
    error = "no vertex routable from the start";
    return false;
  }
  g.to_latlon(out.easting, out.northing, out.lat, out.lon);
  return true;
}

std::unique_ptr<BenchDaemon> BenchDaemon::start(const std::string& daemon_binary, const BenchDaemonOptions& options,
                                                std::string& error) {
  std::unique_ptr<BenchDaemon> b(new BenchDaemon());
  b->options_ = options;
  b->dir_ = fs::temp_directory_path() / ("trailnav-" + options.tag + "-" + std::to_string(::getpid()));
  fs::remove_all(b->dir_);
  fs::create_directories(b->dir_);
  sim::SimOptions so;
  so.scenario = options.scenario;
  so.seed = options.seed;
  so.duration = options.seconds;
  so.out = (b->dir_ / "rec").string();
  so.lidar = options.lidar;
  b->recording_ = so.out;
  const auto model = velodyne::parse_model(options.lidar);
  if (!model) {
    error = "unknown lidar model '" + options.lidar + "'";
    return nullptr;
  }
  std::string calibration = "builtin";
  if (*model != velodyne::Model::vlp16) {
    calibration = sim::default_calibration_file(*model);
    if (calibration.empty()) {
      error = "no calibration for the " + options.lidar + " in ../shared/data/velodyne/calibration/";
      return nullptr;
    }
    calibration = fs::absolute(calibration).string();
    so.calibration = calibration;
  }
  std::string terrain_model = "board/models/terrain-sim.tnrf";
  switch (*model) {
    case velodyne::Model::vlp32c: terrain_model = "board/models/terrain-sim-vlp32c.tnrf"; break;
    case velodyne::Model::hdl32e: terrain_model = "board/models/terrain-sim-hdl32e.tnrf"; break;
    case velodyne::Model::hdl64e: terrain_model = "board/models/terrain-sim-hdl64e.tnrf"; break;
    default: break;
  }
  if (const sim::SimReport sr = sim::run_simulation(so); !sr.error.empty()) {
    error = "simulation: " + sr.error;
    return nullptr;
  }
  if (options.navigation || options.mapping || !options.traversability.empty()) {
    auto loaded = eval::load_sim_truth(so.out + "/truth");
    if (!loaded.truth || loaded.truth->trajectory.empty()) {
      error = "truth: " + loaded.error;
      return nullptr;
    }
    b->truth_ = std::move(*loaded.truth);
  }

  // The bench config, on this test's own ports and DDS domain: a slot none of
  // the benches running at the same time holds (a lock file each). Taken
  // from the process id alone, two of ctest's parallel tests once shared a
  // domain, and each checked the other's maps against its own truth.
  int slot = -1;
  for (int k = 0; k < 100 && slot < 0; ++k) {
    const int n = (::getpid() + k) % 100;
    const std::string lock = (fs::temp_directory_path() / ("trailnav-bench-slot-" + std::to_string(n) + ".lock")).string();
    const int fd = ::open(lock.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
    if (fd < 0) continue;
    if (::flock(fd, LOCK_EX | LOCK_NB) == 0) {
      slot = n;
      b->slot_fd_ = fd;
    } else {
      ::close(fd);
    }
  }
  if (slot < 0) {
    error = "no free bench slot: 100 benches running at once?";
    return nullptr;
  }
  b->base_port_ = 21000 + slot * 10;
  b->domain_ = static_cast<std::uint32_t>(100 + slot);
  const int base = b->base_port_;
  b->config_ = b->dir_ / "robot.yaml";
  {
    std::ofstream c(b->config_);
    const char* nav = options.navigation || options.feed_pose ? "true" : "false";
    const auto serial_link = [&](const char* name, const char* baud, int k) {
      return options.serial_over_udp ? "udp:127.0.0.1:" + std::to_string(base + k)
                                     : "serial:" + (b->dir_ / name).string() + "@" + baud;
    };
    c << "runtime: {realtime: " << (options.realtime ? "best_effort, lock_memory: true" : "off, lock_memory: false")
      << ", log_level: warn, log_sink: stderr}\n"
      << "lidar: {model: " << options.lidar << ", calibration: " << calibration << ", data: 127.0.0.1:" << base
      << ", position: 127.0.0.1:" << base + 1
      << ", rpm: 600}\n"
      << "gps: {link: '" << serial_link("gps", "115200", 4) << "'}\n"
      << "imu: {link: '" << serial_link("imu", "921600", 5) << "', protocol: xsens}\n"
      << "can: {transport: tunnel, tunnel: 127.0.0.1:" << base + 2
      << ", dbc: " << fs::absolute("board/sim/trailnav-robot.dbc").string()
      << ", left: WHEEL_SPEEDS.SpeedLeft, right: WHEEL_SPEEDS.SpeedRight, track: 0.6}\n"
      << "gpio: {transport: tunnel, tunnel: 127.0.0.1:" << base + 3 << ", estop_line: ESTOP}\n"
      << "pose: {antenna: [0.0, 0.0, 1.3], feed_obstacles: " << nav << ", feed_terrain: " << nav << "}\n"
      << "obstacles: {model: PC, terrain: other, mount: {translation: [0.2, 0.0, 1.1]}, map: {size: 600, resolution: 0.1}}\n"
      << "terrain: {model: " << fs::absolute(terrain_model).string() << ", max_step_interval: 1.0" << terrain_cells(terrain_model)
      << "}\n"
      << "dds: {domain: " << b->domain_ << ", cyclone_config: loopback, pose_rate_hz: 20, health_period_s: 0.5"
      << options.dds_yaml << "}\n";
    if (options.preset_tasks) {
      c << "tasks: {preset: auto}\n";
    } else {
      c << "tasks:\n"
      << "  - {name: lidar, kind: periodic, rate_hz: 1000, budget_ms: 1.0}\n"
      << "  - {name: imu, kind: periodic, rate_hz: 400, budget_ms: 2.0}\n"
      << "  - {name: can, kind: periodic, rate_hz: 200, budget_ms: 1.0}\n"
      << "  - {name: gps, kind: periodic, rate_hz: 50, budget_ms: 1.0}\n"
      << "  - {name: gpio, kind: periodic, rate_hz: 200, budget_ms: 1.0}\n"
      << "  - {name: pose, kind: periodic, rate_hz: 100, budget_ms: 1.0}\n"
      << "  - {name: obstacles, kind: event, budget_ms: 40.0}\n"
      << "  - {name: terrain, kind: periodic, rate_hz: 20, budget_ms: 40.0}\n";
      if (options.navigation) c << "  - {name: navigation, kind: periodic, rate_hz: 10, budget_ms: 40.0}\n";
      if (options.mapping) c << "  - {name: mapping, kind: periodic, rate_hz: 2, budget_ms: 450.0}\n";
      if (options.traversability.find("demonstration") != std::string::npos) {
        c << "  - {name: demonstration, kind: periodic, rate_hz: 1, budget_ms: 100.0}\n";
      }
    }
    if (!options.traversability.empty()) c << "traversability: " << options.traversability << "\n";
    if (options.navigation) {
      char goal[120];
      std::snprintf(goal, sizeof goal, "[%.8f, %.8f]", b->truth_.trajectory.back().lat, b->truth_.trajectory.back().lon);
      c << "navigation: {osm: " << so.out << "/world.osm, goal: " << goal << "}\n";
    }
    if (options.mapping) c << "mapping: {optimize_period_s: 2.0" << options.mapping_yaml << "}\n";
    c << options.extra_yaml;
  }

  // trailnavd itself, as systemd would run it (stderr to a file).
  b->stderr_path_ = (b->dir_ / "trailnavd.err").string();
  b->pid_ = spawn_process({daemon_binary, "--config", b->config_.string(), "--duration", "600"},
                          {.stdout_path = "", .stderr_path = b->stderr_path_}, error);
  if (b->pid_ < 0) {
    b->pid_ = 0;
    return nullptr;
  }
  return b;
}

BenchDaemon::~BenchDaemon() {
  join_replay();
  stop();
  fs::remove_all(dir_);
  if (slot_fd_ >= 0) ::close(slot_fd_);
}

bool BenchDaemon::wait_until_up(const std::function<bool(double wait_s)>& arrived, double timeout_s) const {
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < give_up && ::kill(pid_, 0) == 0) {
    if (arrived(0.1)) return true;
  }
  return false;
}

void BenchDaemon::start_replay(double delay_s) {
  replay::ReplayOptions ro;
  const auto port = [&](int k) { return static_cast<std::uint16_t>(base_port_ + k); };
  ro.udp_targets["lidar"] = {0x7F000001u, port(0)};
  ro.udp_targets["lidar-position"] = {0x7F000001u, port(1)};
  ro.can_tunnel = {0x7F000001u, port(2)};
  ro.gpio_tunnel = {0x7F000001u, port(3)};
  if (options_.serial_over_udp) {
    ro.udp_targets["gps"] = {0x7F000001u, port(4)};
    ro.udp_targets["imu"] = {0x7F000001u, port(5)};
  } else {
    ro.serial_links["gps"] = (dir_ / "gps").string();
    ro.serial_links["imu"] = (dir_ / "imu").string();
  }
  for (const std::string& f : options_.faults) {
    const replay::FaultSpecResult parsed = replay::parse_fault_spec(f);
    if (!parsed.spec) {
      replay_error_ = parsed.error;
      std::fprintf(stderr, "bench daemon: %s\n", parsed.error.c_str());
      return;
    }
    ro.faults.push_back(*parsed.spec);
  }
  ro.fault_seed = options_.fault_seed;
  // The replay's start is read by the replayer itself, right before it fixes
  // its schedule (a thread preempted between here and there would otherwise
  // move every true time by as long).
  ro.started = [this] { replay_start_ns_ = wall_clock_ns(); };
  replaying_ = true;
  player_ = std::thread([this, ro, delay_s] {
    auto replayer = replay::Replayer::create(recording_, ro);
    if (!replayer.replayer) {
      std::fprintf(stderr, "bench daemon: replay: %s\n", replayer.error.c_str());
      replay_error_ = replayer.error;
      replaying_ = false;
      return;
    }
    std::this_thread::sleep_for(std::chrono::duration<double>(delay_s));
    replay_report_ = replayer.replayer->run();
    replaying_ = false;
  });
}

void BenchDaemon::join_replay() {
  if (player_.joinable()) player_.join();
}

int BenchDaemon::stop() {
  if (pid_ <= 0) return -1;
  ::kill(pid_, SIGTERM);
  int status = 0;
  ::waitpid(pid_, &status, 0);
  pid_ = 0;
  std::ifstream in(stderr_path_);
  std::stringstream s;
  s << in.rdbuf();
  stderr_text_ = s.str();
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

long BenchDaemon::rss_kb() const {
  std::ifstream in("/proc/" + std::to_string(pid_) + "/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::stol(line.substr(6));
  }
  return 0;
}

double BenchDaemon::cpu_s() const {
  std::ifstream in("/proc/" + std::to_string(pid_) + "/stat");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  // After the command's closing parenthesis: the state is field 3, utime and stime fields 14 and 15.
  const std::size_t close = text.rfind(')');
  if (close == std::string::npos) return 0.0;
  std::istringstream fields(text.substr(close + 1));
  std::string f;
  double ticks = 0.0;
  for (int i = 3; i <= 15 && fields >> f; ++i) {
    if (i >= 14) ticks += std::stod(f);
  }
  return ticks / static_cast<double>(::sysconf(_SC_CLK_TCK));
}

}  // namespace trailnav::test
