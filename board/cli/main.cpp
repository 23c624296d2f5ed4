// trailnav: the command-line tool of the trailnav navigation stack.
#include <CLI/CLI.hpp>

#include <cstdio>

#include "commands.hpp"
#include "trailnav/runtime/config.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "trailnav: real-time navigation for outdoor robots (terrain-adaptive obstacle detection,\n"
      "OpenStreetMap navigation). Each subcommand has its own --help.",
      "trailnav"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("trailnav ") + TRAILNAV_VERSION);
  trailnav::cli::add_bench_demo_command(app);
  trailnav::cli::add_demo_command(app);
  trailnav::cli::add_jitter_command(app);
  trailnav::cli::add_decode_command(app);
  trailnav::cli::add_replay_command(app);
  trailnav::cli::add_sim_command(app);
  trailnav::cli::add_obstacles_command(app);
  trailnav::cli::add_score_labels_command(app);
  trailnav::cli::add_terrain_commands(app);
  trailnav::cli::add_trav_commands(app);
  trailnav::cli::add_lidar_odometry_command(app);
  trailnav::cli::add_station_commands(app);
  trailnav::cli::add_route_command(app);
  trailnav::cli::add_subgoal_eval_command(app);
  trailnav::cli::add_pose_graph_command(app);
  trailnav::cli::add_place_commands(app);
  trailnav::cli::add_gps_decode_command(app);
  trailnav::cli::add_imu_decode_command(app);
  trailnav::cli::add_can_decode_command(app);
  trailnav::cli::add_pose_eval_command(app);
  trailnav::cli::add_echo_command(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const trailnav::ConfigError& e) {
    std::fprintf(stderr, "trailnav: configuration error: %s\n", e.what());
    return 2;
  }
  return 0;
}
