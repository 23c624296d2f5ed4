// `trailnav eval-subgoals`: the subgoal alignment of thesis §8.4 over
// simulated recordings (board/eval/subgoal_eval.hpp): RMSE of raw OSM
// subgoals and of corrected ones per sample count and sequence length K
// (mean over seeds, Fig. 8.5), and junction success rates (Fig. 8.7).
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "builtin_models.hpp"
#include "commands.hpp"
#include "subgoal_eval.hpp"
#include "terminal.hpp"
#include "trailnav/perception/trav_config.hpp"
#include "trailnav/runtime/config.hpp"

namespace trailnav::cli {
namespace {

struct SubgoalEvalCli {
  std::vector<std::string> recordings;
  std::vector<std::size_t> samples{1000, 10000, 50000};
  std::vector<int> sequences{1, 2, 3, 4, 5, 6};
  int seeds = 10;
  std::string model;
  std::string config_file;
  eval::SubgoalEvalOptions options;
  bool quiet = false;
  std::string unknown_cells = "other";
  std::vector<std::string> costs{"classes"};
  std::string trav_model;
  std::string trav_method = "pnb";
};

int run_eval(SubgoalEvalCli& c) {
  const char* who = "trailnav eval-subgoals";
  eval::SubgoalEvalOptions& o = c.options;
  o.recordings = c.recordings;
  o.samples = c.samples;
  o.sequences = c.sequences;
  o.seeds = c.seeds;
  o.navigator.aligner.known_cells_only = c.unknown_cells == "known-only";
  if (!c.config_file.empty()) {
    try {
      const ConfigNode root = ConfigNode::load_file(c.config_file);
      o.terrain = perception::parse_terrain_config(root.map("terrain"));
    } catch (const ConfigError& e) {
      std::fprintf(stderr, "%s: %s\n", who, e.what());
      return 2;
    }
  }
  std::optional<perception::RandomForest> forest;
  std::string model_name = c.model.empty() ? (o.terrain.model.empty() ? "" : o.terrain.model) : c.model;
  if (model_name.empty()) {
    auto parsed = perception::RandomForest::parse(
        builtin_terrain_model(velodyne::Model::vlp16),
        "built-in terrain-sim.tnrf");
    if (!parsed.forest) {
      std::fprintf(stderr, "%s: %s\n", who, parsed.error.c_str());
      return 1;
    }
    forest.emplace(std::move(*parsed.forest));
    model_name = "built-in terrain-sim.tnrf";
  } else {
    auto loaded = perception::RandomForest::load(model_name);
    if (!loaded.forest) {
      std::fprintf(stderr, "%s: %s\n", who, loaded.error.c_str());
      return 1;
    }
    forest.emplace(std::move(*loaded.forest));
  }
  o.forest = &*forest;
  o.forest_name = model_name;
  // No config: the cells the model learnt from (terrain_run checks them).
  if (c.config_file.empty()) perception::adopt_forest_settings(*forest, o.terrain);
  // The learnt traversability cost (docs/traversability.md "On the robot"): its model's full feature set.
  o.costs.clear();
  for (const std::string& name : c.costs) {
    o.costs.push_back(name == "traversability" ? subgoals::AlignerConfig::CellCost::traversability
                                               : subgoals::AlignerConfig::CellCost::classes);
  }
  std::unique_ptr<perception::trav::TravModels> trav_models;
  if (!c.trav_model.empty()) {
    perception::trav::TraversabilityConfig tc;
    tc.model = c.trav_model;
    auto start = perception::trav::load_start_models(tc);
    if (!start.models) {
      std::fprintf(stderr, "%s: --trav-model: %s\n", who, start.error.c_str());
      return 1;
    }
    trav_models = std::move(start.models);
    o.trav_models = trav_models.get();
    o.trav_method = c.trav_method == "pos" ? perception::trav::Method::pos : perception::trav::Method::pnb;
  } else if (std::find(c.costs.begin(), c.costs.end(), "traversability") != c.costs.end()) {
    std::fprintf(stderr, "%s: --cell-cost traversability needs --trav-model MODEL (trailnav trav-train)\n", who);
    return 2;
  }
  std::map<std::string, std::unique_ptr<ProgressBar>> bars;
  std::string current;
  if (!c.quiet) {
    o.progress = [&](const std::string& stage, double f) {
      if (stage != current) {
        if (!current.empty()) bars[current]->finish();
        current = stage;
        bars[stage] = std::make_unique<ProgressBar>(stage, 100.0, "%");
      }
      bars[stage]->update(100.0 * f);
    };
  }
  const eval::SubgoalEvalReport r = eval::evaluate_subgoals(o);
  if (!current.empty()) bars[current]->finish();
  if (!r.error.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, r.error.c_str());
    return 1;
  }
  std::printf("subgoal alignment (thesis §8.4): %zu recording(s), %.0f m planned on their world.osm, %zu subgoals sent\n"
              "terrain model %s; %d seeds per setting; error = Eq. 8.15 (distance to the true path - %.1f m)\n\n",
              c.recordings.size(), r.route_length, r.subgoals_sent, model_name.c_str(), c.seeds, 0.5 * o.street_width);
  std::printf("raw OpenStreetMap subgoals: RMSE %.2f m (max %.2f m)\n\n", r.raw_rmse, r.raw_max);
  for (const auto cost : o.costs) {
    std::printf("corrected, cell cost %s%s, mean RMSE over seeds [m] (reduction against raw)\n%8s",
                eval::cell_cost_name(cost),
                cost == subgoals::AlignerConfig::CellCost::traversability ? (" of " + c.trav_model).c_str() : "",
                "samples");
    for (int k : c.sequences) std::printf("        K=%d     ", k);
    std::printf("\n");
    for (std::size_t s : c.samples) {
      std::printf("%8zu", s);
      for (int k : c.sequences) {
        for (const auto& cr : r.configs) {
          if (cr.cost == cost && cr.samples == s && cr.sequence == k)
            std::printf("  %5.2f (%+4.0f%%) ", cr.mean_rmse, r.raw_rmse > 0 ? 100.0 * (cr.mean_rmse / r.raw_rmse - 1.0) : 0.0);
        }
      }
      std::printf("\n");
    }
    std::printf("\n");
  }
  if (!r.junctions.empty()) {
    std::printf("\njunctions: seeds (of %d) with every subgoal sent near the junction on the trail (error <= %.1f m)\n",
                c.seeds, o.junction_tolerance);
    for (std::size_t j = 0; j < r.junctions.size(); ++j) {
      std::printf("  %s   raw %s\n", r.junctions[j].c_str(), r.raw_junction_ok[j] ? "ok" : "off");
      for (const auto cost : o.costs) {
        for (std::size_t s : c.samples) {
          std::printf("    %-14s %6zu samples:", eval::cell_cost_name(cost), s);
          for (int k : c.sequences)
            for (const auto& cr : r.configs)
              if (cr.cost == cost && cr.samples == s && cr.sequence == k)
                std::printf("  K=%d %2d/%d", k, cr.junction_successes[j], c.seeds);
          std::printf("\n");
        }
      }
    }
  }
  std::printf("\n%llu steps; alignment took %.2f s for all settings together\n", static_cast<unsigned long long>(r.updates),
              r.seconds_aligning);
  return 0;
}

}  // namespace

void add_subgoal_eval_command(CLI::App& app) {
  static SubgoalEvalCli c;
  CLI::App* cmd = app.add_subcommand(
      "eval-subgoals",
      "Evaluate the subgoal alignment (thesis §8.4) on simulated recordings (trailnav sim): plan on each\n"
      "recording's world.osm from the robot's GPS pose to its route's end, estimate the terrain-class map from\n"
      "the lidar with the terrain model, and align the subgoals with every combination of --samples and\n"
      "--sequences, --seeds times each. Prints the RMSE of Eq. 8.15 for raw and corrected subgoals and, for\n"
      "the `junctions` scenario, how many seeds got through each junction on the trail (Fig. 8.7 cases a-f).\n"
      "Example:\n"
      "  trailnav sim --scenario junctions --seed 3 --out build/sim/junctions\n"
      "  trailnav eval-subgoals build/sim/junctions --samples 1000 --sequences 4");
  cmd->add_option("recordings", c.recordings, "Simulated recording directories")->required();
  cmd->add_option("--samples", c.samples, "Sample counts (comma-separated)")->delimiter(',')->capture_default_str();
  cmd->add_option("--sequences", c.sequences, "Sequence lengths K (comma-separated)")->delimiter(',')->capture_default_str();
  cmd->add_option("--seeds", c.seeds, "Seeds per setting")->capture_default_str();
  cmd->add_option("--model", c.model, "Terrain model file (default: the built-in simulation model)");
  cmd->add_option("--config", c.config_file, "YAML file with a `terrain:` section (docs/terrain.md)");
  cmd->add_option("--spacing", c.options.navigator.spacing, "m between subgoals")->capture_default_str();
  cmd->add_option("--lookahead", c.options.navigator.lookahead, "m ahead of the robot a subgoal joins the alignment")->capture_default_str();
  cmd->add_option("--reach", c.options.navigator.reach, "m before a subgoal the next one is sent")->capture_default_str();
  cmd->add_option("--sigma-d", c.options.navigator.aligner.sigma_d, "Eq. 8.7 step-length sigma, m")->capture_default_str();
  cmd->add_option("--sigma-theta", c.options.navigator.aligner.sigma_theta, "Eq. 8.7 angle sigma, rad")->capture_default_str();
  cmd->add_option("--sigma-along", c.options.navigator.aligner.sigma_along, "Eq. 8.8 sigma along the street, m")->capture_default_str();
  cmd->add_option("--sigma-across", c.options.navigator.aligner.sigma_across, "Eq. 8.8 sigma across the street, m")->capture_default_str();
  cmd->add_option("--lambda", c.options.navigator.aligner.lambda, "Eq. 8.11 lambda")->capture_default_str();
  cmd->add_option("--along-prior", c.options.navigator.aligner.along_prior,
                  "Sigma of the prior on a subgoal's offset along the street from its raw position, m (0: off, the thesis)")
      ->capture_default_str();
  cmd->add_option("--corner-sigma", c.options.navigator.aligner.corner_sigma,
                  "Sigma of a corner's shift along the street, m (0: off, the thesis)")
      ->capture_default_str();
  cmd->add_option("--corner-turn", c.options.navigator.aligner.corner_turn,
                  "Sigma of the turn of the route after a corner about that corner, rad (0: off)")
      ->capture_default_str();
  cmd->add_option("--separation", c.options.navigator.aligner.separation,
                  "A sample whose subgoals come closer than this many subgoal spacings to one two or more steps\n"
                  "before them (and closer than the map's own) doubles back and is weighted out (0: off, the thesis)")
      ->capture_default_str();
  cmd->add_option("--unknown-cells", c.unknown_cells,
                  "How a patch treats cells without observations: known-only (mean over the known cells) or other\n"
                  "(each costs unknown_cost, the thesis' reading)")
      ->check(CLI::IsMember({"known-only", "other"}))
      ->capture_default_str();
  cmd->add_option("--cell-cost", c.costs,
                  "What a cell costs the aligner, one setting or both side by side (comma-separated): classes (the\n"
                  "class costs of the terrain section) or traversability (1 - P(trav) of the learnt layer: --trav-model)")
      ->delimiter(',')
      ->check(CLI::IsMember({"classes", "traversability"}))
      ->capture_default_str();
  cmd->add_option("--trav-model", c.trav_model, "Traversability model (.tntrav, trailnav trav-train) for --cell-cost traversability");
  cmd->add_option("--trav-method", c.trav_method, "Its learner: pnb or pos")
      ->check(CLI::IsMember({"pnb", "pos"}))
      ->capture_default_str();
  cmd->add_option("--csv", c.options.csv, "Also write every sent subgoal (raw and each setting's first seed) to this CSV");
  cmd->add_flag("-q,--quiet", c.quiet, "No progress bars");
  cmd->callback([] { std::exit(run_eval(c)); });
}

}  // namespace trailnav::cli
