// Pose-graph solves side by side in one process (pin it: taskset -c 1):
// trailnav's exact Levenberg–Marquardt, trailnav's SMF with parts of 500,
// and Ceres Solver on the same graphs — the thesis' own (../shared/data/g2o)
// and a generated Manhattan world of 20,000 poses. Each iteration solves a
// fresh copy of the graph from its file's guess. Memory is measured apart
// (toolchain/slam-side-by-side.sh: one process per solver).
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <random>
#include <string>

#include "ceres_pose_graph.hpp"
#include "trailnav/navigation/slam/arena.hpp"
#include "trailnav/navigation/slam/g2o_io.hpp"
#include "trailnav/navigation/slam/keyframes.hpp"
#include "trailnav/navigation/slam/lm_solver.hpp"
#include "trailnav/navigation/slam/manhattan.hpp"
#include "trailnav/navigation/slam/smf.hpp"

namespace {

using namespace trailnav;
using namespace trailnav::slam;

const char* const kGraphs[] = {"se-sync_intel_suger.g2o", "se-sync_ETHCampus_suger.g2o", "se-sync_m3500.g2o",
                               "se-sync_sphere2500.g2o", "manhattan-20000"};
constexpr GraphCapacity kCapacity{25000, 100000};

const G2oGraph& graph(int i) {
  static std::map<int, G2oGraph> cache;
  auto it = cache.find(i);
  if (it != cache.end()) return it->second;
  G2oGraph& g = cache[i];
  const std::string name = kGraphs[i];
  if (name == "manhattan-20000") {
    g.kind = GraphKind::planar;
    g.planar.reserve(kCapacity);
    ManhattanOptions o;
    o.nodes = 20000;
    generate_manhattan(o, g.planar);
  } else {
    const G2oReadResult r = read_g2o_file("../shared/data/g2o/" + name, kCapacity, g);
    if (!r.ok) std::fprintf(stderr, "%s\n", r.error.c_str());
  }
  return g;
}

template <class Pose>
PoseGraph<Pose>& pick(G2oGraph& g);
template <>
PoseGraph<Se2>& pick<Se2>(G2oGraph& g) { return g.planar; }
template <>
PoseGraph<Se3>& pick<Se3>(G2oGraph& g) { return g.spatial; }

template <class Pose>
void exact(benchmark::State& state, int i) {
  Arena arena(1u << 30);
  LmSolver<Pose> solver(kCapacity, arena);
  double chi2 = 0.0;
  for (auto _ : state) {
    state.PauseTiming();
    G2oGraph g = graph(i);
    state.ResumeTiming();
    chi2 = solver.solve(pick<Pose>(g), LmOptions{}).chi2;
  }
  state.counters["chi2"] = chi2;
  state.counters["solver_MiB"] = static_cast<double>(arena.high_water()) / 1048576.0;
}

template <class Pose>
void smf(benchmark::State& state, int i) {
  Arena arena(256u << 20);
  SmfSolver<Pose> solver(kCapacity, SmfOptions{}, arena);
  double chi2 = 0.0;
  for (auto _ : state) {
    state.PauseTiming();
    G2oGraph g = graph(i);
    state.ResumeTiming();
    chi2 = solver.solve(pick<Pose>(g)).chi2;
  }
  state.counters["chi2"] = chi2;
  state.counters["solver_MiB"] = static_cast<double>(arena.high_water()) / 1048576.0;
}

void ceres_solve(benchmark::State& state, int i) {
  double chi2 = 0.0;
  for (auto _ : state) {
    state.PauseTiming();
    G2oGraph g = graph(i);
    state.ResumeTiming();
    chi2 = bench::solve_with_ceres(g).chi2;
  }
  state.counters["chi2"] = chi2;
}

void BM_Exact(benchmark::State& state) {
  const int i = static_cast<int>(state.range(0));
  state.SetLabel(kGraphs[i]);
  if (graph(i).kind == GraphKind::spatial) {
    exact<Se3>(state, i);
  } else {
    exact<Se2>(state, i);
  }
}
void BM_Smf(benchmark::State& state) {
  const int i = static_cast<int>(state.range(0));
  state.SetLabel(kGraphs[i]);
  if (graph(i).kind == GraphKind::spatial) {
    smf<Se3>(state, i);
  } else {
    smf<Se2>(state, i);
  }
}
void BM_Ceres(benchmark::State& state) {
  const int i = static_cast<int>(state.range(0));
  state.SetLabel(kGraphs[i]);
  ceres_solve(state, i);
}

// The online map's re-solve (trailnavd's mapping task): a drive through a
// grid of streets (2 m/s, a turn at some crossings), keyframes every 2 m,
// a fix each second with the simulator's receiver error (0.3 m white, a 3 m
// bias wandering over 120 s) and its bias vertex; the graph is optimised
// with five keyframes to go, the five are added from the odometry, and each
// iteration solves that graph: what the task does every optimize_period_s.
// Simulated data.
struct OnlineMap {
  KeyframeGraph graph;
  explicit OnlineMap(std::size_t keyframes) : graph(options(keyframes)) {}
  static KeyframeOptions options(std::size_t keyframes) {
    KeyframeOptions o;
    o.max_keyframes = keyframes;
    o.gps_white_sigma = 1.5;
    return o;
  }
};

const PoseGraph2d& online_map(std::size_t keyframes) {
  static std::map<std::size_t, std::unique_ptr<OnlineMap>> cache;
  auto& slot = cache[keyframes];
  if (slot) return slot->graph.graph();
  slot = std::make_unique<OnlineMap>(keyframes);
  KeyframeGraph& kf = slot->graph;
  std::mt19937_64 rng(3);
  std::normal_distribution<double> unit(0.0, 1.0);
  std::uniform_int_distribution<int> turn(0, 3);
  const double dt = 0.1, speed = 2.0, block = 50.0, bias_sigma = 3.0, tau = 120.0;
  double bx = bias_sigma * unit(rng), by = bias_sigma * unit(rng), along = 0.0;
  Se2 truth{}, odometry{};
  Arena part_arena(smf_part_arena_bytes(3, 500));
  SmfSolver<Se2> solver(kf.capacity(), SmfOptions{}, part_arena);
  bool solved = false;
  for (std::int64_t step = 1; kf.keyframe_count() < keyframes; ++step) {
    along += speed * dt;
    double heading_change = 0.0;
    if (along >= block) {  // a crossing: straight on, left or right
      along -= block;
      const int t = turn(rng);
      heading_change = t == 1 ? M_PI / 2 : (t == 2 ? -M_PI / 2 : 0.0);
    }
    const Se2 motion{speed * dt, 0.0, heading_change};
    truth = truth * motion;
    odometry = odometry * Se2{motion.x * (1.0 + 0.01 * unit(rng)), 0.0, motion.theta + 0.0005 * dt + 0.001 * unit(rng)};
    kf.on_odometry(odometry);
    if (step % 10 == 0) {
      const double a = std::exp(-1.0 / tau), q = bias_sigma * std::sqrt(1.0 - a * a);
      bx = a * bx + q * unit(rng);
      by = a * by + q * unit(rng);
      GpsMeasurement m;
      m.x = truth.x + bx + 0.3 * unit(rng);
      m.y = truth.y + by + 0.3 * unit(rng);
      m.sigma = std::hypot(0.3, bias_sigma);
      m.time_ns = step * 100'000'000;
      m.odometry = odometry;
      kf.on_gps(m);
    }
    if (!solved && kf.keyframe_count() + 5 >= keyframes) {
      solver.solve(kf.graph());
      solved = true;
    }
  }
  return kf.graph();
}

void BM_OnlineMapResolve(benchmark::State& state) {
  const auto keyframes = static_cast<std::size_t>(state.range(0));
  const PoseGraph2d& map = online_map(keyframes);
  Arena part_arena(smf_part_arena_bytes(3, 500));
  SmfSolver<Se2> solver(OnlineMap(keyframes).graph.capacity(), SmfOptions{}, part_arena);
  SmfReport r;
  for (auto _ : state) {
    state.PauseTiming();
    PoseGraph2d g = map;
    state.ResumeTiming();
    r = solver.solve(g);
  }
  state.counters["vertices"] = static_cast<double>(map.vertex_count());
  state.counters["levels"] = r.levels;
  state.counters["iterations"] = r.iterations;
}

BENCHMARK(BM_OnlineMapResolve)->Arg(1000)->Arg(2500)->Arg(5000)->Unit(benchmark::kMillisecond);

BENCHMARK(BM_Exact)->DenseRange(0, 4)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Smf)->DenseRange(0, 4)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Ceres)->DenseRange(0, 4)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
