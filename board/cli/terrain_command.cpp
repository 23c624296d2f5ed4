// `trailnav terrain-train` and `trailnav terrain-eval`: the terrain
// classifier offline. Training learns a random forest from labelled cells
// (simulated recordings' truth, or CSV files users labelled); evaluation runs
// the terrain analysis over recordings and prints the cell-wise confusion
// matrices of the integrated map and of single features (thesis Table 7.2).
#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "commands.hpp"
#include "terminal.hpp"
#include "terrain_run.hpp"
#include "trailnav/perception/forest_training.hpp"
#include "trailnav/perception/terrain_class_map.hpp"

namespace trailnav::cli {
namespace {

namespace fs = std::filesystem;
using perception::ConfusionMatrix;
using perception::TerrainClass;

}  // namespace

bool load_terrain_config(const std::string& file, perception::TerrainConfig& out, const char* who) {
  if (file.empty()) return true;
  try {
    const ConfigNode root = ConfigNode::load_file(file);
    out = perception::parse_terrain_config(root.map("terrain"));
    return true;
  } catch (const ConfigError& e) {
    std::fprintf(stderr, "%s: %s\n", who, e.what());
    return false;
  }
}

namespace {

void print_counts(const perception::LabelledFeatures& d) {
  const auto c = d.class_counts();
  for (int t = 0; t < perception::kTerrainClasses; ++t) {
    std::printf("%s %s %llu", t ? "," : "", std::string(perception::terrain_class_name(static_cast<TerrainClass>(t))).c_str(),
                static_cast<unsigned long long>(c[static_cast<std::size_t>(t)]));
  }
}

// One recording through the terrain analysis, with a progress bar; prints
// the error and returns false when it fails.
bool run_recording(eval::TerrainRunOptions& run, const std::string& label, bool quiet, const char* who,
                   eval::TerrainRunReport& report) {
  ProgressBar bar(label + " " + fs::path(run.input).filename().string(), 100.0, "%");
  if (!quiet) run.progress = [&](double f) { bar.update(100.0 * f); };
  report = eval::run_terrain(run);
  if (!quiet) bar.finish();
  if (!report.error.empty()) std::fprintf(stderr, "%s: %s\n", who, report.error.c_str());
  return report.error.empty();
}

struct TrainOptions {
  std::vector<std::string> inputs;
  std::string out;
  std::string config_file;
  std::string save_features;
  perception::ForestParams forest;
  std::size_t max_per_class = 40000;
  std::vector<std::string> class_cells;  // CLASS=N: that class's own cap
  std::string lidar;  // empty: the recordings' lidar model
  bool quiet = false;
};

int train(TrainOptions& o) {
  const char* who = "trailnav terrain-train";
  perception::TerrainConfig config;
  if (!load_terrain_config(o.config_file, config, who)) return 2;
  if (std::string e = perception::check_forest_params(o.forest); !e.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, e.c_str());
    return 2;
  }
  perception::LabelledFeatures data;
  std::string lidar;  // the recordings' lidar model, if they agree
  bool from_recordings = false;
  for (const std::string& input : o.inputs) {
    if (fs::path(input).extension() == ".csv") {
      const std::size_t before = data.size();
      if (std::string e = eval::load_labelled_csv(input, data); !e.empty()) {
        std::fprintf(stderr, "%s: %s\n", who, e.c_str());
        return 2;
      }
      std::printf("%s: %zu labelled cells\n", input.c_str(), data.size() - before);
      continue;
    }
    from_recordings = true;
    eval::TerrainRunOptions run;
    run.input = input;
    run.config = config;
    run.collect_samples = true;
    eval::TerrainRunReport r;
    if (!run_recording(run, "features", o.quiet, who, r)) return 2;
    if (o.lidar.empty() && !lidar.empty() && r.lidar != lidar) {
      std::fprintf(stderr,
                   "%s: %s is a %s recording, the ones before are %s: their remissions differ; train one model per lidar "
                   "(or say which lidar the model is for with --lidar)\n",
                   who, input.c_str(), r.lidar.c_str(), lidar.c_str());
      return 2;
    }
    lidar = r.lidar;
    std::printf("%s: %llu revolutions, %llu steps, %zu labelled cell features (%llu mixed cells left out):", input.c_str(),
                static_cast<unsigned long long>(r.revolutions), static_cast<unsigned long long>(r.counters.steps),
                r.samples.size(), static_cast<unsigned long long>(r.unlabelled));
    print_counts(r.samples);
    std::printf("\n");
    data.append(r.samples);
  }
  if (!o.save_features.empty()) {
    if (Status st = eval::save_labelled_csv(o.save_features, data); !st) {
      std::fprintf(stderr, "%s: %s\n", who, st.message().c_str());
      return 2;
    }
    std::printf("wrote %s (%zu labelled cells)\n", o.save_features.c_str(), data.size());
  }
  std::array<std::size_t, perception::kTerrainClasses> caps;
  caps.fill(o.max_per_class);
  for (const std::string& c : o.class_cells) {
    const std::size_t eq = c.find('=');
    const auto cls = eq == std::string::npos ? std::nullopt : perception::parse_terrain_class(c.substr(0, eq));
    char* end = nullptr;
    const std::string count = eq == std::string::npos ? std::string() : c.substr(eq + 1);
    const unsigned long long n = std::strtoull(count.c_str(), &end, 10);
    if (!cls || count.empty() || end != count.c_str() + count.size() || count[0] == '-') {
      std::fprintf(stderr, "%s: --class-cells '%s': expected CLASS=N with CLASS one of street, dirt, grass, vegetation, other\n",
                   who, c.c_str());
      return 2;
    }
    caps[static_cast<std::size_t>(*cls)] = static_cast<std::size_t>(n);
  }
  if (std::any_of(caps.begin(), caps.end(), [](std::size_t v) { return v > 0; })) data.limit_per_class(caps, o.forest.seed);
  std::printf("training on %zu cells:", data.size());
  print_counts(data);
  std::printf("\n");
  ProgressBar bar("trees", o.forest.trees, "trees");
  const auto trained = perception::train_forest(data, o.forest, o.quiet ? std::function<void(double)>{} : [&](double f) {
    bar.update(f * o.forest.trees);
  });
  if (!o.quiet) bar.finish();
  if (!trained.forest) {
    std::fprintf(stderr, "%s: %s\n", who, trained.error.c_str());
    return 2;
  }
  perception::RandomForest model = *trained.forest;
  if (from_recordings) {
    // The cells the features came from (CSV files do not say theirs).
    if (std::string e = model.set_feature_settings(perception::feature_settings_of(config)); !e.empty()) {
      std::fprintf(stderr, "%s: %s\n", who, e.c_str());
      return 2;
    }
  }
  if (!o.lidar.empty()) lidar = o.lidar;
  if (std::string e = model.set_lidar(lidar); !e.empty()) {
    std::fprintf(stderr, "%s: --lidar: %s\n", who, e.c_str());
    return 2;
  }
  if (Status st = model.save(o.out); !st) {
    std::fprintf(stderr, "%s: %s\n", who, st.message().c_str());
    return 2;
  }
  std::printf("forest: %zu trees, %zu nodes, %zu leaves, depth up to %zu, for %s; wrote %s\n", model.trees(), model.nodes(),
              model.leaves(), model.max_depth(), lidar.empty() ? "any lidar (not said)" : lidar.c_str(), o.out.c_str());
  std::printf("out-of-bag confusion (rows: true class, columns: estimated; single features):\n%s",
              perception::format_confusion(trained.out_of_bag).c_str());
  return 0;
}

struct EvalOptions {
  std::vector<std::string> inputs;
  std::string model;
  std::string config_file;
  bool quiet = false;
};

// The thesis' Table 7.2 diagonal (integrated map), the goal per class.
double thesis_recall(int t) {
  switch (static_cast<TerrainClass>(t)) {
    case TerrainClass::street: return 0.79;
    case TerrainClass::grass: return 0.91;
    case TerrainClass::dirt: return 0.78;
    case TerrainClass::other: return 0.76;
    case TerrainClass::vegetation: return 0.0;  // not in the thesis
  }
  return 0.0;
}

int evaluate(EvalOptions& o) {
  const char* who = "trailnav terrain-eval";
  perception::TerrainConfig config;
  if (!load_terrain_config(o.config_file, config, who)) return 2;
  if (!o.model.empty()) config.model = o.model;
  if (config.model.empty()) {
    std::fprintf(stderr, "%s: give --model FILE (or terrain.model in --config)\n", who);
    return 2;
  }
  auto loaded = perception::RandomForest::load(config.model);
  if (!loaded.forest) {
    std::fprintf(stderr, "%s: %s\n", who, loaded.error.c_str());
    return 2;
  }
  if (o.config_file.empty() && loaded.forest->feature_settings().said()) {
    // No config: the cells the model learnt from.
    perception::adopt_forest_settings(*loaded.forest, config);
  }
  std::printf("model %s: %zu trees, %zu nodes, depth up to %zu, for %s\n", config.model.c_str(), loaded.forest->trees(),
              loaded.forest->nodes(), loaded.forest->max_depth(),
              loaded.forest->lidar().empty() ? "any lidar (not said)" : loaded.forest->lidar().c_str());
  ConfusionMatrix integrated, single, last;
  double step_ms = 0.0, register_ms = 0.0;
  std::uint64_t steps = 0, revolutions = 0, features = 0;
  for (const std::string& input : o.inputs) {
    eval::TerrainRunOptions run;
    run.input = input;
    run.config = config;
    run.forest = &*loaded.forest;
    run.forest_name = config.model;
    eval::TerrainRunReport r;
    if (!run_recording(run, "terrain", o.quiet, who, r)) return 2;
    std::printf("\n%s: %llu revolutions, %llu steps, %llu cell features; align %.2f ms + register %.2f ms per revolution, "
                "step %.2f ms\n",
                input.c_str(), static_cast<unsigned long long>(r.revolutions), static_cast<unsigned long long>(r.counters.steps),
                static_cast<unsigned long long>(r.counters.features), r.align_ms, r.register_ms, r.step_ms);
    std::printf("integrated map, Eq. 7.15 (single features in brackets):\n%s",
                perception::format_confusion(r.integrated, &r.single).c_str());
    integrated += r.integrated;
    single += r.single;
    last += r.last;
    step_ms += r.step_ms * static_cast<double>(r.counters.steps);
    register_ms += r.register_ms * static_cast<double>(r.revolutions);
    steps += r.counters.steps;
    revolutions += r.revolutions;
    features += r.counters.features;
  }
  if (o.inputs.size() > 1) {
    std::printf("\nall %zu recordings: integrated map, Eq. 7.15 (single features in brackets):\n%s", o.inputs.size(),
                perception::format_confusion(integrated, &single).c_str());
  }
  std::printf("\neach labelled cell once, the map's class at its last observation:\n%s",
              perception::format_confusion(last).c_str());
  std::printf("\nrecall per class (integrated / single feature / thesis Table 7.2):\n");
  for (int t = 0; t < perception::kTerrainClasses; ++t) {
    if (integrated.row_total(t) == 0) continue;
    const double goal = thesis_recall(t);
    std::printf("  %-11s %.3f / %.3f / %s%s\n", std::string(perception::terrain_class_name(static_cast<TerrainClass>(t))).c_str(),
                integrated.recall(t), single.recall(t), goal > 0 ? std::to_string(goal).substr(0, 4).c_str() : "-",
                goal > 0 && integrated.recall(t) < goal ? "  (below the thesis)" : "");
  }
  std::printf("time: register %.2f ms per revolution, classification step %.2f ms (%llu steps, %llu features)\n",
              revolutions ? register_ms / static_cast<double>(revolutions) : 0.0, steps ? step_ms / static_cast<double>(steps) : 0.0,
              static_cast<unsigned long long>(steps), static_cast<unsigned long long>(features));
  return 0;
}

}  // namespace

void add_terrain_commands(CLI::App& app) {
  auto* tr = app.add_subcommand(
      "terrain-train",
      "Learn the terrain classifier (thesis §7.2.2): a random forest over the six cell features (max, mean\n"
      "and standard deviation of remission, roughness, slope, and the remission's spread over the cells\n"
      "around). Inputs are simulated recordings, whose cells are labelled from the truth (only cells of\n"
      "one class), and CSV files of labelled cells (docs/terrain.md). The model file says the lidar and\n"
      "the cells (--config's map resolution, min_points, min_range, max_range) its features came from;\n"
      "trailnavd refuses a config that makes other cells. Prints the out-of-bag confusion matrix. The\n"
      "same inputs and seed give the same model, byte for byte.\n"
      "Example:\n"
      "  trailnav terrain-train build/sim/urban build/sim/forest --out build/terrain.tnrf");
  static TrainOptions t;
  tr->add_option("inputs", t.inputs, "Simulated recording directories and/or labelled-cell .csv files")->required();
  tr->add_option("--out", t.out, "Model file to write")->required();
  tr->add_option("--config", t.config_file, "YAML file with a `terrain:` section (grid, d, minPoints; docs/terrain.md)");
  tr->add_option("--trees", t.forest.trees, "Trees in the forest")->capture_default_str();
  tr->add_option("--features-per-split", t.forest.features_per_split, "Random features tried at each split")
      ->capture_default_str();
  tr->add_option("--min-split", t.forest.min_samples_split, "Fewest samples a node needs to be split")->capture_default_str();
  tr->add_option("--max-depth", t.forest.max_depth, "Deepest tree level (0: unlimited)")->capture_default_str();
  tr->add_option("--seed", t.forest.seed, "Random seed (bootstrap samples, features per split)")->capture_default_str();
  tr->add_option("--max-per-class", t.max_per_class, "Keep at most this many cells of each class (0: all)")
      ->capture_default_str();
  tr->add_option("--class-cells", t.class_cells,
                 "CLASS=N: keep at most N cells of this class instead (0: all), e.g. other=60000; the share of a class "
                 "in training moves the line between overlapping classes (docs/terrain.md)");
  tr->add_option("--threads", t.forest.threads, "Trees grown in parallel (0: one per core)")->capture_default_str();
  tr->add_option("--save-features", t.save_features, "Also write every labelled cell feature to this CSV");
  tr->add_option("--lidar", t.lidar,
                 "The lidar model the forest is for (VLP-16, HDL-64E, ...; default: the recordings'). Its remissions are "
                 "that sensor's: the terrain thread and the tools refuse the model for another lidar");
  tr->add_flag("--quiet", t.quiet, "No progress bars");
  tr->callback([&] { std::exit(train(t)); });

  auto* ev = app.add_subcommand(
      "terrain-eval",
      "Run the terrain analysis (thesis §7.2) over simulated recordings with a trained model and print\n"
      "the cell-wise confusion matrix against the truth, as the thesis' Table 7.2: the integrated class\n"
      "map (Eq. 7.15) and, in brackets, the forest's answer to each single feature, for every labelled\n"
      "cell at every step; then each labelled cell once, with the map's class at its last observation.\n"
      "Example:\n"
      "  trailnav terrain-eval build/sim/mixed-route --model build/terrain.tnrf");
  static EvalOptions e;
  ev->add_option("inputs", e.inputs, "Simulated recording directories")->required();
  ev->add_option("--model", e.model, "Model file (trailnav terrain-train)");
  ev->add_option("--config", e.config_file, "YAML file with a `terrain:` section (docs/terrain.md)");
  ev->add_flag("--quiet", e.quiet, "No progress bars");
  ev->callback([&] { std::exit(evaluate(e)); });
}

}  // namespace trailnav::cli
