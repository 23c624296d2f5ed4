#include "terrain_run.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <unordered_map>
#include <utility>

#include "revolution_source.hpp"
#include "world.hpp"

namespace trailnav::eval {

namespace {

using SteadyClock = std::chrono::steady_clock;
double ms_since(SteadyClock::time_point t0) {
  return std::chrono::duration<double, std::milli>(SteadyClock::now() - t0).count();
}

class Scorer final : public perception::TerrainObserver {
 public:
  Scorer(const SimTruth& truth, double res, TerrainRunReport& report, bool collect, bool scored)
      : truth_(truth), res_(res), report_(report), collect_(collect), scored_(scored) {}
  void observe(const perception::TerrainObservation& o) override {
    const auto label = truth_cell_class(truth_, o.x, o.y, res_);
    if (!label) {
      ++report_.unlabelled;
      return;
    }
    const int t = static_cast<int>(*label);
    if (collect_) report_.samples.add(o.feature, *label);
    if (!scored_) return;
    const auto best = static_cast<int>(std::max_element(o.likelihood.begin(), o.likelihood.end()) - o.likelihood.begin());
    report_.single.add(t, best);
    report_.integrated.add(t, static_cast<int>(o.estimate->best));
    const std::uint64_t key = (static_cast<std::uint64_t>(static_cast<std::uint32_t>(o.cell.x)) << 32) |
                              static_cast<std::uint32_t>(o.cell.y);
    last_[key] = {t, static_cast<int>(o.estimate->best)};
  }
  // Each labelled cell once, with the class the map held for it last.
  void add_last(perception::ConfusionMatrix& m) const {
    for (const auto& [key, v] : last_) m.add(v.first, v.second);
  }

 private:
  const SimTruth& truth_;
  double res_;
  TerrainRunReport& report_;
  bool collect_;
  bool scored_;
  std::unordered_map<std::uint64_t, std::pair<int, int>> last_;
};

}  // namespace

std::optional<perception::TerrainClass> truth_cell_class(const SimTruth& truth, double x, double y, double res) {
  const double rr = truth.terrain.resolution;
  const int inner = std::max(1, static_cast<int>(std::lround(res / rr)));
  const double x0 = x - 0.5 * res + 0.5 * rr;
  const double y0 = y - 0.5 * res + 0.5 * rr;
  int cls = -1;
  bool mixed = false;
  int solid = 0, undergrowth = 0;
  for (int j = 0; j < inner; ++j) {
    for (int i = 0; i < inner; ++i) {
      const double px = x0 + i * rr, py = y0 + j * rr;
      const std::uint8_t c = truth.terrain.at(px, py);
      if (c >= perception::kTerrainClasses) return std::nullopt;  // outside the world
      if (cls < 0) cls = c;
      mixed = mixed || c != cls;
      const std::uint8_t ob = truth.obstacles.at(px, py, 0);
      solid += ob == static_cast<std::uint8_t>(sim::ObstacleTruth::obstacle) ? 1 : 0;
      undergrowth += ob == static_cast<std::uint8_t>(sim::ObstacleTruth::vegetation) ? 1 : 0;
    }
  }
  // An object or a bush covering most of the cell decides its class; one
  // covering part of it makes the cell mixed.
  const int pixels = inner * inner;
  if (2 * solid >= pixels) return perception::TerrainClass::other;
  if (2 * undergrowth >= pixels && solid == 0) return perception::TerrainClass::vegetation;
  if (solid > 0 || undergrowth > 0) return std::nullopt;
  if (mixed || cls < 0) return std::nullopt;
  return static_cast<perception::TerrainClass>(cls);
}

TerrainRunReport run_terrain(const TerrainRunOptions& options) {
  TerrainRunReport report;
  auto opened = RevolutionSource::open({options.input}, options.calibration);
  if (!opened.source) {
    report.error = opened.error;
    return report;
  }
  RevolutionSource& source = *opened.source;
  report.lidar = source.model_name();
  if (!source.truth()) {
    report.error = options.input + ": not a simulated recording (no truth/ directory): its cells have no labels";
    return report;
  }
  if (options.forest != nullptr) {
    if (std::string e = perception::check_forest_lidar(*options.forest, source.model_name(), options.forest_name); !e.empty()) {
      report.error = options.input + ": " + e;
      return report;
    }
    if (std::string e = perception::check_forest_settings(*options.forest, options.config, options.forest_name); !e.empty()) {
      report.error = e;
      return report;
    }
  }
  const SimTruth& truth = *source.truth();
  perception::MountParams mount = options.mount;
  if (mount.translation == std::array<double, 3>{0.0, 0.0, 0.0}) mount.translation = source.mount_translation();
  auto made = perception::TerrainMapper::create(options.config, mount, source.shape(), options.forest);
  if (!made.mapper) {
    report.error = made.error;
    return report;
  }
  perception::TerrainMapper& mapper = *made.mapper;
  Scorer scorer(truth, options.config.map.resolution, report, options.collect_samples, options.forest != nullptr);
  mapper.set_observer(&scorer);
  mapper.set_sums_sink(options.sums_sink);
  perception::PoseTrack poses(truth.trajectory.size() + 1);
  fill_pose_track(truth, poses);

  double align_ms = 0.0, register_ms = 0.0, step_ms = 0.0;
  const std::string error = source.run(
      [&](const velodyne::RangeImage& image) {
        ++report.revolutions;
        auto t0 = SteadyClock::now();
        mapper.align(image, &poses);
        align_ms += ms_since(t0);
        t0 = SteadyClock::now();
        mapper.register_cloud();
        register_ms += ms_since(t0);
        const bool due = mapper.step_due();
        if (due) {
          t0 = SteadyClock::now();
          mapper.step(mapper.cloud().time_ns);
          step_ms += ms_since(t0);
        }
        if (options.on_revolution) options.on_revolution(mapper, due);
        return true;
      },
      options.progress);
  if (!error.empty()) {
    report.error = error;
    return report;
  }
  report.counters = mapper.counters();
  scorer.add_last(report.last);
  if (report.revolutions > 0) {
    report.align_ms = align_ms / static_cast<double>(report.revolutions);
    report.register_ms = register_ms / static_cast<double>(report.revolutions);
  }
  if (report.counters.steps > 0) report.step_ms = step_ms / static_cast<double>(report.counters.steps);
  return report;
}

namespace {
constexpr const char* kCsvHeader = "max_remission,mean_remission,std_remission,roughness,slope,area_std_remission,class";
constexpr const char* kOldCsvHeader = "max_remission,mean_remission,std_remission,roughness,slope,class";
}  // namespace

std::string load_labelled_csv(const std::string& path, perception::LabelledFeatures& out) {
  std::ifstream in(path);
  if (!in) return path + ": cannot open";
  std::string line;
  int line_no = 0;
  bool header = false;
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    if (!header) {
      if (line == kOldCsvHeader) {
        return path + ":" + std::to_string(line_no) +
               ": five features per line; cells need a sixth, area_std_remission (the remission spread over the "
               "cells around; docs/terrain.md), before the class";
      }
      if (line != kCsvHeader) {
        return path + ":" + std::to_string(line_no) + ": expected the header '" + kCsvHeader + "'";
      }
      header = true;
      continue;
    }
    std::stringstream ss(line);
    perception::FeatureVector f{};
    std::string field;
    for (int k = 0; k < perception::kTerrainFeatures; ++k) {
      if (!std::getline(ss, field, ',')) return path + ":" + std::to_string(line_no) + ": expected 7 fields";
      char* end = nullptr;
      const float v = std::strtof(field.c_str(), &end);
      if (field.empty() || end != field.c_str() + field.size() || !std::isfinite(v)) {
        return path + ":" + std::to_string(line_no) + ": '" + field + "' is not a number (" +
               std::string(perception::terrain_feature_name(static_cast<perception::TerrainFeature>(k))) + ")";
      }
      f[static_cast<std::size_t>(k)] = v;
    }
    if (!std::getline(ss, field) || field.find(',') != std::string::npos) {
      return path + ":" + std::to_string(line_no) + ": expected 7 fields";
    }
    const auto cls = perception::parse_terrain_class(field);
    if (!cls) {
      return path + ":" + std::to_string(line_no) + ": unknown class '" + field +
             "' (street, dirt, grass, vegetation or other)";
    }
    out.add(f, *cls);
  }
  if (!header) return path + ": empty (no header line)";
  return {};
}

Status save_labelled_csv(const std::string& path, const perception::LabelledFeatures& data) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) return Status::error("cannot write " + path);
  std::fprintf(f, "%s\n", kCsvHeader);
  for (std::size_t i = 0; i < data.size(); ++i) {
    const auto& v = data.features[i];
    std::fprintf(f, "%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%s\n", static_cast<double>(v[0]), static_cast<double>(v[1]),
                 static_cast<double>(v[2]), static_cast<double>(v[3]), static_cast<double>(v[4]), static_cast<double>(v[5]),
                 std::string(perception::terrain_class_name(static_cast<perception::TerrainClass>(data.labels[i]))).c_str());
  }
  if (std::fclose(f) != 0) return Status::error("cannot write " + path);
  return Status::ok();
}

}  // namespace trailnav::eval
