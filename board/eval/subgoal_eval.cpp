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
#include "trailnav/navigation/osm/router.hpp"

namespace trailnav::eval {
namespace {

namespace fs = std::filesystem;
using osm::Point2;

// The planned route in UTM with arc lengths; the robot's progress is its
// nearest point within an arc window (so a route that passes a place twice
// is not jumped along), which sim::Polyline::project does not offer.
struct Path {
  std::vector<Point2> p;
  std::vector<double> s;
  void finish() {
    s.assign(p.size(), 0.0);
    for (std::size_t i = 1; i < p.size(); ++i) s[i] = s[i - 1] + std::hypot(p[i].x - p[i - 1].x, p[i].y - p[i - 1].y);
  }
  // Distance from (x, y) and the arc of the nearest point, over segments whose arc lies in [lo, hi].
  double nearest(double x, double y, double& arc, double lo = -1e300, double hi = 1e300) const {
    double best = std::numeric_limits<double>::max();
    arc = 0.0;
    for (std::size_t i = 1; i < p.size(); ++i) {
      if (s[i] < lo || s[i - 1] > hi) continue;
      const double dx = p[i].x - p[i - 1].x, dy = p[i].y - p[i - 1].y, l2 = dx * dx + dy * dy;
      const double t = l2 > 0 ? std::clamp(((x - p[i - 1].x) * dx + (y - p[i - 1].y) * dy) / l2, 0.0, 1.0) : 0.0;
      const double d = std::hypot(x - p[i - 1].x - t * dx, y - p[i - 1].y - t * dy);
      if (d < best) {
        best = d;
        arc = s[i - 1] + t * (s[i] - s[i - 1]);
      }
    }
    return best;
  }
};

std::string read_route(const std::string& file, sim::Polyline& out) {
  std::ifstream in(file);
  if (!in) return "cannot read " + file;
  std::string line;
  std::getline(in, line);
  std::vector<sim::Vec2> points;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string arc, x, y;
    if (std::getline(ls, arc, ',') && std::getline(ls, x, ',') && std::getline(ls, y, ','))
      points.emplace_back(std::stod(x), std::stod(y));
  }
  if (points.size() < 2) return file + ": fewer than two route points";
  out = sim::Polyline(std::move(points));
  return {};
}

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

struct UtmSample {
  std::int64_t t;
  double e, n, yaw;
};

struct Run {
  std::unique_ptr<subgoals::SubgoalAligner> aligner;
  std::size_t config = 0;
  int seed = 0;
  double sq = 0.0;
  std::size_t sent = 0;
  std::vector<int> junction_ok;  // per junction of this recording: 1 until a subgoal fails
};

}  // namespace

SubgoalEvalReport evaluate_subgoals(const SubgoalEvalOptions& o) {
  SubgoalEvalReport report;
  auto fail = [&](std::string e) {
    report.error = std::move(e);
    return report;
  };
  if (o.recordings.empty()) return fail("no recordings given");
  if (o.forest == nullptr) return fail("no terrain model");
  if (o.seeds < 1) return fail("at least one seed is needed");
  for (std::size_t s : o.samples) {
    for (int k : o.sequences) {
      subgoals::AlignerConfig c = o.aligner;
      c.samples = s;
      c.sequence = k;
      if (std::string e = subgoals::check_aligner_config(c); !e.empty()) return fail("aligner: " + e);
      SubgoalConfigResult r;
      r.samples = s;
      r.sequence = k;
      report.configs.push_back(r);
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
    for (const auto& c : report.configs) std::fprintf(csv, ",x_%zu_k%d,y_%zu_k%d,error_%zu_k%d", c.samples, c.sequence, c.samples, c.sequence, c.samples, c.sequence);
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
    if (std::string e = read_route((fs::path(rec) / "truth" / "route.csv").string(), true_route); !e.empty()) return fail(e);
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
    std::vector<UtmSample> utm;
    PoseEvalOptions po;
    po.progress = [&](double f) { if (o.progress) o.progress(name + " pose", f); };
    po.on_utm = [&](const pose::UtmPose& u) { utm.push_back({u.time_ns, u.easting, u.northing, u.yaw}); };
    const PoseEvalResult pr = evaluate_pose(rec, po);
    if (!pr.error.empty()) return fail(pr.error);
    if (utm.empty()) return fail(rec + ": the pose estimate never found its heading");
    auto utm_at = [&](std::int64_t t) -> const UtmSample* {
      auto it = std::upper_bound(utm.begin(), utm.end(), t, [](std::int64_t v, const UtmSample& s) { return v < s.t; });
      if (it == utm.begin()) return nullptr;
      return &*(it - 1);
    };

    // Aligners: every configuration and seed.
    std::vector<Run> runs;
    for (std::size_t c = 0; c < report.configs.size(); ++c) {
      for (int seed = 1; seed <= o.seeds; ++seed) {
        subgoals::AlignerConfig ac = o.aligner;
        ac.samples = report.configs[c].samples;
        ac.sequence = report.configs[c].sequence;
        ac.seed = static_cast<std::uint64_t>(seed);
        Run r;
        ac.cost = o.terrain.cost;
        ac.unknown_cost = o.terrain.unknown_cost;
        r.aligner = std::make_unique<subgoals::SubgoalAligner>(ac, o.terrain.map);
        r.config = c;
        r.seed = seed;
        r.junction_ok.assign(junctions.size(), 1);
        runs.push_back(std::move(r));
      }
    }

    // The plan, made at the first step with a UTM pose.
    bool planned = false;
    std::vector<Point2> route_utm, goals_utm;
    Path route_path;
    std::vector<double> goal_arc;
    std::vector<subgoals::Vec2> raw;
    std::size_t pushed = 0, active = 0;
    double robot_arc = 0.0;
    std::string plan_error;
    const TruthPose& end = truth.trajectory.back();

    TerrainRunOptions tr;
    tr.input = rec;
    tr.config = o.terrain;
    tr.forest = o.forest;
    tr.progress = [&](double f) { if (o.progress) o.progress(name + " terrain + alignment", f); };
    tr.on_revolution = [&](const perception::TerrainMapper& mapper, bool stepped) {
      if (!stepped || !plan_error.empty()) return;
      const std::int64_t t = mapper.cloud().time_ns;
      const UtmSample* u = utm_at(t);
      TruthAt p;
      if (u == nullptr || !truth_at(truth.trajectory, t, p)) return;
      if (!planned) {
        double gx = 0, gy = 0;
        graph.to_utm(end.lat, end.lon, gx, gy);
        const auto from = graph.project(u->e, u->n);
        const auto to = graph.project(gx, gy);
        osm::Router router(graph);
        const osm::RouteStats st = router.route(*from, *to, route_utm);
        if (!st.found) {
          plan_error = rec + ": no route on world.osm from the robot's GPS position to the route's end";
          return;
        }
        osm::subsample_path(route_utm, o.spacing, goals_utm);
        route_path.p = route_utm;
        route_path.finish();
        for (const Point2& g : goals_utm) {
          double a = 0;
          route_path.nearest(g.x, g.y, a);
          goal_arc.push_back(a);
        }
        raw.resize(goals_utm.size());
        report.route_length += st.length;
        planned = true;
      }
      // UTM -> world through the estimate: world = P * U^-1 * q.
      const double rot = p.yaw - u->yaw, cr = std::cos(rot), sr = std::sin(rot);
      auto to_world = [&](const Point2& q) {
        const double dx = q.x - u->e, dy = q.y - u->n;
        return subgoals::Vec2{p.x + cr * dx - sr * dy, p.y + sr * dx + cr * dy};
      };
      route_path.nearest(u->e, u->n, robot_arc, robot_arc - 5.0, robot_arc + 30.0);
      std::size_t want = pushed;
      while (want < goals_utm.size() && goal_arc[want] <= robot_arc + o.lookahead) ++want;
      if (want == 0) want = 1;
      const std::size_t first = want > 9 ? want - 9 : 0;
      for (std::size_t i = first; i < want; ++i) raw[i] = to_world(goals_utm[i]);
      // Subgoals to send: the next one when the active one is almost reached.
      std::size_t send_to = active;
      while (send_to < want && goal_arc[send_to] <= robot_arc + o.reach) ++send_to;
      const auto t0 = std::chrono::steady_clock::now();
      for (Run& r : runs) {
        for (std::size_t i = r.aligner->count(); i < want; ++i) r.aligner->push(raw);
        r.aligner->update(mapper.map(), raw);
      }
      report.seconds_aligning += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      ++report.updates;
      pushed = want;
      auto error_of = [&](const subgoals::Vec2& g) {
        return std::max(0.0, true_route.project({g.x, g.y}).distance - 0.5 * o.street_width);
      };
      for (; active < send_to; ++active) {
        const double re = error_of(raw[active]);
        raw_sq += re * re;
        report.raw_max = std::max(report.raw_max, re);
        ++raw_sent;
        for (std::size_t j = 0; j < junctions.size(); ++j) {
          if (p.arc >= junctions[j].arc - o.junction_before && p.arc <= junctions[j].arc + o.junction_after && re > o.junction_tolerance)
            report.raw_junction_ok[junction_base + j] = 0;
        }
        if (csv != nullptr)
          std::fprintf(csv, "%s,%zu,%.2f,%.3f,%.3f,%.3f", name.c_str(), active, p.arc, raw[active].x, raw[active].y, re);
        for (Run& r : runs) {
          const subgoals::Vec2 g = r.aligner->estimated(active) ? r.aligner->estimate(active) : raw[active];
          const double e = error_of(g);
          if (csv != nullptr && r.seed == 1) std::fprintf(csv, ",%.3f,%.3f,%.3f", g.x, g.y, e);
          r.sq += e * e;
          ++r.sent;
          for (std::size_t j = 0; j < junctions.size(); ++j) {
            if (p.arc >= junctions[j].arc - o.junction_before && p.arc <= junctions[j].arc + o.junction_after &&
                e > o.junction_tolerance)
              r.junction_ok[j] = 0;
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
