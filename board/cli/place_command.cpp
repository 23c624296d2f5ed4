// `trailnav place-eval DATABASE QUERY [--ground-truth CSV] [--tolerance N]
// [--report json]` and `trailnav place-map RECORDING --out DB`: camera place recognition across seasons (thesis chapter
// 5) measured on two image sequences, side by side with SeqSLAM
// (board/eval/place_eval.hpp, docs/place.md).
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include "commands.hpp"
#include "place_eval.hpp"
#include "place_map.hpp"
#include "plot.hpp"
#include "terminal.hpp"

namespace trailnav::cli {
namespace {

struct Options {
  eval::PlaceEvalOptions eval;
  std::string report;
  std::string png;
  std::string matches_out;
  bool quiet = false;
  bool float_descriptors = false;
  bool no_seqslam = false;
  bool no_online = false;
};

std::string num(double v, int digits) {
  if (!std::isfinite(v)) return "null";
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", digits, v);
  return b;
}

Rgb color_of(const std::string& method) {
  if (method == "raw") return {150, 150, 150};
  if (method == "filter") return {120, 170, 230};
  if (method == "filter+seq") return {20, 80, 200};
  if (method == "zca+filter") return {240, 160, 90};
  if (method == "zca+filter+seq") return {210, 60, 20};
  if (method == "online") return {200, 170, 220};
  if (method == "online+lag") return {160, 100, 200};
  if (method == "online+lag+seq") return {100, 30, 150};
  return {40, 160, 60};  // seqslam
}

int run(Options& o) {
  const char* who = "trailnav place-eval";
  if (o.report != "" && o.report != "json") {
    std::fprintf(stderr, "%s: --report takes json, not '%s'\n", who, o.report.c_str());
    return 2;
  }
  const auto& s = o.eval.sequence;
  if (s.min_length < 1 || s.row_gap < 1 || s.column_gap < 0 || o.eval.peak_radius < 0 || !(o.eval.zca_epsilon > 0.0) ||
      o.eval.subsample < 1 || o.eval.max_images < 0 || o.eval.online_lag < 0 || o.eval.online_sequence.min_length < 0) {
    std::fprintf(stderr,
                 "%s: --min-sequence and --row-gap must be at least 1, --column-gap and --peak-radius not negative, "
                 "--zca-epsilon positive, --subsample at least 1, --online-lag and --online-min-sequence not negative\n",
                 who);
    return 2;
  }
  if (o.eval.ground_truth.empty() && !o.png.empty()) {
    std::fprintf(stderr, "%s: --png draws precision-recall curves, which need --ground-truth\n", who);
    return 2;
  }
  o.eval.compact = !o.float_descriptors;
  o.eval.seqslam = !o.no_seqslam;
  o.eval.online = !o.no_online;
  o.eval.online_sequence.row_gap = o.eval.sequence.row_gap;
  o.eval.online_sequence.column_gap = o.eval.sequence.column_gap;
  std::unique_ptr<ProgressBar> bar;
  std::string stage;
  if (!o.quiet) {
    o.eval.progress = [&](const std::string& name, double f) {
      if (name != stage) {
        if (bar) bar->finish();
        stage = name;
        bar = std::make_unique<ProgressBar>(name, 100.0, "%");
      }
      bar->update(100.0 * f);
    };
  }
  eval::PlaceEvalReport r;
  try {
    r = eval::run_place_eval(o.eval);
  } catch (const std::exception& e) {
    r.error = e.what();
  }
  if (bar) bar->finish();
  if (!r.error.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, r.error.c_str());
    return 1;
  }
  const bool truth = !o.eval.ground_truth.empty();
  if (!o.matches_out.empty()) {
    std::FILE* out = std::fopen(o.matches_out.c_str(), "w");
    if (out == nullptr) {
      std::fprintf(stderr, "%s: cannot write %s\n", who, o.matches_out.c_str());
      return 1;
    }
    std::fprintf(out, "method,query,database,score,correct\n");
    for (const eval::PlaceMethod& m : r.methods)
      for (const auto& x : m.matches)
        std::fprintf(out, "%s,%d,%d,%.6g,%s\n", m.method.c_str(), r.query_order[static_cast<std::size_t>(x.query)] + 1,
                     x.database + 1, static_cast<double>(x.score), truth ? (r.truth.correct(x) ? "1" : "0") : "");
    std::fclose(out);
  }
  if (!o.png.empty()) {
    Plot p;
    p.title = "Place recognition: precision against recall";
    p.notes.push_back("database " + o.eval.database + " (" + std::to_string(r.database_images) + " images), queries " +
                      o.eval.query + " (" + std::to_string(r.query_images) + ")");
    p.notes.push_back("case " + o.eval.case_name + ", " + std::to_string(r.positives) + " queries with a place, tolerance " +
                      (o.eval.tolerance >= 0 || o.eval.ground_truth == "same-index"
                           ? std::to_string(o.eval.tolerance >= 0 ? o.eval.tolerance : 5) + " images"
                           : std::string("from the ground truth")) +
                      "; HOG of " + std::to_string(r.patch) + "-pixel patches, " + std::to_string(r.descriptor_length) +
                      " values an image");
    p.x_label = "recall";
    p.y_label = "precision";
    for (const eval::PlaceMethod& m : r.methods) {
      PlotSeries series;
      series.label = m.method + "  best F1 " + num(m.curve.best.f1, 3);
      series.color = color_of(m.method);
      for (const auto& pt : m.curve.points) {
        if (pt.matches == 0) continue;
        series.x.push_back(pt.recall);
        series.y.push_back(pt.precision);
      }
      series.mark_last_best = m.curve.best.matches > 0;
      series.best_x = m.curve.best.recall;
      series.best_y = m.curve.best.precision;
      p.series.push_back(std::move(series));
    }
    const Status st = write_plot(o.png, p);
    if (!st.is_ok()) {
      std::fprintf(stderr, "%s: %s\n", who, st.message().c_str());
      return 1;
    }
  }
  if (o.report == "json") {
    std::printf("{\"database\": \"%s\", \"query\": \"%s\", \"case\": \"%s\", \"database_images\": %zu, \"query_images\": %zu, "
                "\"queries_with_place\": %s, \"image_width\": %d, \"image_height\": %d, \"descriptor_length\": %d, "
                "\"descriptor_bytes\": %zu, \"hog_patch\": %d, \"methods\": [",
                o.eval.database.c_str(), o.eval.query.c_str(), o.eval.case_name.c_str(), r.database_images, r.query_images,
                truth ? std::to_string(r.positives).c_str() : "null", r.width, r.height, r.descriptor_length,
                r.descriptor_bytes, r.patch);
    for (std::size_t i = 0; i < r.methods.size(); ++i) {
      const eval::PlaceMethod& m = r.methods[i];
      const auto& b = m.curve.best;
      std::printf("%s{\"method\": \"%s\", \"best_f1\": %s, \"precision\": %s, \"recall\": %s, \"threshold\": %s, "
                  "\"matches\": %zu}",
                  i ? ", " : "", m.method.c_str(), truth ? num(b.f1, 4).c_str() : "null",
                  truth ? num(b.precision, 4).c_str() : "null", truth ? num(b.recall, 4).c_str() : "null",
                  truth ? num(b.threshold, 6).c_str() : "null", m.matches.size());
    }
    std::printf("], \"seconds\": {\"descriptors\": %s, \"similarity\": %s, \"zca\": %s, \"filters\": %s, \"seqslam\": %s, "
                "\"online\": %s}}\n",
                num(r.seconds_descriptors, 3).c_str(), num(r.seconds_similarity, 3).c_str(), num(r.seconds_zca, 3).c_str(),
                num(r.seconds_filters, 3).c_str(), num(r.seconds_seqslam, 3).c_str(), num(r.seconds_online, 3).c_str());
    return 0;
  }
  std::printf("place recognition, case %s: %zu database images, %zu queries (%d x %d pixels), HOG of %d-pixel patches, "
              "%d values an image (%zu bytes stored)\n",
              o.eval.case_name.c_str(), r.database_images, r.query_images, r.width, r.height, r.patch, r.descriptor_length,
              r.descriptor_bytes);
  if (!truth) {
    std::printf("  no --ground-truth: matches only (--matches-out writes them)\n");
    for (const eval::PlaceMethod& m : r.methods) std::printf("  %-15s %zu matches\n", m.method.c_str(), m.matches.size());
    return 0;
  }
  std::printf("  %zu queries have a place in the database\n", r.positives);
  std::printf("  %-15s %8s %10s %8s %12s %8s\n", "method", "best F1", "precision", "recall", "threshold", "matches");
  for (const eval::PlaceMethod& m : r.methods) {
    const auto& b = m.curve.best;
    std::printf("  %-15s %8.3f %10.3f %8.3f %12.6g %8zu\n", m.method.c_str(), b.f1, b.precision, b.recall, b.threshold,
                b.matches);
  }
  std::printf("  seconds: descriptors %.2f, similarities %.2f, ZCA %.2f, filters %.2f, SeqSLAM %.2f, online %.2f\n",
              r.seconds_descriptors, r.seconds_similarity, r.seconds_zca, r.seconds_filters, r.seconds_seqslam,
              r.seconds_online);
  if (!o.png.empty()) std::printf("  precision-recall curves: %s\n", o.png.c_str());
  return 0;
}

struct MapOptions {
  eval::PlaceMapOptions map;
  std::string out;
  bool quiet = false;
};

int run_map(MapOptions& o) {
  const char* who = "trailnav place-map";
  if (o.out.empty()) {
    std::fprintf(stderr, "%s: --out DB is required\n", who);
    return 2;
  }
  if (o.map.width < 4 || o.map.height < 4 || !(o.map.every_m >= 0.0) || o.map.zca_rank < 0 || o.map.zca_rank > 1024 ||
      !(o.map.zca_epsilon > 0.0)) {
    std::fprintf(stderr,
                 "%s: --width and --height must be at least 4 pixels, --every not negative, --zca-rank 0 to 1024 and "
                 "--zca-epsilon positive\n",
                 who);
    return 2;
  }
  std::unique_ptr<ProgressBar> bar;
  if (!o.quiet) {
    bar = std::make_unique<ProgressBar>("place map", 100.0, "%");
    o.map.progress = [&](double f) { bar->update(100.0 * f); };
  }
  eval::PlaceMapReport r;
  try {
    r = eval::make_place_map(o.map);
  } catch (const std::exception& e) {
    r.error = e.what();
  }
  if (bar) bar->finish();
  if (!r.error.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, r.error.c_str());
    return 1;
  }
  const std::string e = perception::place::save_place_database(r.database, o.out);
  if (!e.empty()) {
    std::fprintf(stderr, "%s: %s\n", who, e.c_str());
    return 1;
  }
  const auto& db = r.database;
  std::printf("place database %s: %zu images of %zu frames (%zu without a pose, %zu closer than %.2f m), %.1f m of path\n",
              o.out.c_str(), db.entries.size(), r.frames, r.without_pose, r.too_close, o.map.every_m, r.path_m);
  std::printf("  descriptors: %d x %d frames, %d-pixel patches, %d values (%d bytes an image); poses from %s\n", db.width,
              db.height, db.hog.patch, db.length, db.length + 48, r.pose_source.c_str());
  if (db.whitening.rank > 0) {
    std::printf("  ZCA for the robot: the %d largest directions of the database against itself, epsilon %.2g (%zu bytes)\n",
                db.whitening.rank, static_cast<double>(db.whitening.epsilon_relative),
                4 * (db.whitening.directions.size() + db.whitening.mean.size() + db.whitening.gains.size()));
  } else {
    std::printf("  no ZCA (--zca-rank 0): the robot normalises with Eq. 5.3\n");
  }
  return 0;
}

}  // namespace

void add_place_commands(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "place-eval",
      "Camera place recognition across seasons (thesis chapter 5) on two image sequences: DATABASE (an earlier\n"
      "run) and QUERY (a later one), directories of PNG frames in name order. Whole-image HOG descriptors\n"
      "(32 x 32-pixel patches of 4 x 4 cells, 8 orientations), cosine similarities normalised per database image\n"
      "and per query (Eq. 5.3-5.4) or ZCA-whitened (Eq. 5.11-5.14), the discrete Bayes filter run forward and\n"
      "backward (f = 5, b = 3, c_f = 500, c_s = 100, c_b = 50) and the sequence filter (l_s, g_r = g_c = 5).\n"
      "Methods: raw (best cosine match), filter, filter+seq, zca+filter, zca+filter+seq, and seqslam (SeqSLAM as\n"
      "Milford and Wyeth published it, for comparison); and the robot's own: online (trailnavd's causal filter,\n"
      "queries one at a time, ZCA learnt from the database alone), online+lag (each answer given --online-lag\n"
      "queries later, smoothed over that window) and online+lag+seq (those that pass the online sequence test,\n"
      "chains of at least --online-min-sequence). With ground truth, each method's best F1 and its\n"
      "precision and recall; --png draws the precision-recall curves. docs/place.md.\n"
      "Ground truth: a CSV of `query,reference[,tolerance]` rows (1-based indices into the sequences as read,\n"
      "after --subsample; OpenSeqSLAM's convention), or `same-index` when frame i of both shows one place.\n"
      "Examples:\n"
      "  trailnav place-eval ../shared/data/nordland/summer ../shared/data/nordland/winter --ground-truth same-index\n"
      "      --hog-patch 16 --png nordland-pr.png\n"
      "  trailnav place-eval ../shared/data/nordland/summer ../shared/data/nordland/winter --subsample 10\n"
      "      --ground-truth ../shared/data/nordland/sample_ground_truth.csv --report json");
  static Options o;
  auto& e = o.eval;
  cmd->add_option("database", e.database, "Directory of the database's PNG frames")->required();
  cmd->add_option("query", e.query, "Directory of the queries' PNG frames")->required();
  cmd->add_option("--ground-truth", e.ground_truth, "CSV `query,reference[,tolerance]` (1-based), or same-index");
  cmd->add_option("--tolerance", e.tolerance,
                  "A match within this many images of the true place is correct (default: the CSV's, else 5: the "
                  "thesis' fewer than six)");
  cmd->add_option("--report", o.report, "json: one JSON object, a `methods` entry per method (method, best_f1, precision, recall)");
  cmd->add_option("--png", o.png, "Write the precision-recall curves to this PNG");
  cmd->add_option("--matches-out", o.matches_out, "CSV of each method's matches at its best F1 (method,query,database,score,correct)");
  cmd->add_option("--case", e.case_name,
                  "connected (as recorded), or scattered-1, scattered-2, scattered-3: the queries re-ordered in chunks "
                  "with jumps and revisits, a stretch of the database left out")
      ->capture_default_str();
  cmd->add_option("--subsample", e.subsample, "Every N-th image of each directory, from the first")->capture_default_str();
  cmd->add_option("--max-images", e.max_images, "At most N images of each sequence (0: all)")->capture_default_str();
  cmd->add_option("--hog-patch", e.hog.patch,
                  "HOG patch side (pixels); 0: 32, halved while the image holds fewer than 8 patches (64 x 32 frames: 16)")
      ->capture_default_str();
  cmd->add_option("--hog-cells", e.hog.cells, "HOG cells per patch side")->capture_default_str();
  cmd->add_option("--hog-bins", e.hog.bins, "HOG orientations over 180 degrees")->capture_default_str();
  cmd->add_flag("--float-descriptors", o.float_descriptors, "Keep descriptors as floats instead of bytes");
  cmd->add_option("--min-sequence", e.sequence.min_length, "l_s: matches kept in sequences at least this long")->capture_default_str();
  cmd->add_option("--row-gap", e.sequence.row_gap, "g_r: queries between a sequence's matches at most")->capture_default_str();
  cmd->add_option("--column-gap", e.sequence.column_gap, "g_c: database images between a sequence's matches at most")->capture_default_str();
  cmd->add_option("--peak-radius", e.peak_radius, "A match is the largest belief within this many database images")->capture_default_str();
  cmd->add_option("--zca-epsilon", e.zca_epsilon, "ZCA's epsilon as a fraction of the covariance's mean eigenvalue")->capture_default_str();
  cmd->add_flag("--zca-after-columns", e.zca_after_columns, "Eq. 5.3 before ZCA (by default ZCA replaces it)");
  cmd->add_flag("--zca-from-database", e.zca_from_database,
                "Learn ZCA's whitening from the database against itself instead of from the queries (what a robot "
                "has before it drives)");
  cmd->add_flag("--no-seqslam", o.no_seqslam, "Leave SeqSLAM out");
  cmd->add_flag("--no-online", o.no_online, "Leave the online methods out");
  cmd->add_option("--online-lag", e.online_lag, "Queries the online filter's smoothed answer trails the newest (trailnavd's place.lag)")
      ->capture_default_str();
  cmd->add_option("--online-zca-rank", e.online_zca_rank,
                  "The online filter's whitening, learnt from the database as place-map learns it: its largest "
                  "directions kept (0: Eq. 5.3 with running means instead)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1024));
  cmd->add_option("--online-min-sequence", e.online_sequence.min_length,
                  "The online sequence test's l_s: chains through the answer at least this long (trailnavd's "
                  "place.min_sequence; g_r and g_c as --row-gap and --column-gap)")
      ->capture_default_str();
  cmd->add_flag("--quiet", o.quiet, "No progress bars");
  cmd->callback([] { std::exit(run(o)); });

  auto* map = app.add_subcommand(
      "place-map",
      "A place database for trailnavd's place task from a recording's camera frames (an image stream) and the\n"
      "poses the robot had when it took them: a simulated recording's true trajectory (simulated truth), or\n"
      "--poses CSV `time,x,y,yaw[,lat,lon]` (seconds since the epoch, metres, radians, degrees) from whatever\n"
      "localised that drive. Frames are reduced to --width x --height (the camera's out_width x out_height) and\n"
      "described as place-eval describes them; one is kept every --every metres. docs/place.md.\n"
      "Example:\n"
      "  trailnav place-map build/sim/meadow --out meadow.tnplace --every 2");
  static MapOptions m;
  map->add_option("recording", m.map.recording, "A recording directory with an image stream")->required();
  map->add_option("--out", m.out, "The database file to write (.tnplace)")->required();
  map->add_option("--camera", m.map.camera, "The image stream's name (default: the recording's only one)");
  map->add_option("--poses", m.map.poses, "CSV of the drive's poses: time,x,y,yaw[,lat,lon] (default: the simulated truth)");
  map->add_option("--every", m.map.every_m, "Keep a frame every this many metres driven (0: every frame)")->capture_default_str();
  map->add_option("--width", m.map.width, "Frame width the descriptors are computed on")->capture_default_str();
  map->add_option("--height", m.map.height, "Frame height the descriptors are computed on")->capture_default_str();
  map->add_option("--hog-patch", m.map.hog.patch, "HOG patch side (0: auto, as place-eval)")->capture_default_str();
  map->add_option("--zca-rank", m.map.zca_rank,
                  "ZCA for the robot, learnt from the database against itself: directions kept (0: none)")
      ->capture_default_str();
  map->add_option("--zca-epsilon", m.map.zca_epsilon, "ZCA's epsilon as a fraction of the mean eigenvalue")->capture_default_str();
  map->add_flag("--quiet", m.quiet, "No progress bar");
  map->callback([] { std::exit(run_map(m)); });
}

}  // namespace trailnav::cli
