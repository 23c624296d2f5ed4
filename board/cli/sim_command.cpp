// `trailnav sim`: simulate a robot driving through a scenario world and write
// a bench recording of its sensors' bytes plus the ground truth.
#include <cstdio>
#include <string>

#include "commands.hpp"
#include "scenario.hpp"
#include "simulator.hpp"
#include "terminal.hpp"

namespace trailnav::cli {
namespace {

struct SimCliOptions {
  sim::SimOptions sim;
  std::string season = "summer";
  std::string camera_size;
  bool quiet = false;
  bool list = false;
};

int run_sim(SimCliOptions& o) {
  if (o.list) {
    for (const std::string& name : sim::builtin_scenario_names()) {
      const auto loaded = sim::load_scenario(name);
      std::printf("%-14s %s\n", name.c_str(), loaded.scenario ? loaded.scenario->description.c_str() : loaded.error.c_str());
    }
    return 0;
  }
  if (o.sim.out.empty()) {
    std::fprintf(stderr, "trailnav sim: --out DIR is required\n");
    return 2;
  }
  if (o.season != "summer" && o.season != "winter") {
    std::fprintf(stderr, "trailnav sim: --season takes summer or winter, not '%s'\n", o.season.c_str());
    return 2;
  }
  o.sim.season = o.season == "winter" ? sim::Season::winter : sim::Season::summer;
  if (!o.camera_size.empty()) {
    int w = 0, h = 0;
    char end = 0;
    if (std::sscanf(o.camera_size.c_str(), "%dx%d%c", &w, &h, &end) != 2 || w < 8 || h < 8 || w > 4096 || h > 4096) {
      std::fprintf(stderr, "trailnav sim: --camera-size takes WIDTHxHEIGHT, 8 to 4096 pixels each, not '%s'\n",
                   o.camera_size.c_str());
      return 2;
    }
    o.sim.camera_spec.width = w;
    o.sim.camera_spec.height = h;
  }
  ProgressBar progress("sim", 1.0, "s");
  bool started = false;
  if (!o.quiet) {
    o.sim.progress = [&](double done, double total) {
      if (!started) {
        progress = ProgressBar("sim", total, "s simulated");
        started = true;
      }
      progress.update(done);
    };
  }
  const sim::SimReport r = sim::run_simulation(o.sim);
  if (started) progress.finish();
  if (!r.error.empty()) {
    std::fprintf(stderr, "trailnav sim: %s\n", r.error.c_str());
    return 2;
  }
  std::fprintf(stderr, "trailnav sim: scenario %s, seed %llu, %s (%s)\n", r.scenario.c_str(),
               static_cast<unsigned long long>(o.sim.seed), r.lidar_model.c_str(), r.calibration.c_str());
  std::fprintf(stderr, "  %.1f s simulated, route %.1f m; wrote %s\n", r.sim_seconds, r.route_length, o.sim.out.c_str());
  std::fprintf(stderr, "  lidar: %llu data packets, %llu position packets, %llu rays, %llu returns\n",
               static_cast<unsigned long long>(r.lidar_packets), static_cast<unsigned long long>(r.position_packets),
               static_cast<unsigned long long>(r.rays), static_cast<unsigned long long>(r.returns));
  std::fprintf(stderr, "  gps: %llu NMEA sentences; imu: %llu MTData2 messages; can: %llu frames; gpio: %llu levels\n",
               static_cast<unsigned long long>(r.nmea_sentences), static_cast<unsigned long long>(r.imu_messages),
               static_cast<unsigned long long>(r.can_frames), static_cast<unsigned long long>(r.gpio_levels));
  if (o.sim.camera)
    std::fprintf(stderr, "  camera (simulated, %s): %llu frames of %d x %d, %llu rays, rendered in %.2f s\n",
                 sim::season_name(o.sim.season), static_cast<unsigned long long>(r.camera_frames), o.sim.camera_spec.width,
                 o.sim.camera_spec.height, static_cast<unsigned long long>(r.camera_rays), r.camera_seconds);
  const double rays_per_s = r.lidar_seconds > 0 ? static_cast<double>(r.rays) / r.lidar_seconds : 0.0;
  std::fprintf(stderr, "  speed: world built in %.2f s; lidar %.2f M rays/s = %.2fx real time; total %.2f s\n",
               r.world_seconds, rays_per_s / 1e6, r.lidar_seconds > 0 ? r.sim_seconds / r.lidar_seconds : 0.0,
               r.total_seconds);
  return 0;
}

}  // namespace

void add_sim_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "sim",
      "Simulate the robot driving a scenario and write a bench recording of exactly the bytes its\n"
      "sensors send (Velodyne data and position packets, NMEA GGA/RMC/GST/VTG, Xsens MTData2, CAN\n"
      "wheel odometry per board/sim/trailnav-robot.dbc) plus the ground truth in DIR/truth/ and the\n"
      "OpenStreetMap view in DIR/world.osm (docs/simulator.md). The same seed gives the same bytes.\n"
      "Built-in scenarios: urban, meadow-block, forest-track, mixed-route, junctions (--list).\n"
      "With --camera, also an image stream of rendered grey frames (simulated: a sky, the terrain classes'\n"
      "textures, obstacles, sun and shadows; --season winter: snow, an overcast sky, bare trees, fog) for\n"
      "the place task: `trailnav place-map` on a summer drive, then a winter drive replayed into trailnavd\n"
      "(docs/place.md).\n"
      "Replay the result with `trailnav replay DIR`.");
  static SimCliOptions o;
  cmd->add_option("--scenario", o.sim.scenario, "Built-in scenario name or a scenario YAML file")->capture_default_str();
  cmd->add_option("--seed", o.sim.seed, "Random seed: noise, grass, GPS bias, ...")->capture_default_str();
  cmd->add_option("--duration", o.sim.duration,
                  "Seconds to simulate (default: the scenario's, else until the route's end)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--lidar", o.sim.lidar, "Lidar model: VLP-16, VLP-16-HiRes, VLP-32C, HDL-32E or HDL-64E (default: the scenario's)");
  cmd->add_option("--calibration", o.sim.calibration,
                  "Velodyne calibration file (default: the model's file in ../shared/data/velodyne/calibration/)");
  cmd->add_option("--out", o.sim.out, "Output recording directory");
  cmd->add_flag("--no-lidar", [&](std::int64_t) { o.sim.lidar_packets = false; },
                "Leave the lidar streams empty (for pose work: GPS, IMU, CAN and GPIO only, much faster)");
  cmd->add_flag("--camera", o.sim.camera, "Render a camera's frames into the image stream `camera` (simulated)");
  cmd->add_option("--season", o.season, "The camera's season: summer or winter")->capture_default_str();
  cmd->add_option("--camera-size", o.camera_size, "Rendered frame size, WIDTHxHEIGHT (default 128x64)");
  cmd->add_option("--camera-rate", o.sim.camera_spec.rate, "Camera frames per second")->capture_default_str()->check(CLI::Range(0.5, 60.0));
  cmd->add_flag("--list", o.list, "List the built-in scenarios and exit");
  cmd->add_flag("--quiet", o.quiet, "No progress bar");
  cmd->callback([] {
    const int code = run_sim(o);
    if (code != 0) throw CLI::RuntimeError(code);
  });
}

}  // namespace trailnav::cli
