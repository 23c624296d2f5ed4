// Each subcommand of `trailnav` registers itself on the application.
#pragma once

#include <CLI/CLI.hpp>

#include <string>

#include "trailnav/perception/terrain_config.hpp"

namespace trailnav::cli {

void add_demo_command(CLI::App& app);
void add_bench_demo_command(CLI::App& app);
void add_jitter_command(CLI::App& app);
void add_lidar_odometry_command(CLI::App& app);
void add_station_commands(CLI::App& app);
void add_decode_command(CLI::App& app);
void add_replay_command(CLI::App& app);
void add_sim_command(CLI::App& app);
void add_obstacles_command(CLI::App& app);
void add_score_labels_command(CLI::App& app);
void add_gps_decode_command(CLI::App& app);
void add_imu_decode_command(CLI::App& app);
void add_can_decode_command(CLI::App& app);
void add_pose_eval_command(CLI::App& app);
void add_echo_command(CLI::App& app);
void add_terrain_commands(CLI::App& app);
void add_trav_commands(CLI::App& app);
// The `terrain:` section of a YAML file into `out` (nothing when `file` is
// empty); prints the error after `who` and returns false.
bool load_terrain_config(const std::string& file, perception::TerrainConfig& out, const char* who);
void add_route_command(CLI::App& app);
void add_subgoal_eval_command(CLI::App& app);
void add_pose_graph_command(CLI::App& app);
void add_place_commands(CLI::App& app);

}  // namespace trailnav::cli
