// `trailnav runtime-demo`: the runtime on its own. A simulated robot drives a curving
// trail; the task table's threads integrate its odometry, move a 600 x 600
// obstacle grid and a 300 x 300 terrain grid with it, mark what is around it,
// and hand snapshots to a non-real-time reader through mailboxes — the data
// flow of the daemon, with synthetic data. After arm(), the real-time threads
// are watched for heap use; the run ends with the task table's statistics.
#include <cmath>
#include <csignal>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "demo_config.hpp"
#include "png.hpp"
#include "terminal.hpp"
#include "trailnav/runtime/alloc_guard.hpp"
#include "trailnav/runtime/fixed_vector.hpp"
#include "trailnav/runtime/log.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/rolling_grid.hpp"
#include "trailnav/runtime/runtime_config.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/spsc_queue.hpp"

namespace trailnav::cli {
namespace {

struct GridSettings {
  std::int32_t size_cells = 0;
  double resolution_m = 0.0;
};

struct DemoConfig {
  RuntimeSettings runtime;
  double duration_s = 5.0;
  double speed_mps = 1.2;
  GridSettings obstacle_grid;
  GridSettings terrain_grid;
  std::vector<TaskSpec> tasks;
};

GridSettings parse_grid(const ConfigNode& node) {
  GridSettings g;
  g.size_cells = static_cast<std::int32_t>(node.integer("size_cells", 16, 4000));
  g.resolution_m = node.number("resolution_m", 0.01, 5.0);
  node.reject_unknown_keys();
  return g;
}

DemoConfig parse_demo_config(const ConfigNode& root) {
  DemoConfig c;
  c.runtime = parse_runtime_settings(root.map("runtime"));
  const ConfigNode demo = root.map("demo");
  c.duration_s = demo.number("duration_s", 0.1, 86'400.0);
  c.speed_mps = demo.number("speed_mps", 0.0, 5.0);
  c.obstacle_grid = parse_grid(demo.map("obstacle_grid"));
  c.terrain_grid = parse_grid(demo.map("terrain_grid"));
  demo.reject_unknown_keys();
  const int cpus = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  c.tasks = parse_task_table(root, "tasks", cpus);
  for (const char* name : {"motion", "odometry", "obstacle_map", "terrain_map"}) require_task(c.tasks, name, root, "tasks");
  if (require_task(c.tasks, "odometry", root, "tasks").kind != TaskKind::event) {
    root.fail("tasks", "task 'odometry' must be event-driven: it runs when motion samples arrive");
  }
  root.reject_unknown_keys();
  return c;
}

// --- data flowing between the tasks ---

struct MotionSample {
  Nanos time = 0;
  double speed = 0.0;     // m/s
  double yaw_rate = 0.0;  // rad/s
};

struct Pose2 {
  Nanos time = 0;
  double x = 0.0;
  double y = 0.0;
  double yaw = 0.0;
};

struct GridSnapshot {
  explicit GridSnapshot(std::size_t cell_count) : cells(cell_count) { cells.resize(cell_count); }
  CellIndex origin;
  std::int32_t size = 0;
  double resolution = 0.0;
  std::uint64_t cycle = 0;
  FixedVector<std::int8_t> cells;
};

using MotionQueue = SpscQueue<MotionSample, 1024>;

// 'motion': the robot's wheel and gyro readings along a gently curving trail.
class MotionTask final : public Task {
 public:
  MotionTask(MotionQueue& queue, TaskEvent& ready, double speed) : queue_(queue), ready_(ready), speed_(speed) {}
  void run(const TaskTick& tick) override {
    if (start_ < 0) start_ = tick.started;
    const double t = nanos_to_seconds(tick.started - start_);
    const MotionSample s{tick.started, speed_, 0.25 * std::sin(0.15 * t)};
    if (!queue_.try_push(s)) ++dropped;
    ready_.signal(tick.started);
  }
  std::uint64_t dropped = 0;

 private:
  MotionQueue& queue_;
  TaskEvent& ready_;
  double speed_;
  Nanos start_ = -1;
};

// 'odometry': integrates the samples into a pose and publishes it to each reader.
class OdometryTask final : public Task {
 public:
  OdometryTask(MotionQueue& queue, Mailbox<Pose2>& to_obstacles, Mailbox<Pose2>& to_terrain)
      : queue_(queue), to_obstacles_(to_obstacles), to_terrain_(to_terrain) {}
  void run(const TaskTick&) override {
    MotionSample s;
    bool any = false;
    while (queue_.try_pop(s)) {
      if (pose_.time != 0) {
        const double dt = nanos_to_seconds(s.time - pose_.time);
        pose_.yaw += s.yaw_rate * dt;
        pose_.x += s.speed * std::cos(pose_.yaw) * dt;
        pose_.y += s.speed * std::sin(pose_.yaw) * dt;
        distance += s.speed * dt;
      }
      pose_.time = s.time;
      any = true;
    }
    if (!any) return;
    to_obstacles_.write_slot() = pose_;
    to_obstacles_.publish();
    to_terrain_.write_slot() = pose_;
    to_terrain_.publish();
  }
  double distance = 0.0;

 private:
  MotionQueue& queue_;
  Mailbox<Pose2>& to_obstacles_;
  Mailbox<Pose2>& to_terrain_;
  Pose2 pose_;
};

// 'obstacle_map' / 'terrain_map': a rolling grid that follows the pose. The
// obstacle map marks a free corridor around the robot and posts every 6 m on
// both sides of the trail; the terrain map marks the corridor's surface.
class GridTask final : public Task {
 public:
  GridTask(Mailbox<Pose2>& poses, Mailbox<GridSnapshot>& out, const GridSettings& g, bool obstacles)
      : poses_(poses), out_(out), grid_(g.size_cells, g.size_cells, g.resolution_m, std::int8_t{-1}), obstacles_(obstacles) {}

  void run(const TaskTick& tick) override {
    if (const Pose2* p = poses_.try_read()) pose_ = *p;
    grid_.move_to(pose_.x, pose_.y);
    const double r = grid_.resolution();
    const auto reach = static_cast<std::int32_t>(2.0 / r);  // 2 m around the robot
    const CellIndex c = grid_.world_to_index(pose_.x, pose_.y);
    const double nx = -std::sin(pose_.yaw);
    const double ny = std::cos(pose_.yaw);
    grid_.for_each_in_window({c.x - reach, c.y - reach}, {c.x + reach + 1, c.y + reach + 1}, [&](CellIndex i, std::int8_t& cell) {
      const WorldPoint w = grid_.cell_center(i);
      const double lateral = (w.x - pose_.x) * nx + (w.y - pose_.y) * ny;
      if (std::abs(lateral) > 2.0) return;
      if (!obstacles_) {
        cell = std::abs(lateral) < 1.2 ? std::int8_t{1} : std::int8_t{3};  // trail surface / verge
        return;
      }
      const bool post = std::abs(std::abs(lateral) - 1.8) < 0.15 && std::fmod(std::abs(w.x) + std::abs(w.y), 6.0) < 0.3;
      if (post) {
        cell = 100;
      } else if (cell != 100) {
        cell = 0;
      }
    });
    GridSnapshot& snap = out_.write_slot();
    grid_.copy_to(snap.cells.span());
    snap.origin = grid_.origin();
    snap.size = grid_.size_x();
    snap.resolution = r;
    snap.cycle = tick.cycle;
    out_.publish();
  }

 private:
  Mailbox<Pose2>& poses_;
  Mailbox<GridSnapshot>& out_;
  RollingGrid<std::int8_t> grid_;
  bool obstacles_;
  Pose2 pose_;
};

volatile std::sig_atomic_t g_interrupted = 0;
void on_signal(int) { g_interrupted = 1; }

// Grey PNG of an occupancy snapshot: unknown mid-grey, free white, occupied
// black; row 0 of the image is the map's highest y (north up).
Status save_obstacle_png(const GridSnapshot& snap, const std::string& path) {
  const auto n = static_cast<std::size_t>(snap.size);
  std::vector<std::uint8_t> pixels(n * n);
  for (std::size_t row = 0; row < n; ++row) {
    for (std::size_t col = 0; col < n; ++col) {
      const std::int8_t v = snap.cells[(n - 1 - row) * n + col];
      pixels[row * n + col] = v < 0 ? 128 : static_cast<std::uint8_t>(255 - v * 255 / 100);
    }
  }
  return write_png(path, static_cast<std::uint32_t>(n), static_cast<std::uint32_t>(n), PngColor::grey, pixels);
}

int run_demo(const std::string& config_path, std::optional<double> duration_override, const std::string& png_path) {
  const ConfigNode root = config_path.empty() ? ConfigNode::parse(kBuiltinDemoConfig, kBuiltinDemoConfigName)
                                              : ConfigNode::load_file(config_path);
  DemoConfig config = parse_demo_config(root);
  if (duration_override) config.duration_s = *duration_override;
  log::set_min_level(config.runtime.log_level);
  log::start(config.runtime.log_sink);

  // --- start-up: everything the real-time threads use is allocated here ---
  MonotonicClock clock;
  auto queue = std::make_unique<MotionQueue>();
  TaskEvent motion_ready;
  Mailbox<Pose2> poses_for_obstacles;
  Mailbox<Pose2> poses_for_terrain;
  const auto obstacle_cells = static_cast<std::size_t>(config.obstacle_grid.size_cells) * static_cast<std::size_t>(config.obstacle_grid.size_cells);
  const auto terrain_cells = static_cast<std::size_t>(config.terrain_grid.size_cells) * static_cast<std::size_t>(config.terrain_grid.size_cells);
  Mailbox<GridSnapshot> obstacle_maps(obstacle_cells);
  Mailbox<GridSnapshot> terrain_maps(terrain_cells);
  MotionTask motion(*queue, motion_ready, config.speed_mps);
  OdometryTask odometry(*queue, poses_for_obstacles, poses_for_terrain);
  GridTask obstacle_task(poses_for_obstacles, obstacle_maps, config.obstacle_grid, true);
  GridTask terrain_task(poses_for_terrain, terrain_maps, config.terrain_grid, false);

  Scheduler scheduler(clock, config.runtime.scheduler);
  for (const TaskSpec& spec : config.tasks) {
    Status added = spec.name == "motion"         ? scheduler.add(spec, motion)
                   : spec.name == "odometry"     ? scheduler.add(spec, odometry, &motion_ready)
                   : spec.name == "obstacle_map" ? scheduler.add(spec, obstacle_task)
                   : spec.name == "terrain_map"  ? scheduler.add(spec, terrain_task)
                                                 : Status::error("task '" + spec.name + "' is not part of the demo");
    if (!added) {
      std::fprintf(stderr, "trailnav runtime-demo: %s\n", added.message().c_str());
      log::stop();
      return 2;
    }
  }

  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  std::printf("trailnav runtime-demo: %zu tasks, obstacle grid %dx%d at %.2f m, terrain grid %dx%d at %.2f m, %.1f s\n",
              config.tasks.size(), config.obstacle_grid.size_cells, config.obstacle_grid.size_cells,
              config.obstacle_grid.resolution_m, config.terrain_grid.size_cells, config.terrain_grid.size_cells,
              config.terrain_grid.resolution_m, config.duration_s);
  if (Status s = scheduler.start(); !s) {
    std::fprintf(stderr, "trailnav runtime-demo: %s\n", s.message().c_str());
    log::stop();
    return 1;
  }
  alloc_guard::reset_counters();
  const bool guard = alloc_guard::arm();

  // --- the reader side: not real-time ---
  std::uint64_t obstacle_snapshots = 0;
  std::uint64_t terrain_snapshots = 0;
  ProgressBar progress("runtime-demo", config.duration_s, "s");
  const Nanos start = clock.now();
  while (g_interrupted == 0) {
    const double elapsed = nanos_to_seconds(clock.now() - start);
    if (elapsed >= config.duration_s) break;
    if (obstacle_maps.try_read() != nullptr) ++obstacle_snapshots;
    if (terrain_maps.try_read() != nullptr) ++terrain_snapshots;
    progress.update(elapsed);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  progress.finish();
  scheduler.stop();
  alloc_guard::disarm();
  if (obstacle_maps.try_read() != nullptr) ++obstacle_snapshots;

  std::printf("\nrealtime scheduling: %s; memory locked: %s\n", scheduler.realtime_active() ? "SCHED_FIFO" : "normal",
              scheduler.memory_locked() ? "yes" : "no");
  print_task_table(stdout, scheduler);
  std::printf("\nrobot drove %.1f m; snapshots received: obstacle map %llu, terrain map %llu\n", odometry.distance,
              static_cast<unsigned long long>(obstacle_snapshots), static_cast<unsigned long long>(terrain_snapshots));
  const std::uint64_t heap_ops = print_allocation_report(stdout);
  if (!png_path.empty() && obstacle_maps.last_read_sequence() > 0) {
    if (Status s = save_obstacle_png(obstacle_maps.last_read(), png_path); !s) {
      std::fprintf(stderr, "trailnav runtime-demo: %s\n", s.message().c_str());
    } else {
      std::printf("obstacle map written to %s\n", png_path.c_str());
    }
  }
  log::stop();
  return guard && heap_ops == 0 ? 0 : 1;
}

}  // namespace

void add_demo_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "runtime-demo",
      "Run the real-time runtime on a simulated robot: the task table's threads move a 600x600 obstacle grid and a\n"
      "300x300 terrain grid with the robot and hand snapshots to a reader, then print per-task runs, overruns,\n"
      "slips and timing, and the heap operations seen on real-time threads after arm (must be 0; exit code 1 if not).");
  static std::string config_path;
  static std::optional<double> duration;
  static std::string png_path;
  cmd->add_option("--config", config_path, "Demo configuration (YAML); default: the built-in board/demo/runtime-demo.yaml")
      ->check(CLI::ExistingFile);
  cmd->add_option("--duration", duration, "Seconds to run, overriding demo.duration_s")->check(CLI::Range(0.1, 86400.0));
  cmd->add_option("--png", png_path, "Write the last obstacle-map snapshot to this PNG file");
  cmd->callback([] {
    const int code = run_demo(config_path, duration, png_path);
    if (code != 0) throw CLI::RuntimeError(code);
  });
}

}  // namespace trailnav::cli
