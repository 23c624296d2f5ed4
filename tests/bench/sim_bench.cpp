// The simulator's hot path: ray casting an HDL-64E-like fan of rays against
// the built-in worlds, and a whole simulated HDL-64E second.
#include <benchmark/benchmark.h>

#include <cmath>
#include <filesystem>
#include <numbers>

#include "motion.hpp"
#include "roads.hpp"
#include "scenario.hpp"
#include "simulator.hpp"
#include "world.hpp"

namespace {

using namespace trailnav::sim;

void cast_fan(benchmark::State& state, const char* scenario) {
  const Scenario s = *load_scenario(scenario).scenario;
  const RoadNetwork roads = *build_roads(s, 1).roads;
  const auto world = World::build(s, roads, 1);
  const Vec2 start = roads.route.at(10.0);
  const Vec3 origin(start.x(), start.y(), world->ground(start.x(), start.y()) + 1.9);
  // 64 elevations from +2 to -24.8 degrees, as the HDL-64E.
  std::vector<double> elevation;
  for (int i = 0; i < 64; ++i) elevation.push_back((2.0 - 26.8 * i / 63.0) * std::numbers::pi / 180.0);
  std::uint64_t key = 0;
  double azimuth = 0.0;
  std::int64_t rays = 0, hits = 0;
  for (auto _ : state) {
    for (double e : elevation) {
      const Vec3 d(std::cos(e) * std::cos(azimuth), std::cos(e) * std::sin(azimuth), std::sin(e));
      const Hit h = world->cast(origin, d, 0.9, 120.0, ++key);
      hits += h.hit ? 1 : 0;
      ++rays;
    }
    azimuth += 0.0031;
  }
  state.counters["rays_per_s"] = benchmark::Counter(static_cast<double>(rays), benchmark::Counter::kIsRate);
  state.counters["hit_fraction"] = static_cast<double>(hits) / static_cast<double>(std::max<std::int64_t>(rays, 1));
}

void BM_CastHdl64eFanUrban(benchmark::State& state) { cast_fan(state, "urban"); }
void BM_CastHdl64eFanForest(benchmark::State& state) { cast_fan(state, "forest-track"); }
void BM_CastHdl64eFanMeadow(benchmark::State& state) { cast_fan(state, "meadow-block"); }
BENCHMARK(BM_CastHdl64eFanUrban);
BENCHMARK(BM_CastHdl64eFanForest);
BENCHMARK(BM_CastHdl64eFanMeadow);

// One simulated second of the forest track with an HDL-64E: everything the
// simulator does (world, motion, all sensors, files). Real time is <= 1 s.
void BM_SimulateForestHdl64eOneSecond(benchmark::State& state) {
  const auto dir = std::filesystem::temp_directory_path() / "trailnav-sim-bench";
  for (auto _ : state) {
    SimOptions o;
    o.scenario = "forest-track";
    o.duration = 1.0;
    o.lidar = "HDL-64E";
    o.out = dir.string();
    const SimReport r = run_simulation(o);
    if (!r.error.empty()) state.SkipWithError(r.error.c_str());
    state.counters["lidar_realtime_factor"] = r.sim_seconds / r.lidar_seconds;
  }
  std::filesystem::remove_all(dir);
}
BENCHMARK(BM_SimulateForestHdl64eOneSecond)->Unit(benchmark::kMillisecond)->Iterations(3);

}  // namespace
BENCHMARK_MAIN();
