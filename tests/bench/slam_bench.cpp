// Pose-graph solves side by side in one process (pin it: taskset -c 1):
// trailnav's exact Levenberg–Marquardt, trailnav's SMF with parts of 500,
// and Ceres Solver on the same graphs — the thesis' own (../shared/data/g2o)
// and a generated Manhattan world of 20,000 poses. Each iteration solves a
// fresh copy of the graph from its file's guess. Memory is measured apart
// (toolchain/slam-side-by-side.sh: one process per solver).
#include <benchmark/benchmark.h>

#include <cstdio>
#include <map>
#include <string>

#include "ceres_pose_graph.hpp"
#include "trailnav/navigation/slam/arena.hpp"
#include "trailnav/navigation/slam/g2o_io.hpp"
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

BENCHMARK(BM_Exact)->DenseRange(0, 4)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Smf)->DenseRange(0, 4)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Ceres)->DenseRange(0, 4)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
