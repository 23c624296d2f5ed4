// `trailnav trav-train` and `trailnav trav-eval`: traversability learnt from
// driving demonstrations (thesis chapter 6, docs/traversability.md).
// Training drives the terrain analysis over demonstration recordings, labels
// the words of the cells the robot's footprint crossed as positive and the
// rest unlabelled, and learns the terrain models of both learners for the
// full feature vector and the ablations NoRe and NoRS; evaluation classifies
// every cell of every local map of held-out recordings and scores it against
// the robot profile's truth with the thesis' rule.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "commands.hpp"
#include "terminal.hpp"
#include "trav_run.hpp"

namespace trailnav::cli {
namespace {

namespace fs = std::filesystem;
namespace trav = perception::trav;

struct TrainOptions {
  std::vector<std::string> inputs;
  std::string profile;
  std::string out;
  std::string extend;
  std::string config_file;
  double local_map = 20.0;
  double max_range = 20.0;
  std::uint32_t max_models = 8;
  double prior = 0.0;
  std::string bins;  // "w:n,w:n,w:n,w:n,w:n,w:n"
  bool verbose = false;
  bool quiet = false;
};

// "--bins 0.1:6,16:10,8:4,0.03:3,15:3,0.4:5,0.1:3": width and count per dimension.
bool parse_bins(const std::string& text, trav::VocabularyConfig& v, const char* who) {
  if (text.empty()) return true;
  std::size_t pos = 0;
  for (int d = 0; d < trav::kDims; ++d) {
    const std::size_t end = text.find(',', pos);
    const std::string item = text.substr(pos, end == std::string::npos ? std::string::npos : end - pos);
    const std::size_t colon = item.find(':');
    char* e1 = nullptr;
    char* e2 = nullptr;
    const std::string w = colon == std::string::npos ? "" : item.substr(0, colon);
    const std::string n = colon == std::string::npos ? "" : item.substr(colon + 1);
    const float width = std::strtof(w.c_str(), &e1);
    const long count = std::strtol(n.c_str(), &e2, 10);
    if (w.empty() || n.empty() || *e1 != '\0' || *e2 != '\0' || count < 1 || count > 64 || (d + 1 < trav::kDims && end == std::string::npos) ||
        (d + 1 == trav::kDims && end != std::string::npos)) {
      std::fprintf(stderr, "%s: --bins: expected six WIDTH:COUNT pairs (max_dz m, remission mean, remission standard "
                   "deviation, RMS plane distance m, slope degrees, height above the ground m), got '%s'\n", who,
                   text.c_str());
      return false;
    }
    v.bins[static_cast<std::size_t>(d)] = {width, static_cast<std::uint32_t>(count)};
    pos = end + 1;
  }
  if (std::string e = trav::check_vocabulary(v); !e.empty()) {
    std::fprintf(stderr, "%s: --bins: %s\n", who, e.c_str());
    return false;
  }
  return true;
}

int train(TrainOptions& o) {
  const char* who = "trailnav trav-train";
  perception::TerrainConfig terrain;
  if (!load_terrain_config(o.config_file, terrain, who)) return 2;
  const eval::LoadedProfile profile = eval::load_profile(o.profile);
  if (!profile.profile) {
    std::fprintf(stderr, "%s: --profile: %s\n", who, profile.error.c_str());
    return 2;
  }
  eval::TravRunOptions run;
  run.inputs = o.inputs;
  run.terrain = terrain;
  run.profile = *profile.profile;
  run.recorder.local_map_distance = o.local_map;
  run.recorder.max_range = o.max_range;
  run.recorder.footprint = run.profile.footprint;
  if (std::string e = trav::check_recorder(run.recorder); !e.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, e.c_str());
    return 2;
  }
  trav::LearnerConfig learner;
  learner.max_models = o.max_models;
  learner.prior = o.prior;
  if (std::string e = trav::check_learner(learner); !e.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, e.c_str());
    return 2;
  }
  std::optional<trav::TravModelFile> old;
  if (!o.extend.empty()) {
    auto loaded = trav::load_trav_model(o.extend);
    if (!loaded.model) {
      std::fprintf(stderr, "%s: --extend: %s\n", who, loaded.error.c_str());
      return 2;
    }
    if (loaded.model->profile != run.profile.name) {
      std::fprintf(stderr, "%s: --extend: %s was learnt for robot profile '%s', not '%s'\n", who, o.extend.c_str(),
                   loaded.model->profile.c_str(), run.profile.name.c_str());
      return 2;
    }
    old = std::move(loaded.model);
  }
  trav::VocabularyConfig vocabulary;
  if (old) vocabulary = old->sets.front().vocabulary;
  if (!parse_bins(o.bins, vocabulary, who)) return 2;
  ProgressBar bar("demonstrations", 100.0, "%");
  if (!o.quiet) run.progress = [&](double f) { bar.update(100.0 * f); };
  const eval::TravTrainReport r = eval::run_trav_train(run, vocabulary, learner, old ? &*old : nullptr);
  const std::size_t local_maps = r.sets.front().local_maps.size();
  if (!o.quiet) bar.finish();
  if (!r.error.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, r.error.c_str());
    return 2;
  }
  std::printf("robot profile %s (footprint %.2f x %.2f m): %llu revolutions, %llu local maps of %.0f m\n",
              run.profile.name.c_str(), run.profile.footprint.length, run.profile.footprint.width,
              static_cast<unsigned long long>(r.revolutions), static_cast<unsigned long long>(local_maps), o.local_map);
  std::printf("words (full vector): %llu, %llu of them positive (the footprint's cells), %llu cells beyond %.0f m, %llu "
              "dropped\n",
              static_cast<unsigned long long>(r.recorder.words), static_cast<unsigned long long>(r.recorder.positive_words),
              static_cast<unsigned long long>(r.recorder.too_far), o.max_range,
              static_cast<unsigned long long>(r.recorder.dropped));
  for (std::size_t s = 0; s < r.sets.size(); ++s) {
    const eval::TravTrainSet& t = r.sets[s];
    std::printf("  %-5s |V| %6u: %zu terrain model(s); local maps learnt %llu (new model %llu, forced %llu), without "
                "positives %llu\n",
                std::string(trav::feature_set_name(t.set)).c_str(), trav::Vocabulary(r.model.sets[s].vocabulary).size(),
                r.model.sets[s].models.size(), static_cast<unsigned long long>(t.learnt),
                static_cast<unsigned long long>(t.created), static_cast<unsigned long long>(t.forced),
                static_cast<unsigned long long>(t.unlearnt));
  }
  if (o.verbose) {
    std::printf("local maps of the full vector: terrain model (new / forced), chi-square p-value, positive and unlabelled "
                "words\n");
    for (std::size_t i = 0; i < r.sets[0].local_maps.size(); ++i) {
      const eval::TravLocalMap& l = r.sets[0].local_maps[i];
      char p[32] = "-";
      if (!l.assignment.created) std::snprintf(p, sizeof p, "%.3g", l.assignment.test.p_value);
      std::printf("  %3zu: model %d%s  p %s  %llu / %llu\n", i + 1, l.assignment.model,
                  l.assignment.created ? " (new)" : l.assignment.forced ? " (forced)" : "", p,
                  static_cast<unsigned long long>(l.positive), static_cast<unsigned long long>(l.unlabelled));
    }
    const trav::TravModelSet& full = r.model.sets[0];
    trav::TravModels models(trav::Vocabulary(full.vocabulary), full.learner);
    models.set_models(full.models);
    std::printf("terrain models of the full vector: P(trav) of PNB (estimated unless --prior), Elkan-Noto's c; POS prior %.3f\n",
                models.pos_prior());
    for (std::uint32_t m = 0; m < models.models(); ++m) {
      std::printf("  model %u: %llu positive, %llu unlabelled words; P(trav) %.3f, c %.3f\n", m,
                  static_cast<unsigned long long>(models.counts(m).total_positive()),
                  static_cast<unsigned long long>(models.counts(m).total_unlabelled()), models.pnb_prior(m),
                  models.elkan_noto_c(m));
    }
  }
  if (Status st = trav::save_trav_model(o.out, r.model); !st) {
    std::fprintf(stderr, "%s: %s\n", who, st.message().c_str());
    return 2;
  }
  std::printf("wrote %s\n", o.out.c_str());
  return 0;
}

struct EvalOptions {
  std::vector<std::string> inputs;
  std::string model;
  std::string profile;  // default: the model's
  std::string config_file;
  std::string report;
  std::string png_dir;
  double local_map = 20.0;
  double max_range = 20.0;
  bool quiet = false;
};

int evaluate(EvalOptions& o) {
  const char* who = "trailnav trav-eval";
  perception::TerrainConfig terrain;
  if (!load_terrain_config(o.config_file, terrain, who)) return 2;
  if (!o.report.empty() && o.report != "json") {
    std::fprintf(stderr, "%s: --report takes 'json', got '%s'\n", who, o.report.c_str());
    return 2;
  }
  auto loaded = trav::load_trav_model(o.model);
  if (!loaded.model) {
    std::fprintf(stderr, "%s: %s\n", who, loaded.error.c_str());
    return 2;
  }
  const eval::LoadedProfile profile = eval::load_profile(o.profile.empty() ? loaded.model->profile : o.profile);
  if (!profile.profile) {
    std::fprintf(stderr, "%s: robot profile: %s\n", who, profile.error.c_str());
    return 2;
  }
  eval::TravRunOptions run;
  run.inputs = o.inputs;
  run.terrain = terrain;
  run.profile = *profile.profile;
  run.recorder.local_map_distance = o.local_map;
  run.recorder.max_range = o.max_range;
  if (std::string e = trav::check_recorder(run.recorder); !e.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, e.c_str());
    return 2;
  }
  if (!o.png_dir.empty()) {
    if (o.inputs.size() != 1) {
      std::fprintf(stderr, "%s: --png takes one recording (each has its own world frame)\n", who);
      return 2;
    }
    std::error_code ec;
    std::filesystem::create_directories(o.png_dir, ec);
    if (ec) {
      std::fprintf(stderr, "%s: --png: cannot create %s: %s\n", who, o.png_dir.c_str(), ec.message().c_str());
      return 2;
    }
    run.png_dir = o.png_dir;
  }
  const bool json = o.report == "json";
  ProgressBar bar("evaluation", 100.0, "%");
  if (!o.quiet && !json) run.progress = [&](double f) { bar.update(100.0 * f); };
  const eval::TravEvalReport r = eval::run_trav_eval(run, *loaded.model);
  if (!o.quiet && !json) bar.finish();
  if (!r.error.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, r.error.c_str());
    return 2;
  }
  if (json) {
    std::printf("{\"profile\": \"%s\", \"revolutions\": %llu, \"local_maps\": %llu, \"step_ms\": %.4f, \"results\": [",
                run.profile.name.c_str(), static_cast<unsigned long long>(r.revolutions),
                static_cast<unsigned long long>(r.local_maps), r.step_ms);
    for (std::size_t i = 0; i < r.rows.size(); ++i) {
      const eval::TravEvalRow& row = r.rows[i];
      std::printf("%s\n  {\"method\": \"%s\", \"features\": \"%s\", \"precision\": %.4f, \"recall\": %.4f, \"specificity\": "
                  "%.4f, \"cells\": %llu, \"tp\": %llu, \"fp\": %llu, \"tn\": %llu, \"fn\": %llu, \"forgiven\": %llu, "
                  "\"strict_specificity\": %.4f, \"called_traversable\": {",
                  i ? "," : "", std::string(trav::method_name(row.method)).c_str(),
                  std::string(trav::feature_set_name(row.set)).c_str(), row.scores.precision(), row.scores.recall(),
                  row.scores.specificity(), static_cast<unsigned long long>(row.scores.cells()),
                  static_cast<unsigned long long>(row.scores.tp), static_cast<unsigned long long>(row.scores.fp),
                  static_cast<unsigned long long>(row.scores.tn), static_cast<unsigned long long>(row.scores.fn),
                  static_cast<unsigned long long>(row.scores.forgiven), row.scores.strict_specificity());
      bool first = true;
      for (int c = 0; c < perception::kTerrainClasses; ++c) {
        const auto k = static_cast<std::size_t>(c);
        if (row.class_cells[k] == 0) continue;
        std::printf("%s\"%s\": %.4f", first ? "" : ", ",
                    std::string(perception::terrain_class_name(static_cast<perception::TerrainClass>(c))).c_str(),
                    static_cast<double>(row.called_traversable[k]) / static_cast<double>(row.class_cells[k]));
        first = false;
      }
      std::printf("}, \"false_positives\": {");
      for (std::size_t c = 1; c < eval::kUntraversableCauses; ++c) {
        std::printf("%s\"%s\": %llu", c > 1 ? ", " : "", eval::untraversable_name(static_cast<eval::Untraversable>(c)),
                    static_cast<unsigned long long>(row.false_positives[c]));
      }
      std::printf("}}");
    }
    std::printf("\n]}\n");
    return 0;
  }
  std::printf("robot profile %s: %llu revolutions, %llu local maps; a 0.5 m step (terrain features and words) %.2f ms\n",
              run.profile.name.c_str(), static_cast<unsigned long long>(r.revolutions),
              static_cast<unsigned long long>(r.local_maps), r.step_ms);
  std::printf("method features  precision  recall  specificity    cells   strict specificity (every untraversable cell "
              "called traversable counted)\n");
  for (const eval::TravEvalRow& row : r.rows) {
    std::printf("%-6s %-8s  %9.3f  %6.3f  %11.3f  %7llu   %.3f\n", std::string(trav::method_name(row.method)).c_str(),
                std::string(trav::feature_set_name(row.set)).c_str(), row.scores.precision(), row.scores.recall(),
                row.scores.specificity(), static_cast<unsigned long long>(row.scores.cells()),
                row.scores.strict_specificity());
  }
  std::printf("called traversable, by true class (full vector, PNB / POS):\n");
  for (int c = 0; c < perception::kTerrainClasses; ++c) {
    const auto k = static_cast<std::size_t>(c);
    if (r.rows.size() < 2 || r.rows[0].class_cells[k] == 0) continue;
    std::printf("  %-11s %.3f / %.3f of %llu cells\n",
                std::string(perception::terrain_class_name(static_cast<perception::TerrainClass>(c))).c_str(),
                static_cast<double>(r.rows[0].called_traversable[k]) / static_cast<double>(r.rows[0].class_cells[k]),
                static_cast<double>(r.rows[1].called_traversable[k]) / static_cast<double>(r.rows[1].class_cells[k]),
                static_cast<unsigned long long>(r.rows[0].class_cells[k]));
  }
  if (r.rows.size() >= 2) {
    std::printf("false positives (thesis' rule), by why the cell is not traversable (full vector, PNB / POS):\n");
    for (std::size_t c = 1; c < eval::kUntraversableCauses; ++c) {
      std::printf("  %-11s %llu / %llu\n", eval::untraversable_name(static_cast<eval::Untraversable>(c)),
                  static_cast<unsigned long long>(r.rows[0].false_positives[c]),
                  static_cast<unsigned long long>(r.rows[1].false_positives[c]));
    }
  }
  std::printf("thesis (real robots): Viona PNB 0.992 / 0.79 / 0.987; Obelix PNB 0.978 / 0.947 / 0.984, POS 0.975 / 0.947 / "
              "0.982\n");
  for (const std::string& f : r.files) std::printf("wrote %s\n", f.c_str());
  return 0;
}

}  // namespace

void add_trav_commands(CLI::App& app) {
  auto* tr = app.add_subcommand(
      "trav-train",
      "Learn this robot's traversability from driving demonstrations (thesis chapter 6): the cells its\n"
      "footprint crossed are positive examples, every other cell unlabelled; Positive Naive Bayes and the\n"
      "Elkan-Noto classifier learn from them, with terrain models chosen by a chi-square test, for the full\n"
      "feature vector and the ablations NoRe (no remission) and NoRS (no roughness and slope). Inputs are\n"
      "simulated recordings of demonstration drives (their true trajectory gives the footprint).\n"
      "Profiles: large (street, dirt, grass, low vegetation, other ground), small (street, dirt and other\n"
      "hard ground: walkways, plazas), or a YAML file\n"
      "(docs/traversability.md).\n"
      "Example:\n"
      "  trailnav sim --scenario demo-large --out build/sim/demo-large\n"
      "  trailnav trav-train build/sim/demo-large --profile large --out build/large.tntrav");
  static TrainOptions t;
  tr->add_option("recordings", t.inputs, "Simulated recordings of demonstration drives")->required();
  tr->add_option("--profile", t.profile, "Robot profile: large, small or a YAML file")->required();
  tr->add_option("--out", t.out, "Model file to write (written atomically)")->required();
  tr->add_option("--extend", t.extend, "Continue training this model (same profile) instead of starting anew");
  tr->add_option("--config", t.config_file, "YAML file with a `terrain:` section (grid, d, minPoints; docs/terrain.md)");
  tr->add_option("--local-map", t.local_map, "d_M: metres driven per local map")->capture_default_str();
  tr->add_option("--max-range", t.max_range, "Cells farther from the robot give no feature (m)")->capture_default_str();
  tr->add_option("--max-models", t.max_models, "Most terrain models per feature set")->capture_default_str();
  tr->add_option("--prior", t.prior, "P(trav) for PNB (0: Elkan-Noto's estimate per terrain model)")->capture_default_str();
  tr->add_option("--bins", t.bins,
                 "Vocabulary: WIDTH:COUNT for max |dz| (m), remission mean, remission standard deviation, RMS distance "
                 "from the cell's plane (m), slope (degrees), height above the ground (m), depth below it (m: a ditch); "
                 "default\n0.1:6,16:10,8:4,0.03:3,15:3,0.4:5,0.1:3");
  tr->add_flag("--verbose", t.verbose, "Also list each local map: its terrain model, the test's p-value, its words");
  tr->add_flag("--quiet", t.quiet, "No progress bars");
  tr->callback([&] { std::exit(train(t)); });

  auto* ev = app.add_subcommand(
      "trav-eval",
      "Classify every cell of every local map of held-out simulated recordings with a traversability model\n"
      "and score it against the robot profile's truth (free ground of a kind the profile may cross): precision,\n"
      "recall and specificity of PNB and POS for every feature set in the model, with the thesis' rule (an\n"
      "untraversable cell called traversable is a false positive only when its 8 neighbours are called\n"
      "traversable too), and what share of each true terrain class is called traversable.\n"
      "Example:\n"
      "  trailnav trav-eval build/sim/mixed-route --model build/large.tntrav --report json");
  static EvalOptions e;
  ev->add_option("recordings", e.inputs, "Simulated recordings (never the training drives)")->required();
  ev->add_option("--model", e.model, "Model file (trailnav trav-train)")->required();
  ev->add_option("--profile", e.profile, "Robot profile for the truth (default: the model's)");
  ev->add_option("--config", e.config_file, "YAML file with a `terrain:` section (docs/terrain.md)");
  ev->add_option("--local-map", e.local_map, "d_M: metres driven per local map")->capture_default_str();
  ev->add_option("--max-range", e.max_range, "Cells farther from the robot give no feature (m)")->capture_default_str();
  ev->add_option("--png", e.png_dir,
                 "Write DIR/traversability-PNB.png and -POS.png: the full vector's answer per cell against the truth "
                 "(one recording)");
  ev->add_option("--report", e.report, "json: one JSON object (fields method, features, precision, recall, specificity, cells)");
  ev->add_flag("--quiet", e.quiet, "No progress bars");
  ev->callback([&] { std::exit(evaluate(e)); });
}

}  // namespace trailnav::cli
