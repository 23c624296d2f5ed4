// Navigation hot paths on one core: one subgoal-alignment update (thesis
// §8.4.4: 8.3 ms with 1,000 samples and K = 4, 62 ms with 50,000; our goals
// 0.4 ms and 12 ms) on a full terrain map, and A* on the real Liechtenstein
// network.
#include <benchmark/benchmark.h>

#include <cmath>
#include <random>

#include "trailnav/navigation/osm/road_graph.hpp"
#include "trailnav/navigation/osm/router.hpp"
#include "trailnav/navigation/subgoals/subgoal_aligner.hpp"

namespace {

using namespace trailnav;

// A 300 x 300 map at 0.2 m: a 3 m dirt track curving through grass, every cell known.
const perception::TerrainClassMap& track_map() {
  static perception::TerrainClassMap map = [] {
    perception::TerrainClassMap m;
    auto& grid = m.grid();
    grid.move_to(20.0, 0.0);
    const CellIndex o = grid.origin();
    for (std::int32_t y = o.y; y < o.y + grid.size_y(); ++y) {
      for (std::int32_t x = o.x; x < o.x + grid.size_x(); ++x) {
        const auto c = grid.cell_center({x, y});
        const double centre = 3.0 * std::sin(c.x / 15.0);
        std::array<float, perception::kTerrainClasses> p{0.05f, 0.1f, 0.7f, 0.1f, 0.05f};
        if (std::abs(c.y - centre) < 1.5) p = {0.1f, 0.7f, 0.1f, 0.05f, 0.05f};
        grid.at({x, y}).set(p);
      }
    }
    return m;
  }();
  return map;
}

void BM_AlignmentUpdate(benchmark::State& state) {
  subgoals::AlignerConfig c;
  c.samples = static_cast<std::size_t>(state.range(0));
  c.sequence = static_cast<int>(state.range(1));
  const auto& map = track_map();
  subgoals::SubgoalAligner aligner(c, map.shape());
  // 12 subgoals aligned, 4 more of the route ahead; with a third argument
  // of 1 the route turns left at subgoal 10, inside the window, so every
  // sample also moves the corner and scores the route beyond the window.
  const bool corner = state.range(2) != 0;
  std::vector<subgoals::Vec2> raw;
  for (int i = 0; i < 16; ++i) raw.push_back(corner && i > 10 ? subgoals::Vec2{40.0, 4.0 * (i - 10)} : subgoals::Vec2{4.0 * i, 1.0});
  for (std::size_t i = 0; i < 12; ++i) {
    aligner.push(raw);
    aligner.update(map, raw);
  }
  for (auto _ : state) {
    aligner.update(map, raw);
    benchmark::DoNotOptimize(aligner.estimate(aligner.count() - 1));
  }
  state.counters["cells"] = static_cast<double>(aligner.counters().cells_summed);
  state.counters["n_eff"] = aligner.counters().last_neff;
}
BENCHMARK(BM_AlignmentUpdate)
    ->Args({1000, 4, 0})->Args({10000, 4, 0})->Args({50000, 4, 0})->Args({1000, 1, 0})->Args({1000, 6, 0})
    ->Args({50000, 6, 0})->Args({1000, 4, 1})->Args({50000, 4, 1})
    ->Unit(benchmark::kMicrosecond);

void BM_RouteLiechtenstein(benchmark::State& state) {
  static const auto loaded = osm::load_road_graph("../shared/data/osm/osm2pgsql_liechtenstein-2013-08-03.osm.pbf");
  if (!loaded.graph) {
    state.SkipWithError(loaded.error.c_str());
    return;
  }
  const osm::RoadGraph& g = *loaded.graph;
  osm::Router router(g);
  std::vector<osm::Point2> path;
  router.reserve_path(path);
  std::mt19937_64 rng(11);
  std::uniform_int_distribution<std::size_t> pick(0, g.vertex_count() - 1);
  std::vector<std::pair<osm::RoadProjection, osm::RoadProjection>> pairs;
  for (int i = 0; i < 64; ++i) {
    const auto& a = g.vertices()[pick(rng)];
    const auto& b = g.vertices()[pick(rng)];
    pairs.emplace_back(*g.project(a.x, a.y), *g.project(b.x, b.y));
  }
  const auto algorithm = state.range(0) ? osm::Router::Algorithm::astar : osm::Router::Algorithm::dijkstra;
  std::size_t i = 0, expanded = 0;
  for (auto _ : state) {
    const auto& [from, to] = pairs[i++ % pairs.size()];
    expanded += router.route(from, to, path, algorithm).expanded;
  }
  state.counters["expanded"] = benchmark::Counter(static_cast<double>(expanded), benchmark::Counter::kAvgIterations);
}
BENCHMARK(BM_RouteLiechtenstein)->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
