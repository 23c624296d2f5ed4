// `trailnav obstacles`: the obstacle pipeline offline, on a recording, a pcap
// or KITTI scans: map pictures, raw probabilities, scores against a
// simulated recording's truth and the KL comparison of the fusion models.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "commands.hpp"
#include "label_score.hpp"
#include "obstacle_run.hpp"
#include "trailnav/drivers/cloud/cloud_file.hpp"
#include "trailnav/perception/terrain_config.hpp"
#include "trailnav/runtime/config.hpp"
#include "terminal.hpp"

namespace trailnav::cli {
namespace {

namespace fs = std::filesystem;

struct ObstaclesCliOptions {
  eval::ObstacleRunOptions run;
  std::string config_file;
  std::string model;
  std::string terrain;
  std::string terrain_model;
  std::optional<perception::RandomForest> forest;
  std::string misses_file;
  std::string blocked_file;
  std::string points_file;
  std::vector<double> points_box;
  std::string rings;
  std::string labels_out;
  std::string labels_ply;
  std::string score_labels;
  bool quiet = false;
};

// A file a command option asked for (--misses, --blocked, --points: CSV;
// --labels-out, --labels-ply): opened with its header, checked and closed
// after its last line. Errors name the option and the file.
class OptionFile {
 public:
  OptionFile(const char* option, const std::string& path) : option_(option), path_(path) {}
  bool wanted() const noexcept { return !path_.empty(); }
  std::FILE* get() const noexcept { return file_.get(); }
  bool open(const char* header) {
    file_.reset(std::fopen(path_.c_str(), "w"));
    if (!file_) {
      std::fprintf(stderr, "trailnav obstacles: %s %s: cannot write: %s\n", option_, path_.c_str(), std::strerror(errno));
      return false;
    }
    std::fputs(header, file_.get());
    return true;
  }
  // True when everything was written (or nothing was asked for).
  bool close() {
    if (!file_) return true;
    const bool written = std::ferror(file_.get()) == 0;
    if (std::fclose(file_.release()) != 0 || !written) {
      std::fprintf(stderr, "trailnav obstacles: %s %s: writing failed\n", option_, path_.c_str());
      return false;
    }
    return true;
  }

 private:
  const char* option_;
  std::string path_;
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> file_{nullptr, &std::fclose};
};

// --labels-out: one line per input point, in input order: the answer (1, 0,
// -1), the code (eval::AnswerCode) and P(obstacle) ("nan" when not evaluated).
bool write_labels_text(const std::string& path, const eval::ScanAnswers& a) {
  OptionFile f("--labels-out", path);
  if (!f.open("")) return false;
  for (const eval::ScanPointAnswer& p : a.answers) {
    if (std::isnan(p.probability)) {
      std::fprintf(f.get(), "%d %d nan\n", p.obstacle, static_cast<int>(p.code));
    } else {
      std::fprintf(f.get(), "%d %d %.4f\n", p.obstacle, static_cast<int>(p.code), static_cast<double>(p.probability));
    }
  }
  return f.close();
}

// --labels-ply: the points with their answers as fields (binary little-endian PLY).
bool write_labels_ply(const std::string& path, const eval::ScanAnswers& a) {
  OptionFile f("--labels-ply", path);
  char header[768];
  std::snprintf(header, sizeof header,
                "ply\nformat binary_little_endian 1.0\ncomment trailnav obstacles: per-point answers for %s\n"
                "comment obstacle: 1, 0, or -1 not evaluated (code says why: docs/obstacles.md)\n"
                "element vertex %zu\nproperty float x\nproperty float y\nproperty float z\nproperty float intensity\n"
                "property char obstacle\nproperty uchar code\nproperty float p_obstacle\nproperty float step_height\n"
                "property float incline_deg\nproperty float height_above_ground\nend_header\n",
                a.file.substr(0, 256).c_str(), a.answers.size());
  if (!f.open(header)) return false;
  std::vector<unsigned char> record(4 * 4 + 2 + 4 * 4);
  auto put = [&](std::size_t at, float v) {
    std::uint32_t u;
    std::memcpy(&u, &v, 4);
    for (int b = 0; b < 4; ++b) record[at + static_cast<std::size_t>(b)] = static_cast<unsigned char>(u >> (8 * b));
  };
  for (std::size_t i = 0; i < a.answers.size(); ++i) {
    put(0, a.cloud.x[i]);
    put(4, a.cloud.y[i]);
    put(8, a.cloud.z[i]);
    put(12, a.cloud.intensity[i]);
    record[16] = static_cast<unsigned char>(a.answers[i].obstacle);
    record[17] = static_cast<unsigned char>(a.answers[i].code);
    put(18, a.answers[i].probability);
    put(22, a.answers[i].step_height);
    put(26, static_cast<float>(std::asin(std::clamp(static_cast<double>(a.answers[i].sin_incline), 0.0, 1.0)) * 180.0 / M_PI));
    put(30, a.answers[i].height);
    std::fwrite(record.data(), 1, record.size(), f.get());
  }
  return f.close();
}

// A recall as text: "n/a" when no truth cell was observed (no obstacle of
// that kind in range, or a recording without that truth), never a 1.0 that
// nothing supports.
std::string recall_text(const eval::FoundCells& f) {
  if (f.cells == 0) return "n/a";
  char text[16];
  std::snprintf(text, sizeof text, "%.4f", f.recall());
  return text;
}

void print_score(const char* model, const eval::MapScore& s) {
  const auto all = s.all_free();
  std::printf("  %s: obstacle faces seen %llu/%llu cells found (recall %s); faces hit at all, grazing or over grass "
              "%s (%llu); outlines seen anywhere %s (%llu), whole footprints %s (%llu); ditches %s (%llu); bushes %s (%llu)\n",
              model, static_cast<unsigned long long>(s.faces.found), static_cast<unsigned long long>(s.faces.cells),
              recall_text(s.faces).c_str(), recall_text(s.faces_hit).c_str(),
              static_cast<unsigned long long>(s.faces_hit.cells), recall_text(s.outlines).c_str(),
              static_cast<unsigned long long>(s.outlines.cells), recall_text(s.obstacles).c_str(),
              static_cast<unsigned long long>(s.obstacles.cells), recall_text(s.negative).c_str(),
              static_cast<unsigned long long>(s.negative.cells), recall_text(s.vegetation).c_str(),
              static_cast<unsigned long long>(s.vegetation.cells));
  if (s.faces.cells > s.faces.found) {
    const std::uint64_t missed = s.faces.cells - s.faces.found;
    std::printf("      faces missed %llu: %llu lost after an earlier snapshot found them, %llu never found (--misses lists "
                "them)\n",
                static_cast<unsigned long long>(missed), static_cast<unsigned long long>(s.faces_lost),
                static_cast<unsigned long long>(missed - s.faces_lost));
  }
  std::printf("      fake obstacles: all %.4f (%llu/%llu)", all.rate(), static_cast<unsigned long long>(all.fake),
              static_cast<unsigned long long>(all.free));
  for (int t = 0; t < perception::kTerrainClasses; ++t) {
    const auto& c = s.classes[static_cast<std::size_t>(t)];
    if (c.free == 0) continue;
    std::printf("; %s %.4f", std::string(perception::terrain_class_name(static_cast<perception::TerrainClass>(t))).c_str(),
                c.rate());
  }
  std::printf("\n      path blocked by fake obstacles in %llu of %llu snapshots (%.1f %%)%s\n",
              static_cast<unsigned long long>(s.blocked), static_cast<unsigned long long>(s.snapshots),
              s.snapshots ? 100.0 * static_cast<double>(s.blocked) / static_cast<double>(s.snapshots) : 0.0,
              s.blocked ? " (--blocked lists them)" : "");
  for (const auto& n : s.named) {
    if (n.snapshots == 0) continue;
    std::printf("      %-28s detected in %llu of %llu snapshots within range; faces %llu/%llu cells (%s)\n",
                n.name.c_str(), static_cast<unsigned long long>(n.detected), static_cast<unsigned long long>(n.snapshots),
                static_cast<unsigned long long>(n.faces.found), static_cast<unsigned long long>(n.faces.cells),
                recall_text(n.faces).c_str());
  }
}

int run(ObstaclesCliOptions& o) {
  if (!o.config_file.empty()) {
    auto loaded = perception::load_obstacle_config(o.config_file);
    if (!loaded.config) {
      std::fprintf(stderr, "trailnav obstacles: %s\n", loaded.error.c_str());
      return 2;
    }
    o.run.config = *loaded.config;
  }
  if (!o.model.empty()) {
    const auto m = perception::parse_fusion_model(o.model);
    if (!m) {
      std::fprintf(stderr, "trailnav obstacles: --model %s: allowed are PW, PS and PC\n", o.model.c_str());
      return 2;
    }
    o.run.config.model = *m;
  }
  if (!o.terrain.empty()) {
    if (o.terrain == "truth") {
      o.run.terrain = eval::TerrainMode::truth;
      o.run.config.fixed_class.reset();
    } else if (o.terrain == "estimated") {
      o.run.terrain = eval::TerrainMode::estimated;
      o.run.config.fixed_class.reset();
      bool terrain_section = false;
      if (!o.config_file.empty()) {
        try {
          const ConfigNode root = ConfigNode::load_file(o.config_file);
          if (auto t = root.optional_map("terrain")) {
            o.run.terrain_config = perception::parse_terrain_config(*t);
            terrain_section = true;
          }
        } catch (const ConfigError& e) {
          std::fprintf(stderr, "trailnav obstacles: %s\n", e.what());
          return 2;
        }
      }
      if (!o.terrain_model.empty()) o.run.terrain_config.model = o.terrain_model;
      if (o.run.terrain_config.model.empty()) {
        std::fprintf(stderr, "trailnav obstacles: --terrain estimated needs --terrain-model FILE (trailnav terrain-train)\n");
        return 2;
      }
      auto loaded = perception::RandomForest::load(o.run.terrain_config.model);
      if (!loaded.forest) {
        std::fprintf(stderr, "trailnav obstacles: %s\n", loaded.error.c_str());
        return 2;
      }
      o.forest = std::move(loaded.forest);
      // No terrain section: the cells the model learnt from.
      if (!terrain_section) perception::adopt_forest_settings(*o.forest, o.run.terrain_config);
      o.run.terrain_forest = &*o.forest;
      o.run.terrain_forest_name = o.run.terrain_config.model;
    } else if (o.terrain == "adaptive") {
      o.run.config.fixed_class.reset();
    } else if (const auto c = perception::parse_terrain_class(o.terrain)) {
      o.run.config.fixed_class = *c;
    } else {
      std::fprintf(stderr,
                   "trailnav obstacles: --terrain %s: allowed are truth, estimated, adaptive, street, dirt, grass, "
                   "vegetation, other\n",
                   o.terrain.c_str());
      return 2;
    }
  }
  // --misses: every face cell a map missed, one CSV line per scored snapshot.
  OptionFile misses("--misses", o.misses_file);
  std::uint64_t miss_lines = 0;
  if (misses.wanted()) {
    if (!misses.open("model,time_s,robot_x,robot_y,x,y,distance_m,side_seen_s,obstacle,probability,found_before\n")) return 2;
    o.run.on_face_miss = [&](const eval::FaceMiss& m) {
      // Names such as "trunk at (12.0, 3.5)" hold commas: quoted, quotes doubled.
      std::string name = "\"";
      for (const char ch : m.obstacle) name += ch == '"' ? std::string("\"\"") : std::string(1, ch);
      name += '"';
      std::fprintf(misses.get(), "%s,%.1f,%.2f,%.2f,%.2f,%.2f,%.2f,%.1f,%s,%.3f,%d\n",
                   std::string(perception::fusion_model_name(m.model)).c_str(), m.time_s, m.robot_x, m.robot_y, m.x, m.y,
                   m.distance, m.side_seen_s, name.c_str(), static_cast<double>(m.probability), m.found_before ? 1 : 0);
      ++miss_lines;
    };
  }
  // --blocked: every scored snapshot whose path a map blocks, with the first
  // fake obstacle cell on the path.
  OptionFile blocked("--blocked", o.blocked_file);
  std::uint64_t blocked_lines = 0;
  if (blocked.wanted()) {
    if (!blocked.open("model,time_s,robot_x,robot_y,x,y,ahead_m,true_class,probability\n")) return 2;
    o.run.on_blocked = [&](const eval::BlockedPath& b) {
      const bool known = static_cast<int>(b.truth_class) < perception::kTerrainClasses;
      std::fprintf(blocked.get(), "%s,%.1f,%.2f,%.2f,%.2f,%.2f,%.2f,%s,%.3f\n",
                   std::string(perception::fusion_model_name(b.model)).c_str(), b.time_s, b.robot_x, b.robot_y, b.x,
                   b.y, b.ahead, known ? std::string(perception::terrain_class_name(b.truth_class)).c_str() : "none",
                   static_cast<double>(b.probability));
      ++blocked_lines;
    };
  }
  // --points: every point inside --points-box, per revolution.
  OptionFile points("--points", o.points_file);
  std::uint64_t point_lines = 0;
  if (o.points_file.empty() != o.points_box.empty()) {
    std::fprintf(stderr, "trailnav obstacles: --points and --points-box go together\n");
    return 2;
  }
  if (points.wanted()) {
    const auto& b = o.points_box;
    if (!(b[0] < b[1]) || !(b[2] < b[3])) {
      std::fprintf(stderr, "trailnav obstacles: --points-box %g,%g,%g,%g: give XMIN,XMAX,YMIN,YMAX with XMIN < XMAX and "
                           "YMIN < YMAX\n", b[0], b[1], b[2], b[3]);
      return 2;
    }
    if (!points.open("time_s,revolution,ring,column,x,y,z,range,state,step_height,incline_deg,terrain,terrain_known,dirac,"
                     "smooth\n"))
      return 2;
    o.run.points_box = std::array<double, 4>{b[0], b[1], b[2], b[3]};
    o.run.on_point = [&](const eval::PointRecord& p) {
      const char* state = p.state == perception::PointState::measured ? "measured"
                          : p.state == perception::PointState::flat   ? "flat"
                          : p.state == perception::PointState::isolated ? "isolated"
                                                                          : "valid";
      const double incline = std::asin(std::clamp(static_cast<double>(p.sin_incline), 0.0, 1.0)) * 180.0 / M_PI;
      std::fprintf(points.get(), "%.3f,%llu,%d,%d,%.3f,%.3f,%.3f,%.3f,%s,%.4f,%.2f,%s,%d,%d,%.4f\n", p.time_s,
                   static_cast<unsigned long long>(p.revolution), p.ring, p.column, p.x, p.y, p.z,
                   static_cast<double>(p.range), state, static_cast<double>(p.step_height), incline,
                   std::string(perception::terrain_class_name(p.terrain)).c_str(), p.terrain_known ? 1 : 0,
                   p.dirac ? 1 : 0, static_cast<double>(p.smooth));
      ++point_lines;
    };
  }
  if (!o.rings.empty()) {
    o.run.cloud.rings = cloud::ring_source_named(o.rings);
    if (!o.run.cloud.rings) {
      std::fprintf(stderr, "trailnav obstacles: --rings %s: allowed are automatic, field, elevation and order\n",
                   o.rings.c_str());
      return 2;
    }
  }
  // Per-point answers of point-cloud files: for one file, the files given;
  // for several, directories holding one file per scan (its name's stem).
  const bool per_point = !o.labels_out.empty() || !o.labels_ply.empty() || !o.score_labels.empty();
  const bool several = o.run.inputs.size() > 1;
  std::vector<std::uint32_t> truth_labels;
  std::vector<std::int8_t> answered;
  bool answers_written = true;
  std::string answers_error;
  std::uint64_t answer_codes[eval::kAnswerCodes] = {};
  std::optional<eval::LabelScore> total_score;
  std::vector<std::string> scan_scores;
  auto path_for = [&](const std::string& given, const std::string& scan, const char* ext) {
    return several ? (fs::path(given) / (fs::path(scan).stem().string() + ext)).string() : given;
  };
  if (per_point) {
    for (const std::string& in : o.run.inputs) {
      if (!cloud::cloud_format_of(in) || fs::is_directory(in)) {
        std::fprintf(stderr, "trailnav obstacles: --labels-out, --labels-ply and --score-labels take point-cloud files "
                             "(.bin, .pcd or .ply); %s is not one\n", in.c_str());
        return 2;
      }
    }
    if (several) {
      // Several scans: the outputs go to directories, the labels come from one.
      for (const std::string* d : {&o.labels_out, &o.labels_ply}) {
        std::error_code ec;
        if (!d->empty() && !fs::is_directory(*d) && !fs::create_directories(*d, ec)) {
          std::fprintf(stderr, "trailnav obstacles: %s: with several scans give a directory (cannot create it: %s)\n",
                       d->c_str(), ec.message().c_str());
          return 2;
        }
      }
      if (!o.score_labels.empty() && !fs::is_directory(o.score_labels)) {
        std::fprintf(stderr, "trailnav obstacles: --score-labels %s: with several scans give the directory of their "
                             ".label files (SCAN.bin is scored against DIR/SCAN.label)\n", o.score_labels.c_str());
        return 2;
      }
    } else if (!o.score_labels.empty()) {
      if (Status st = eval::load_semantickitti_labels(o.score_labels, truth_labels); !st) {
        std::fprintf(stderr, "trailnav obstacles: --score-labels %s\n", st.message().c_str());
        return 2;
      }
    }
    o.run.on_scan_answers = [&](const eval::ScanAnswers& a) {
      answered.resize(a.answers.size());
      for (std::size_t i = 0; i < a.answers.size(); ++i) {
        answered[i] = a.answers[i].obstacle;
        ++answer_codes[static_cast<int>(a.answers[i].code)];
      }
      if (!o.labels_out.empty()) answers_written = write_labels_text(path_for(o.labels_out, a.file, ".answers"), a) && answers_written;
      if (!o.labels_ply.empty()) answers_written = write_labels_ply(path_for(o.labels_ply, a.file, ".ply"), a) && answers_written;
      if (o.score_labels.empty() || !answers_error.empty()) return;
      const std::string labels_file = path_for(o.score_labels, a.file, ".label");
      if (several) {
        if (Status st = eval::load_semantickitti_labels(labels_file, truth_labels); !st) {
          answers_error = "--score-labels " + st.message();
          return;
        }
      }
      if (truth_labels.size() != answered.size()) {
        answers_error = "--score-labels " + labels_file + ": " + std::to_string(truth_labels.size()) + " labels for " +
                        std::to_string(answered.size()) + " points of " + a.file;
        return;
      }
      const eval::LabelScore one = eval::score_labels(answered, truth_labels);
      char line[256];
      std::snprintf(line, sizeof line, "  %s: precision %.3f, recall %.3f, F1 %.3f", a.file.c_str(), one.precision(),
                    one.recall(), one.f1());
      scan_scores.emplace_back(line);
      if (!total_score) total_score = one;
      else eval::merge_label_scores(*total_score, one);
    };
  }
  ProgressBar progress("obstacles", 100.0, "%");
  if (!o.quiet) o.run.progress = [&](double f) { progress.update(100.0 * f); };
  const eval::ObstacleRunReport r = eval::run_obstacles(o.run);
  if (!o.quiet) progress.finish();
  if (!r.error.empty()) {
    std::fprintf(stderr, "trailnav obstacles: %s\n", r.error.c_str());
    return 2;
  }
  if (!points.close() || !misses.close() || !blocked.close() || !answers_written) return 2;
  if (!answers_error.empty()) {
    std::fprintf(stderr, "trailnav obstacles: %s\n", answers_error.c_str());
    return 2;
  }
  if (blocked.wanted() && !r.scored) {
    std::fprintf(stderr, "trailnav obstacles: --blocked needs a simulated recording (its truth says where the path and "
                         "the obstacles are); %s is empty\n", o.blocked_file.c_str());
  }
  if (misses.wanted() && !r.scored) {
    std::fprintf(stderr, "trailnav obstacles: --misses needs a simulated recording (its truth says where the faces are); "
                         "%s is empty\n", o.misses_file.c_str());
  }
  const auto& c = r.counters;
  const char* terrain = o.run.terrain == eval::TerrainMode::truth       ? "true classes (adaptive)"
                        : o.run.terrain == eval::TerrainMode::estimated ? "estimated classes (adaptive, terrain analysis)"
                        : o.run.config.fixed_class
                            ? perception::terrain_class_name(*o.run.config.fixed_class).data()
                            : "adaptive (no terrain map: unknown class)";
  std::printf("trailnav obstacles: %s, %s; %llu revolutions; terrain: %s; model %s\n", r.input_kind.c_str(),
              r.model_name.c_str(), static_cast<unsigned long long>(r.revolutions), terrain,
              std::string(perception::fusion_model_name(o.run.config.model)).c_str());
  std::printf("  points %llu (out of range %llu, the robot itself %llu); features: measured %llu, flat %llu, isolated %llu; "
              "outside map %llu; malformed packets %llu\n",
              static_cast<unsigned long long>(c.align.points), static_cast<unsigned long long>(c.align.out_of_range),
              static_cast<unsigned long long>(c.align.self_hits),
              static_cast<unsigned long long>(c.features.measured), static_cast<unsigned long long>(c.features.flat),
              static_cast<unsigned long long>(c.features.isolated), static_cast<unsigned long long>(c.map.outside_map),
              static_cast<unsigned long long>(r.malformed_packets));
  if (r.source_self_box) {
    const auto& b = *r.source_self_box;
    std::printf("  returns from the recording vehicle itself dropped (%s input: features.self_box [%.2f, %.2f, %.2f, %.2f, %.2f, "
                "%.2f] in the sensor frame; give your own in --config)\n",
                r.input_kind.c_str(), static_cast<double>(b[0]), static_cast<double>(b[1]), static_cast<double>(b[2]),
                static_cast<double>(b[3]), static_cast<double>(b[4]), static_cast<double>(b[5]));
  }
  if (r.input_kind == "kitti" || r.input_kind == "cloud") {
    const auto& p = r.cloud_points;
    std::printf("  file points %llu: %llu placed, %llu second in their cell (layer 1), %llu more counted, %llu without a "
                "return, %llu without a ring of the layout\n",
                static_cast<unsigned long long>(p.points), static_cast<unsigned long long>(p.placed),
                static_cast<unsigned long long>(p.second), static_cast<unsigned long long>(p.collisions),
                static_cast<unsigned long long>(p.invalid), static_cast<unsigned long long>(p.bad_ring));
  }
  if (per_point) {
    std::printf("  per-point answers by code:");
    const char* sep = " ";
    for (int k = 0; k < eval::kAnswerCodes; ++k) {
      if (answer_codes[k] == 0) continue;
      std::printf("%s%d (%s) %llu", sep, k, std::string(eval::answer_code_name(static_cast<eval::AnswerCode>(k))).c_str(),
                  static_cast<unsigned long long>(answer_codes[k]));
      sep = "; ";
    }
    std::printf("\n");
  }
  std::printf("  time per revolution: align %.3f ms, smoothing + features %.3f ms, map update%s %.3f ms\n", r.align_ms,
              r.features_ms, r.kl ? " (PW + PS + PC)" : "", r.map_ms);
  if (o.run.terrain == eval::TerrainMode::estimated) {
    std::printf("  terrain analysis: %llu steps, %.3f ms per revolution\n", static_cast<unsigned long long>(r.terrain_steps),
                r.terrain_ms);
  }
  if (r.scored) {
    std::printf("  scores against truth within %.0f m (tolerance %d cell):\n", o.run.score_radius, o.run.tolerance_cells);
    if (!r.side_sightings)
      std::printf("  (the recording has no truth/side_hits.u32: it was simulated before the simulator said which side\n"
                  "  returns show their face, so no face counts as seen; simulate it again with this trailnav sim to\n"
                  "  score the faces)\n");
    for (int m = 0; m < perception::kFusionModels; ++m) {
      const auto& s = r.scores[static_cast<std::size_t>(m)];
      if (s) print_score(perception::fusion_model_name(static_cast<perception::FusionModel>(m)).data(), *s);
    }
  }
  if (r.kl) {
    std::printf("  KL divergence to PC over observed cells (%llu snapshots): PW mean %.4f max %.4f bits; PS mean %.4f max %.4f bits\n",
                static_cast<unsigned long long>(r.kl->snapshots), r.kl->mean_pw, r.kl->max_pw, r.kl->mean_ps, r.kl->max_ps);
  }
  for (const std::string& f : r.files) {
    if (f.find("-0") == std::string::npos) std::printf("  wrote %s\n", f.c_str());
  }
  if (!o.labels_out.empty()) {
    std::printf("  wrote %s%s (one line per point: answer, code, P(obstacle))\n", o.labels_out.c_str(),
                several ? "/SCAN.answers" : "");
  }
  if (!o.labels_ply.empty()) std::printf("  wrote %s%s\n", o.labels_ply.c_str(), several ? "/SCAN.ply" : "");
  if (total_score) {
    std::printf("\nagainst %s (SemanticKITTI labels; docs/obstacles.md \"On real labelled lidar\")%s:\n",
                o.score_labels.c_str(), several ? ", every scan's points together" : "");
    if (several) {
      for (const std::string& line : scan_scores) std::printf("%s\n", line.c_str());
    }
    std::printf("\n%s", eval::label_score_table(*total_score, "class").c_str());
  }
  if (!o.points_file.empty()) {
    std::printf("  wrote %s (%llu points in the box, over all revolutions)\n", o.points_file.c_str(),
                static_cast<unsigned long long>(point_lines));
  }
  if (!o.blocked_file.empty() && r.scored) {
    std::printf("  wrote %s (%llu blocked snapshots, over all maps)\n", o.blocked_file.c_str(),
                static_cast<unsigned long long>(blocked_lines));
  }
  if (!o.misses_file.empty() && r.scored) {
    std::printf("  wrote %s (%llu face cells missed, over all scored snapshots and maps)\n", o.misses_file.c_str(),
                static_cast<unsigned long long>(miss_lines));
  }
  return 0;
}

}  // namespace

// `trailnav score-labels ANSWERS LABELS`: any tool's per-point answers (one
// line per point, the first field 1 for an obstacle, 0 or -1 for not), scored
// against SemanticKITTI labels as --score-labels scores trailnav's.
int score_labels_file(const std::string& answers_file, const std::string& labels_file, const std::string& title) {
  std::ifstream in(answers_file);
  if (!in) {
    std::fprintf(stderr, "trailnav score-labels: %s: cannot open: %s\n", answers_file.c_str(), std::strerror(errno));
    return 2;
  }
  std::vector<std::int8_t> answers;
  std::string line;
  std::size_t number = 0;
  while (std::getline(in, line)) {
    ++number;
    const char* p = line.c_str();
    char* end = nullptr;
    errno = 0;
    const long v = std::strtol(p, &end, 10);
    if (end == p || errno != 0 || (v != 1 && v != 0 && v != -1) || (*end != '\0' && *end != ' ' && *end != '\t' && *end != '\r')) {
      std::fprintf(stderr, "trailnav score-labels: %s:%zu: '%s': each line must begin with 1, 0 or -1\n",
                   answers_file.c_str(), number, line.substr(0, 40).c_str());
      return 2;
    }
    answers.push_back(static_cast<std::int8_t>(v));
  }
  std::vector<std::uint32_t> labels;
  if (Status st = eval::load_semantickitti_labels(labels_file, labels); !st) {
    std::fprintf(stderr, "trailnav score-labels: %s\n", st.message().c_str());
    return 2;
  }
  if (labels.size() != answers.size()) {
    std::fprintf(stderr, "trailnav score-labels: %zu answers in %s, %zu labels in %s: one of each per point\n",
                 answers.size(), answers_file.c_str(), labels.size(), labels_file.c_str());
    return 2;
  }
  std::printf("%s", eval::label_score_table(eval::score_labels(answers, labels), title).c_str());
  return 0;
}

void add_score_labels_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "score-labels",
      "Score per-point obstacle answers against SemanticKITTI labels (the protocol of docs/obstacles.md \"On real\n"
      "labelled lidar\": ground = road, parking, sidewalk, other-ground, terrain; obstacles = building, fence,\n"
      "car, truck, other-vehicle, person, bicyclist, pole, traffic-sign, trunk; vegetation shown apart; an answer\n"
      "other than 1 counts as not an obstacle). ANSWERS has one line per point in the scan's order, its first\n"
      "field 1, 0 or -1 (`trailnav obstacles SCAN --labels-out`, or any other tool's). Prints a table per class\n"
      "and precision, recall and F1.\n"
      "Example:\n"
      "  trailnav score-labels scan.answers ../shared/data/semantickitti/000000.label");
  static std::string answers, labels, title = "class";
  cmd->add_option("answers", answers, "Per-point answers, one line per point")->required();
  cmd->add_option("labels", labels, "The scan's SemanticKITTI .label file")->required();
  cmd->add_option("--title", title, "The table's first column header (the tool's name)");
  cmd->callback([&] { std::exit(score_labels_file(answers, labels, title)); });
}

void add_obstacles_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "obstacles",
      "Run the obstacle detection (thesis §7.1, §7.3) offline and deterministically on a recording\n"
      "directory, a pcap file or point-cloud files (KITTI .bin, PCD, PLY). Writes the obstacle maps as\n"
      "PNG (and the last one's probabilities as float32) to --out; for point-cloud files also every point's\n"
      "answer (--labels-out, --labels-ply), scored against SemanticKITTI labels with --score-labels.\n"
      "On a simulated recording (`trailnav sim`) it follows the true trajectory, keeps PW, PS and PC maps\n"
      "side by side, scores them against the truth (obstacle recall, fake obstacles per terrain class, path\n"
      "blocked) and prints their KL divergence (§7.4.4).\n"
      "Examples:\n"
      "  trailnav obstacles build/sim/meadow --terrain truth --out build/obstacles\n"
      "  trailnav obstacles build/sim/meadow --terrain street     # the basic approach with street parameters\n"
      "  trailnav obstacles build/sim/meadow --terrain estimated --terrain-model board/models/terrain-sim.tnrf\n"
      "  trailnav obstacles ../shared/data/kitti/*.bin --out build/kitti\n"
      "  trailnav obstacles scan.bin --config board/robots/kitti-car.yaml --labels-out scan.answers \\\n"
      "      --score-labels scan.label           # every point answered and scored (docs/obstacles.md)\n"
      "  trailnav obstacles scan.pcd --lidar VLP-16 --labels-ply scan-answers.ply");
  static ObstaclesCliOptions o;
  cmd->add_option("inputs", o.run.inputs,
                  "A recording directory, a pcap file, or point-cloud files (KITTI .bin, PCD, PLY; one revolution each)")
      ->required();
  cmd->add_option("--config", o.config_file, "YAML file with an `obstacles:` section (docs/obstacles.md)");
  cmd->add_option("--model", o.model, "Fusion model of the main map: PW (Dirac, most likely class; default), PS (smooth, "
                                      "most likely class) or PC (smooth, full class distribution)");
  cmd->add_option("--terrain", o.terrain,
                  "Terrain classes: truth (a simulated recording's true classes), estimated (the terrain analysis "
                  "with --terrain-model), adaptive (no terrain map: unknown class), or one class for every cell: "
                  "street, dirt, grass, vegetation, other");
  cmd->add_option("--terrain-model", o.terrain_model,
                  "Terrain model for --terrain estimated (trailnav terrain-train; e.g. board/models/terrain-sim.tnrf)");
  cmd->add_option("--out", o.run.out_dir, "Directory for the map pictures and raw probabilities");
  cmd->add_option("--png-every", o.run.png_every, "Also write the maps every N revolutions (0: only the last)")
      ->capture_default_str();
  cmd->add_option("--score-every", o.run.score_every, "Score (and compare) the maps every N revolutions")
      ->capture_default_str();
  cmd->add_option("--radius", o.run.score_radius, "Score cells within this many metres of the robot")->capture_default_str();
  cmd->add_option("--misses", o.misses_file,
                  "Write every obstacle face cell a map missed to this CSV, per scored snapshot: when, where, how far, "
                  "when a return first showed its side, the map's P(o) there and whether it had been found before (simulated "
                  "recordings)");
  cmd->add_option("--blocked", o.blocked_file,
                  "Write every scored snapshot whose map blocks the robot's path to this CSV: when, where the robot "
                  "was, the first fake obstacle cell within 0.3 m of its next 4 m of true path, how far along the path, "
                  "the cell's true terrain class and the map's P(o) there (simulated recordings)");
  cmd->add_option("--points", o.points_file,
                  "Write every point inside --points-box to this CSV, per revolution: ring, column, position, range, "
                  "its features (stepHeight, incline; or flat, isolated), the terrain class it was fused with, and "
                  "the Dirac (Eq. 7.11) and smooth (Eq. 7.12) models' answers; to see why a cell is or is not an obstacle");
  cmd->add_option("--points-box", o.points_box, "XMIN,XMAX,YMIN,YMAX in the odometry frame (a simulated recording: the "
                                                "world frame of its truth), m")
      ->expected(4)
      ->delimiter(',');
  cmd->add_option("--revolutions", o.run.max_revolutions, "Stop after N revolutions (0: all)")->capture_default_str();
  cmd->add_option("--calibration", o.run.calibration, "Lidar calibration file (default: the recording's or the model's)");
  cmd->add_option("--lidar", o.run.cloud.lidar,
                  "Point-cloud files: the lidar whose ring layout they follow: a preset (VLP-16, VLP-32C, HDL-32E, "
                  "HDL-64E, Pandar40P, Pandar64, OS0-32 ... OS2-128) or a layout file (YAML: lidar_layout: {name, "
                  "columns, elevations_deg}); default for KITTI .bin: HDL-64E; or give a Velodyne --calibration file");
  cmd->add_option("--rings", o.rings,
                  "Point-cloud files: where a point's ring comes from: automatic (the file's ring field, else the "
                  "elevation; PCD and PLY default), field, elevation, or order (the sensor's firing order kept in the "
                  "file; KITTI .bin default)");
  cmd->add_option("--columns", o.run.cloud.columns, "Point-cloud files: azimuth columns of a revolution (0: the lidar's)");
  cmd->add_option("--labels-out", o.labels_out,
                  "Point-cloud files: write (to this file; with several scans, to DIR/SCAN.answers) one line per input point, in input order: the obstacle answer (1, 0, or "
                  "-1 not evaluated), a code (0 evaluated, 1 its range-image cell's answer, 2 no return, 3 not placed, "
                  "4 apart in its cell, 5 out of range, 6 the vehicle, 7 dropped in alignment, 8 isolated, 9 by its height "
                  "above the ground alone: a second point apart in its cell or a third, obstacles.ground on) and "
                  "P(obstacle) of the smooth model (nan when not evaluated)");
  cmd->add_option("--labels-ply", o.labels_ply,
                  "Point-cloud files: write (to this file; with several scans, DIR/SCAN.ply) the points as PLY with the answers as fields (obstacle, code, p_obstacle, "
                  "step_height, incline_deg, height_above_ground: NaN unless obstacles.ground is on)");
  cmd->add_option("--score-labels", o.score_labels,
                  "Point-cloud files: score the answers against the SemanticKITTI .label file (with several scans: the directory "
                  "holding SCAN.label for each; their points scored together, each scan's F1 printed too) (ground: road, "
                  "parking, sidewalk, other-ground, terrain; obstacles: building, fence, vehicles, people, pole, "
                  "traffic-sign, trunk; vegetation apart) and print precision, recall, F1 and a table per class");
  cmd->add_flag("--quiet", o.quiet, "No progress bar");
  cmd->callback([&] { std::exit(run(o)); });
}

}  // namespace trailnav::cli
