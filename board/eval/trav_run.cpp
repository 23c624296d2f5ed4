#include "trav_run.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <unordered_map>

#include "figure.hpp"
#include "revolution_source.hpp"
#include "trailnav/perception/terrain_mapper.hpp"
#include "trailnav/runtime/config.hpp"
#include "world.hpp"

namespace trailnav::eval {
namespace trav = perception::trav;
namespace {

using SteadyClock = std::chrono::steady_clock;
double ms_since(SteadyClock::time_point t0) {
  return std::chrono::duration<double, std::milli>(SteadyClock::now() - t0).count();
}

// The terrain step's sums to one recorder per feature set.
class FanOut final : public perception::CellSumsSink {
 public:
  std::vector<trav::TravRecorder*> recorders;
  void cell_sums(CellIndex cell, const perception::CellStats& sums, const perception::FeatureVector* feature, double x,
                 double y) noexcept override {
    for (trav::TravRecorder* r : recorders) r->cell_sums(cell, sums, feature, x, y);
  }
};

// One pass over each recording: the mapper's steps feed a recorder per
// feature set; `on_local_map(set index, recorder)` when one ends.
std::string drive_recordings(const TravRunOptions& o, const std::vector<trav::VocabularyConfig>& vocabularies,
                             std::uint64_t& revolutions, double* step_ms,
                             const std::function<void(const SimTruth&)>& on_input,
                             const std::function<void(std::size_t, trav::TravRecorder&)>& on_local_map) {
  for (std::size_t n = 0; n < o.inputs.size(); ++n) {
    const std::string& input = o.inputs[n];
    auto opened = RevolutionSource::open({input}, o.calibration);
    if (!opened.source) return opened.error;
    RevolutionSource& source = *opened.source;
    if (!source.truth()) {
      return input + ": not a simulated recording (no truth/ directory): its poses and truth are needed";
    }
    const SimTruth& truth = *source.truth();
    if (on_input) on_input(truth);
    perception::MountParams mount;
    mount.translation = source.mount_translation();
    auto made = perception::TerrainMapper::create(o.terrain, mount, source.shape(), nullptr);
    if (!made.mapper) return input + ": " + made.error;
    perception::TerrainMapper& mapper = *made.mapper;
    std::vector<std::unique_ptr<trav::TravRecorder>> recorders;
    FanOut fan;
    trav::RecorderConfig rc = o.recorder;
    rc.footprint = o.profile.footprint;
    for (const trav::VocabularyConfig& v : vocabularies) {
      recorders.push_back(std::make_unique<trav::TravRecorder>(rc, trav::Vocabulary(v), o.terrain.map.size_x,
                                                               o.terrain.map.size_y, o.terrain.map.resolution));
      fan.recorders.push_back(recorders.back().get());
    }
    mapper.set_sums_sink(&fan);
    perception::PoseTrack poses(truth.trajectory.size() + 1);
    fill_pose_track(truth, poses);
    // The footprint follows every true pose (100 Hz), not only each revolution's.
    std::size_t next_pose = 0;
    double step_total = 0.0;
    std::uint64_t steps = 0;
    const std::string error = source.run(
        [&](const velodyne::RangeImage& image) {
          ++revolutions;
          mapper.align(image, &poses);
          mapper.register_cloud();
          const std::int64_t end = image.reference_end_ns();
          while (next_pose < truth.trajectory.size() && truth.trajectory[next_pose].utc_ns <= end) {
            const TruthPose& p = truth.trajectory[next_pose++];
            for (auto& r : recorders) r->drive(p.x, p.y, p.yaw);
          }
          if (mapper.step_due()) {
            const auto t0 = SteadyClock::now();
            mapper.step(mapper.cloud().time_ns);
            step_total += ms_since(t0);
            ++steps;
          }
          for (std::size_t s = 0; s < recorders.size(); ++s) {
            if (recorders[s]->local_map_complete()) on_local_map(s, *recorders[s]);
          }
          return true;
        },
        o.progress ? std::function<void(double)>([&](double f) {
          o.progress((static_cast<double>(n) + f) / static_cast<double>(o.inputs.size()));
        })
                   : std::function<void(double)>());
    if (!error.empty()) return error;
    if (step_ms != nullptr && steps > 0) *step_ms = step_total / static_cast<double>(steps);
  }
  return {};
}

}  // namespace

std::optional<RobotProfile> builtin_profile(const std::string& name) {
  RobotProfile p;
  p.name = name;
  if (name == "large") {
    // Viona's class: ground clearance for meadows and low undergrowth.
    p.footprint = *trav::builtin_footprint(name);
    p.ground = {true, true, true, true, true};
    return p;
  }
  if (name == "small") {
    // Obelix's class: streets and walkways (street, dirt paths and the
    // simulator's `other`, hard bare ground: walkways, plazas).
    p.footprint = *trav::builtin_footprint(name);
    p.ground = {true, true, false, false, true};
    return p;
  }
  return std::nullopt;
}

LoadedProfile load_profile(const std::string& name_or_file) {
  if (auto b = builtin_profile(name_or_file)) return {b, ""};
  if (name_or_file.find('/') == std::string::npos && name_or_file.find(".yaml") == std::string::npos) {
    return {std::nullopt, "unknown robot profile '" + name_or_file + "' (built in: large, small; or a YAML file)"};
  }
  try {
    const ConfigNode root = ConfigNode::load_file(name_or_file);
    if (root.string("format") != "trailnav-robot-profile") {
      throw ConfigError(root.file(), root.line(), "format", "expected 'trailnav-robot-profile'");
    }
    RobotProfile p;
    p.name = root.string("name");
    if (p.name.empty() || p.name.size() > trav::kMaxProfileName) {
      throw ConfigError(root.file(), root.line(), "name", "1 to 64 characters");
    }
    for (char c : p.name) {
      if (c < 0x21 || c > 0x7e) throw ConfigError(root.file(), root.line(), "name", "printable ASCII without spaces");
    }
    const ConfigNode fp = root.map("footprint");
    p.footprint.length = fp.number("length", 0.1, 10.0);
    p.footprint.width = fp.number("width", 0.1, 10.0);
    p.footprint.forward = fp.number("forward", -5.0, 5.0, 0.0);
    fp.reject_unknown_keys();
    for (const std::string& g : root.string_list("ground")) {
      const auto c = perception::parse_terrain_class(g);
      if (!c) {
        throw ConfigError(root.file(), root.line(), "ground",
                          "unknown kind of ground '" + g + "' (street, dirt, grass, vegetation, other)");
      }
      p.ground[static_cast<std::size_t>(*c)] = true;
    }
    if (std::none_of(p.ground.begin(), p.ground.end(), [](bool b) { return b; })) {
      throw ConfigError(root.file(), root.line(), "ground", "the robot may drive on no ground at all");
    }
    root.reject_unknown_keys();
    return {p, ""};
  } catch (const ConfigError& e) {
    return {std::nullopt, e.what()};
  }
}

const char* untraversable_name(Untraversable cause) noexcept {
  switch (cause) {
    case Untraversable::none: return "none";
    case Untraversable::solid: return "solid";
    case Untraversable::ditch: return "ditch";
    case Untraversable::undergrowth: return "undergrowth";
    case Untraversable::ground: return "ground";
  }
  return "none";
}

std::optional<Untraversable> truth_cause(const RobotProfile& profile, const SimTruth& truth, double x, double y,
                                         double res) {
  const double rr = truth.terrain.resolution;
  const int inner = std::max(1, static_cast<int>(std::lround(res / rr)));
  const double x0 = x - 0.5 * res + 0.5 * rr, y0 = y - 0.5 * res + 0.5 * rr;
  // Worst first: a solid obstacle, a ditch, undergrowth, ground not allowed.
  constexpr int kRank[] = {0, 4, 3, 2, 1};
  Untraversable worst = Untraversable::none;
  for (int j = 0; j < inner; ++j) {
    for (int i = 0; i < inner; ++i) {
      const double px = x0 + i * rr, py = y0 + j * rr;
      const std::uint8_t c = truth.terrain.at(px, py);
      if (c >= perception::kTerrainClasses) return std::nullopt;
      Untraversable here = Untraversable::none;
      switch (static_cast<sim::ObstacleTruth>(truth.obstacles.at(px, py, 0))) {
        case sim::ObstacleTruth::obstacle: here = Untraversable::solid; break;
        case sim::ObstacleTruth::negative: here = Untraversable::ditch; break;
        case sim::ObstacleTruth::vegetation: here = Untraversable::undergrowth; break;
        case sim::ObstacleTruth::free: here = profile.ground[c] ? Untraversable::none : Untraversable::ground; break;
      }
      if (kRank[static_cast<int>(here)] > kRank[static_cast<int>(worst)]) worst = here;
    }
  }
  return worst;
}

std::optional<bool> truth_traversable(const RobotProfile& profile, const SimTruth& truth, double x, double y,
                                      double res) {
  const auto cause = truth_cause(profile, truth, x, y, res);
  if (!cause) return std::nullopt;
  return *cause == Untraversable::none;
}

TravTrainReport run_trav_train(const TravRunOptions& options, const trav::VocabularyConfig& vocabulary,
                               const trav::LearnerConfig& learner, const trav::TravModelFile* extend) {
  TravTrainReport report;
  std::vector<trav::VocabularyConfig> vocabularies;
  for (trav::FeatureSet s : {trav::FeatureSet::full, trav::FeatureSet::thesis, trav::FeatureSet::no_remission,
                             trav::FeatureSet::no_roughness_slope}) {
    trav::VocabularyConfig v = vocabulary;
    v.set = s;
    vocabularies.push_back(v);
  }
  std::vector<std::unique_ptr<trav::TravModels>> models;
  std::vector<trav::WordCounts> counts;
  for (const trav::VocabularyConfig& v : vocabularies) {
    models.push_back(std::make_unique<trav::TravModels>(trav::Vocabulary(v), learner));
    counts.emplace_back(trav::Vocabulary(v).size());
    TravTrainSet set;
    set.set = v.set;
    report.sets.push_back(set);
    if (extend != nullptr) {
      const trav::TravModelSet* old = extend->set(v.set);
      if (old != nullptr) models.back()->set_models(old->models);
    }
  }
  const std::string error = drive_recordings(
      options, vocabularies, report.revolutions, nullptr, {}, [&](std::size_t s, trav::TravRecorder& rec) {
        rec.finish_local_map(counts[s]);
        const trav::TravModels::Assignment a = models[s]->train(counts[s]);
        TravTrainSet& t = report.sets[s];
        t.local_maps.push_back({a, counts[s].total_positive(), counts[s].total_unlabelled()});
        if (a.model < 0) {
          ++t.unlearnt;
        } else {
          ++t.learnt;
          t.created += a.created ? 1 : 0;
          t.forced += a.forced ? 1 : 0;
        }
        if (s == 0) report.recorder = rec.counters();
      });
  if (!error.empty()) {
    report.error = error;
    return report;
  }
  report.model.profile = options.profile.name;
  for (std::size_t s = 0; s < models.size(); ++s) {
    trav::TravModelSet set;
    set.vocabulary = vocabularies[s];
    set.learner = learner;
    for (std::uint32_t m = 0; m < models[s]->models(); ++m) set.models.push_back(models[s]->counts(m));
    report.model.sets.push_back(std::move(set));
  }
  return report;
}

TravEvalReport run_trav_eval(const TravRunOptions& options, const trav::TravModelFile& model) {
  TravEvalReport report;
  std::vector<trav::VocabularyConfig> vocabularies;
  std::vector<std::unique_ptr<trav::TravModels>> models;
  for (const trav::TravModelSet& s : model.sets) {
    vocabularies.push_back(s.vocabulary);
    models.push_back(std::make_unique<trav::TravModels>(trav::Vocabulary(s.vocabulary), s.learner));
    models.back()->set_models(s.models);
    for (trav::Method m : {trav::Method::pnb, trav::Method::pos}) {
      TravEvalRow row;
      row.method = m;
      row.set = s.vocabulary.set;
      report.rows.push_back(row);
    }
  }
  const SimTruth* truth = nullptr;
  const double res = options.terrain.map.resolution;
  struct Called {
    bool traversable = false;
    std::int8_t truth = -1;   // -1 outside
    std::int8_t cls = -1;     // the cell's single true class, -1 mixed
    Untraversable cause = Untraversable::none;
  };
  std::unordered_map<std::uint64_t, std::array<Called, 2>> cells;
  auto key = [](CellIndex c) {
    return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(c.x)) << 32) | static_cast<std::uint32_t>(c.y);
  };
  std::uint64_t local_maps_full = 0;
  // For the pictures: each cell's latest answer of the full vector (both methods) and its truth.
  std::unordered_map<std::uint64_t, std::array<Called, 2>> latest;
  std::size_t full_set = model.sets.size();
  for (std::size_t s = 0; s < model.sets.size(); ++s) {
    if (model.sets[s].vocabulary.set == trav::FeatureSet::full) full_set = s;
  }
  const std::string error = drive_recordings(
      options, vocabularies, report.revolutions, &report.step_ms, [&](const SimTruth& t) { truth = &t; },
      [&](std::size_t s, trav::TravRecorder& rec) {
        cells.clear();
        const double cell_res = res;
        trav::WordCounts counts(rec.vocabulary().size());
        rec.finish_local_map(counts, [&](const trav::TravRecorder::CellWords& c) {
          std::array<Called, 2> called{};
          const double x = (c.cell.x + 0.5) * cell_res, y = (c.cell.y + 0.5) * cell_res;
          const std::optional<Untraversable> cause = truth_cause(options.profile, *truth, x, y, cell_res);
          const std::int8_t t = !cause ? std::int8_t{-1} : *cause == Untraversable::none ? std::int8_t{1} : std::int8_t{0};
          std::int8_t cls = -1;
          if (t >= 0) {
            // Its single class, for the per-class figures.
            const std::uint8_t c0 = truth->terrain.at(x, y);
            cls = c0 < perception::kTerrainClasses ? static_cast<std::int8_t>(c0) : std::int8_t{-1};
          }
          for (std::size_t m = 0; m < 2; ++m) {
            const double p = models[s]->probability(static_cast<trav::Method>(m), c.words);
            called[m] = {p > 0.5, t, cls, cause.value_or(Untraversable::none)};
          }
          cells[key(c.cell)] = called;
          if (s == full_set && !options.png_dir.empty() && options.inputs.size() == 1) latest[key(c.cell)] = called;
        });
        // Score with the thesis' rule: an untraversable cell called
        // traversable is a false positive only when its 8 neighbours are
        // called traversable too.
        for (const auto& [k, called] : cells) {
          const CellIndex c{static_cast<std::int32_t>(k >> 32), static_cast<std::int32_t>(k & 0xffffffffu)};
          for (std::size_t m = 0; m < 2; ++m) {
            TravEvalRow& row = report.rows[2 * s + m];
            const Called& me = called[m];
            if (me.truth < 0) {
              if (s == 0 && m == 0) ++report.unscored;
              continue;
            }
            if (me.cls >= 0) {
              ++row.class_cells[static_cast<std::size_t>(me.cls)];
              row.called_traversable[static_cast<std::size_t>(me.cls)] += me.traversable ? 1 : 0;
            }
            if (me.truth == 1) {
              (me.traversable ? row.scores.tp : row.scores.fn) += 1;
              continue;
            }
            if (!me.traversable) {
              ++row.scores.tn;
              continue;
            }
            bool all = true;
            for (int dy = -1; dy <= 1 && all; ++dy) {
              for (int dx = -1; dx <= 1 && all; ++dx) {
                if (dx == 0 && dy == 0) continue;
                const auto it = cells.find(key({c.x + dx, c.y + dy}));
                all = it != cells.end() && it->second[m].traversable;
              }
            }
            if (all) {
              ++row.scores.fp;
              ++row.false_positives[static_cast<std::size_t>(me.cause)];
            } else {
              ++row.scores.tn;
              ++row.scores.forgiven;
            }
          }
        }
        if (s == 0) ++local_maps_full;
      });
  if (!error.empty()) {
    report.error = error;
    return report;
  }
  report.local_maps = local_maps_full;
  if (!latest.empty()) {
    std::int32_t x0 = INT32_MAX, y0 = INT32_MAX, x1 = INT32_MIN, y1 = INT32_MIN;
    for (const auto& [k, called] : latest) {
      const auto x = static_cast<std::int32_t>(k >> 32), y = static_cast<std::int32_t>(k & 0xffffffffu);
      x0 = std::min(x0, x), y0 = std::min(y0, y), x1 = std::max(x1, x), y1 = std::max(y1, y);
    }
    const int w = x1 - x0 + 1, h = y1 - y0 + 1;
    constexpr cli::Rgb kTp{90, 180, 90}, kTn{70, 70, 80}, kFp{220, 40, 40}, kFn{240, 160, 40}, kOut{200, 200, 205},
        kNone{245, 245, 240};
    for (std::size_t m = 0; m < 2; ++m) {
      std::vector<std::uint8_t> rgb(static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * 3);
      for (std::size_t i = 0; i < rgb.size(); i += 3) rgb[i] = kNone.r, rgb[i + 1] = kNone.g, rgb[i + 2] = kNone.b;
      for (const auto& [k, called] : latest) {
        const auto x = static_cast<std::int32_t>(k >> 32), y = static_cast<std::int32_t>(k & 0xffffffffu);
        const Called& a = called[m];
        const cli::Rgb c = a.truth < 0 ? kOut
                           : a.truth == 1 ? (a.traversable ? kTp : kFn)
                                          : (a.traversable ? kFp : kTn);
        const std::size_t row = static_cast<std::size_t>(y1 - y), col = static_cast<std::size_t>(x - x0);
        std::uint8_t* px = &rgb[(row * static_cast<std::size_t>(w) + col) * 3];
        px[0] = c.r, px[1] = c.g, px[2] = c.b;
      }
      cli::MapFigure f;
      f.title = "traversability, " + std::string(trav::method_name(static_cast<trav::Method>(m))) + ", robot " +
                options.profile.name;
      f.notes = {options.inputs.front(), "each cell's answer when its last local map ended, against the SIMULATED truth",
                 "world frame, north up"};
      f.legend = {{kTp, "traversable, called so"},
                  {kTn, "untraversable, called so"},
                  {kFp, "untraversable, called traversable"},
                  {kFn, "traversable, called not"},
                  {kOut, "outside the world"},
                  {kNone, "no feature"}};
      f.metres_per_pixel = res;
      const std::string path = options.png_dir + "/traversability-" +
                               std::string(trav::method_name(static_cast<trav::Method>(m))) + ".png";
      if (Status st = cli::write_map_figure(path, rgb, w, h, f); st) {
        report.files.push_back(path);
      } else {
        report.error = st.message();
      }
    }
  }
  return report;
}

}  // namespace trailnav::eval
