// The subgoal evaluation of thesis §8.4 on simulated recordings: the robot
// plans on the recording's world.osm (with its mapping errors) from its GPS
// pose to the route's end, and every aligner configuration (samples x K x
// seeds) runs in lockstep on the same terrain-class map, which the terrain
// analysis estimates from the lidar with a trained forest, as on the robot.
//
// Frames: the terrain map is registered with the true trajectory (the local
// frame is the simulated world); the OSM subgoals come into it through the
// pose estimator's UTM pose, run on the recording's GPS, IMU and wheels (so
// GPS errors enter as on the robot): q_world = P(t) U(t)^-1 q_utm.
//
// Each configuration and seed runs the navigation task's own logic
// (nav::Navigator, as in trailnavd): subgoals join the aligner when they come
// within `lookahead` metres of the robot along the route (its GPS position
// projected onto the route), and the robot drives to a subgoal until it is
// almost reached (`reach` metres along). A subgoal counts as sent with its
// estimate when it is reached. The error of a sent subgoal is Eq. 8.15: its distance to the true
// path minus half a 3 m street width, floored at 0. Per configuration the
// RMSE over all sent subgoals of all recordings is taken per seed, then
// averaged over the seeds, as in Fig. 8.5. At the junctions a recording's
// truth lists (the `junctions` scenario: the cases of Fig. 8.7), a seed
// succeeds when every subgoal sent while the robot is within the junction's
// window has an error of at most `junction_tolerance`.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "trailnav/navigation/osm/road_graph.hpp"
#include "trailnav/navigation/navigator/navigator.hpp"
#include "trailnav/perception/random_forest.hpp"
#include "trailnav/perception/terrain_config.hpp"
#include "trailnav/perception/trav_learner.hpp"

namespace trailnav::eval {

struct SubgoalEvalOptions {
  std::vector<std::string> recordings;
  std::vector<std::size_t> samples{1000, 10000, 50000};
  std::vector<int> sequences{1, 2, 3, 4, 5, 6};
  int seeds = 10;
  // The navigation task's settings (spacing, lookahead, reach, the aligner);
  // the goal, samples, sequence and seed are set per recording and configuration.
  nav::NavigatorConfig navigator;
  perception::TerrainConfig terrain;
  const perception::RandomForest* forest = nullptr;
  std::string forest_name = "the terrain model";  // its file, for errors
  // The cells' costs the aligner is run with, side by side in lockstep on the
  // same maps: the class costs (terrain.cost) and/or the learnt
  // traversability layer's 1 − P(trav), which needs `trav_models`
  // (docs/traversability.md): its layer runs on the terrain steps as in
  // trailnavd's terrain thread.
  std::vector<subgoals::AlignerConfig::CellCost> costs{subgoals::AlignerConfig::CellCost::classes};
  const perception::trav::TravModels* trav_models = nullptr;
  perception::trav::Method trav_method = perception::trav::Method::pnb;
  double trav_local_map = 20.0, trav_max_range = 20.0;
  osm::RoutingProfile profile;
  double street_width = 3.0;  // s of Eq. 8.15
  double junction_before = 8.0, junction_after = 12.0;  // m of route around a junction
  double junction_tolerance = 0.5;  // m of Eq. 8.15 error a feasible subgoal may have
  std::function<void(const std::string& stage, double fraction)> progress;
  // Optional: one row per sent subgoal (raw and every configuration's first seed).
  std::string csv;
};

struct SubgoalConfigResult {
  subgoals::AlignerConfig::CellCost cost = subgoals::AlignerConfig::CellCost::classes;
  std::size_t samples = 0;
  int sequence = 0;
  std::vector<double> rmse;  // per seed
  double mean_rmse = 0.0;
  // Per junction (in the order of SubgoalEvalReport::junctions): seeds that succeeded.
  std::vector<int> junction_successes;
};

struct SubgoalEvalReport {
  std::string error;
  std::size_t subgoals_sent = 0;   // per configuration and seed, all recordings
  double raw_rmse = 0.0;           // the uncorrected OSM subgoals
  double raw_max = 0.0;
  std::vector<std::string> junctions;   // "recording: a (t1/t2, shifted 7 m)"
  std::vector<int> raw_junction_ok;     // raw subgoals feasible at each junction (0 or 1)
  std::vector<SubgoalConfigResult> configs;
  double route_length = 0.0;       // m, planned, all recordings
  double seconds_aligning = 0.0;   // total time in aligner updates
  std::uint64_t updates = 0;
};

SubgoalEvalReport evaluate_subgoals(const SubgoalEvalOptions& options);

// "classes" or "traversability".
const char* cell_cost_name(subgoals::AlignerConfig::CellCost cost) noexcept;

}  // namespace trailnav::eval
