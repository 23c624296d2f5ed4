#include "subgoal_eval.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>

#include "pose_eval.hpp"
#include "roads.hpp"
#include "sim_truth.hpp"
#include "terrain_run.hpp"
#include "trailnav/perception/trav_layer.hpp"
#include "trailnav/navigation/navigator/navigator.hpp"

namespace trailnav::eval {
namespace {

namespace fs = std::filesystem;

struct Junction {
  std::string label;
  double x = 0, y = 0;
  double arc = 0;  // along the true route
};

std::vector<Junction> read_junctions(const std::string& file, const sim::Polyline& route) {
  std::vector<Junction> out;
  std::ifstream in(file);
  std::string line;
  if (!in || !std::getline(in, line)) return out;
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    std::istringstream ls(line);
    for (std::string v; std::getline(ls, v, ',');) f.push_back(v);
    if (f.size() < 7) continue;
    Junction j;
    j.x = std::stod(f[3]);
    j.y = std::stod(f[4]);
    const double shift = std::hypot(std::stod(f[5]) - j.x, std::stod(f[6]) - j.y);
    char buf[96];
    std::snprintf(buf, sizeof buf, "%s/%s, OSM node %.1f m off", f[0].c_str(), f[1].c_str(), shift);
    j.label = buf;
    const auto on_route = route.project({j.x, j.y});
    if (on_route.distance > 3.0) continue;  // not on the driven route
    j.arc = on_route.arc;
    out.push_back(j);
  }
  return out;
}

struct Run {
  std::unique_ptr<nav::Navigator> navigator;
  std::size_t config = 0;
  int seed = 0;
  double sq = 0.0;
  std::size_t sent = 0;
  std::vector<int> junction_ok;  // per junction of this recording: 1 until a subgoal fails
};

}  // namespace

const char* cell_cost_name(subgoals::AlignerConfig::CellCost cost) noexcept {
  return cost == subgoals::AlignerConfig::CellCost::traversability ? "traversability" : "classes";
}

SubgoalEvalReport evaluate_subgoals(const SubgoalEvalOptions& o) {
  SubgoalEvalReport report;
  auto fail = [&](std::string e) {
    report.error = std::move(e);
    return report;
  };
  if (o.recordings.empty()) return fail("no recordings given");
  if (o.forest == nullptr) return fail("no terrain model");
  if (o.seeds < 1) return fail("at least one seed is needed");
  using CellCost = subgoals::AlignerConfig::CellCost;
  const bool learnt = std::find(o.costs.begin(), o.costs.end(), CellCost::traversability) != o.costs.end();
  if (o.costs.empty()) return fail("no cell cost to align with");
  if (learnt && o.trav_models == nullptr) return fail("the traversability cost needs a traversability model");
  for (CellCost cost : o.costs) {
    for (std::size_t s : o.samples) {
      for (int k : o.sequences) {
        subgoals::AlignerConfig c = o.navigator.aligner;
        c.samples = s;
        c.sequence = k;
        if (std::string e = subgoals::check_aligner_config(c); !e.empty()) return fail("aligner: " + e);
        SubgoalConfigResult r;
        r.cost = cost;
        r.samples = s;
        r.sequence = k;
        report.configs.push_back(r);
      }
    }
  }
  double raw_sq = 0.0;
  std::size_t raw_sent = 0;
  std::vector<double> config_sq(report.configs.size() * static_cast<std::size_t>(o.seeds), 0.0);
  std::FILE* csv = nullptr;
  if (!o.csv.empty()) {
    csv = std::fopen(o.csv.c_str(), "w");
    if (csv == nullptr) return fail("cannot write " + o.csv);
    std::fprintf(csv, "recording,subgoal,true_arc,raw_x,raw_y,raw_error");
    for (const auto& c : report.configs) {
      const char* n = c.cost == CellCost::classes ? "" : "_trav";
      std::fprintf(csv, ",x_%zu_k%d%s,y_%zu_k%d%s,error_%zu_k%d%s", c.samples, c.sequence, n, c.samples, c.sequence, n,
                   c.samples, c.sequence, n);
    }
    std::fprintf(csv, "\n");
  }
  struct CsvCloser {
    std::FILE*& f;
    ~CsvCloser() { if (f != nullptr) std::fclose(f); }
  } closer{csv};

  for (const std::string& rec : o.recordings) {
    const std::string name = fs::path(rec).filename().string();
    auto loaded = load_sim_truth((fs::path(rec) / "truth").string());
    if (!loaded.truth) return fail(rec + ": needs a simulated recording's truth: " + loaded.error);
    const SimTruth& truth = *loaded.truth;
    sim::Polyline true_route;
    if (std::string e = load_true_route((fs::path(rec) / "truth").string(), true_route); !e.empty()) return fail(e);
    std::vector<Junction> junctions;
    if (truth.scenario.name == "junctions") junctions = read_junctions((fs::path(rec) / "truth" / "junctions.csv").string(), true_route);
    const std::size_t junction_base = report.junctions.size();
    for (std::size_t i = 0; i < junctions.size(); ++i) {
      report.junctions.push_back(name + ": (" + std::string(1, static_cast<char>('a' + i)) + ") " + junctions[i].label);
      report.raw_junction_ok.push_back(1);
      for (auto& c : report.configs) c.junction_successes.push_back(0);
    }

    const sim::GeoFrame geo(truth.scenario.origin_lat, truth.scenario.origin_lon);
    if (o.progress) o.progress(name + " map", 0.0);
    auto graph_loaded = osm::load_road_graph((fs::path(rec) / "world.osm").string(), o.profile,
                                             [&](double f) { if (o.progress) o.progress(name + " map", f); }, geo.zone());
    if (!graph_loaded.graph) return fail(graph_loaded.error);
    const osm::RoadGraph& graph = *graph_loaded.graph;

    // The robot's UTM pose as the pose estimator has it.
    std::vector<pose::UtmPose> utm;
    PoseEvalOptions po;
    po.progress = [&](double f) { if (o.progress) o.progress(name + " pose", f); };
    po.on_utm = [&](const pose::UtmPose& u) { utm.push_back(u); };
    const PoseEvalResult pr = evaluate_pose(rec, po);
    if (!pr.error.empty()) return fail(pr.error);
    if (utm.empty()) return fail(rec + ": the pose estimate never found its heading");
    auto utm_at = [&](std::int64_t t) -> const pose::UtmPose* {
      auto it = std::upper_bound(utm.begin(), utm.end(), t, [](std::int64_t v, const pose::UtmPose& s) { return v < s.time_ns; });
      if (it == utm.begin()) return nullptr;
      return &*(it - 1);
    };

    // Navigators: every configuration and seed, each as trailnavd runs it.
    const TruthPose& end = truth.trajectory.back();
    std::vector<Run> runs;
    for (std::size_t c = 0; c < report.configs.size(); ++c) {
      for (int seed = 1; seed <= o.seeds; ++seed) {
        nav::NavigatorConfig nc = o.navigator;
        nc.goal_lat = end.lat;
        nc.goal_lon = end.lon;
        nc.aligner.samples = report.configs[c].samples;
        nc.aligner.sequence = report.configs[c].sequence;
        nc.aligner.seed = static_cast<std::uint64_t>(seed);
        nc.aligner.cost = o.terrain.cost;
        nc.aligner.unknown_cost = o.terrain.unknown_cost;
        nc.aligner.cell_cost = report.configs[c].cost;
        auto made = nav::Navigator::create(graph, nc, o.terrain.map);
        if (!made.navigator) return fail(rec + ": " + made.error);
        Run r;
        r.navigator = std::move(made.navigator);
        r.config = c;
        r.seed = seed;
        r.junction_ok.assign(junctions.size(), 1);
        runs.push_back(std::move(r));
      }
    }

    bool planned = false;
    std::string plan_error;
    auto error_of = [&](const subgoals::Vec2& g) {
      return std::max(0.0, true_route.project({g.x, g.y}).distance - 0.5 * o.street_width);
    };
    auto in_junction = [&](double arc, std::size_t j) {
      return arc >= junctions[j].arc - o.junction_before && arc <= junctions[j].arc + o.junction_after;
    };

    std::unique_ptr<perception::trav::TravLayer> layer;
    if (learnt) {
      auto made = perception::trav::TravLayer::create(*o.trav_models, o.trav_method, o.trav_local_map, o.trav_max_range,
                                                      o.terrain.map.size_x, o.terrain.map.size_y, o.terrain.map.resolution);
      if (!made.layer) return fail("traversability: " + made.error);
      layer = std::move(made.layer);
    }
    TerrainRunOptions tr;
    tr.input = rec;
    tr.sums_sink = layer.get();
    tr.config = o.terrain;
    tr.forest = o.forest;
    tr.forest_name = o.forest_name;
    tr.progress = [&](double f) { if (o.progress) o.progress(name + " terrain + alignment", f); };
    tr.on_revolution = [&](const perception::TerrainMapper& mapper, bool stepped) {
      if (!stepped || !plan_error.empty()) return;
      const std::int64_t t = mapper.cloud().time_ns;
      const pose::UtmPose* u = utm_at(t);
      TruthAt p;
      if (u == nullptr || !truth_at(truth.trajectory, t, p)) return;
      // The local frame is the simulated world here (the map is registered with the true trajectory).
      pose::LocalPose local;
      local.time_ns = t;
      local.x = p.x;
      local.y = p.y;
      local.yaw = p.yaw;
      const auto t0 = std::chrono::steady_clock::now();
      std::size_t reached_begin = 0, reached_end = 0;
      for (Run& r : runs) {
        const nav::StepResult sr = r.navigator->step(local, *u, &mapper.map());
        reached_begin = sr.reached_begin;
        reached_end = sr.reached_end;
      }
      report.seconds_aligning += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      ++report.updates;
      const nav::Navigator& first = *runs.front().navigator;
      if (first.state() == nav::NavState::failed) {
        plan_error = rec + ": no route on world.osm from the robot's GPS position to the route's end";
        return;
      }
      if (!planned && first.state() != nav::NavState::planning) {
        planned = true;
        report.route_length += first.route_length();
      }
      // Subgoals reached in this step: their final estimates are what the robot drove to.
      for (std::size_t i = reached_begin; i < reached_end; ++i) {
        const subgoals::Vec2 raw = first.raw_local(i);
        const double re = error_of(raw);
        raw_sq += re * re;
        report.raw_max = std::max(report.raw_max, re);
        ++raw_sent;
        for (std::size_t j = 0; j < junctions.size(); ++j) {
          if (in_junction(p.arc, j) && re > o.junction_tolerance) report.raw_junction_ok[junction_base + j] = 0;
        }
        if (csv != nullptr) std::fprintf(csv, "%s,%zu,%.2f,%.3f,%.3f,%.3f", name.c_str(), i, p.arc, raw.x, raw.y, re);
        for (Run& r : runs) {
          const subgoals::Vec2 g = r.navigator->corrected(i);
          const double e = error_of(g);
          if (csv != nullptr && r.seed == 1) std::fprintf(csv, ",%.3f,%.3f,%.3f", g.x, g.y, e);
          r.sq += e * e;
          ++r.sent;
          for (std::size_t j = 0; j < junctions.size(); ++j) {
            if (in_junction(p.arc, j) && e > o.junction_tolerance) r.junction_ok[j] = 0;
          }
        }
        if (csv != nullptr) std::fprintf(csv, "\n");
      }
    };
    const TerrainRunReport trr = run_terrain(tr);
    if (!trr.error.empty()) return fail(trr.error);
    if (!plan_error.empty()) return fail(plan_error);
    if (!planned) return fail(rec + ": no terrain step with a UTM pose; nothing was planned");
    for (Run& r : runs) {
      config_sq[r.config * static_cast<std::size_t>(o.seeds) + static_cast<std::size_t>(r.seed - 1)] += r.sq;
      for (std::size_t j = 0; j < junctions.size(); ++j) report.configs[r.config].junction_successes[junction_base + j] += r.junction_ok[j];
    }
  }
  report.subgoals_sent = raw_sent;
  report.raw_rmse = raw_sent ? std::sqrt(raw_sq / static_cast<double>(raw_sent)) : 0.0;
  for (std::size_t c = 0; c < report.configs.size(); ++c) {
    auto& cr = report.configs[c];
    double sum = 0.0;
    for (int s = 0; s < o.seeds; ++s) {
      const double rmse = raw_sent ? std::sqrt(config_sq[c * static_cast<std::size_t>(o.seeds) + static_cast<std::size_t>(s)] /
                                               static_cast<double>(raw_sent))
                                   : 0.0;
      cr.rmse.push_back(rmse);
      sum += rmse;
    }
    cr.mean_rmse = sum / o.seeds;
  }
  return report;
}

}  // namespace trailnav::eval
