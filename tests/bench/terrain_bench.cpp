// The terrain thread's hot paths (thesis §7.2) on real HDL-64E data (the
// KITTI scans): registering a revolution into the 300 x 300 grid, one
// classification step (features + forest + Bayes update of every cell with
// enough points) over a map filled by several revolutions, and the forest
// alone per cell with the shipped model.
#include <benchmark/benchmark.h>

#include <array>
#include <cmath>
#include <memory>
#include <random>
#include <stdexcept>
#include <vector>

#include "kitti_scans.hpp"
#include "trailnav/perception/kitti.hpp"
#include "trailnav/perception/random_forest.hpp"
#include "trailnav/perception/terrain_mapper.hpp"

namespace {

using namespace trailnav;
using namespace trailnav::perception;

const RandomForest& model() {
  static const RandomForest forest = [] {
    auto m = RandomForest::load("board/models/terrain-sim.tnrf");
    if (!m.forest) throw std::runtime_error(m.error);
    return std::move(*m.forest);
  }();
  return forest;
}


MountParams kitti_mount() {
  MountParams m;
  m.translation = {0.0, 0.0, 1.73};
  return m;
}

// Times one step of `mapper`, each time from `filled`'s state.
void time_steps(benchmark::State& state, const TerrainMapper& filled, TerrainMapper& mapper) {
  std::uint64_t features = 0;
  for (auto _ : state) {
    state.PauseTiming();
    mapper.copy_state_from(filled);
    const std::uint64_t before = mapper.counters().features;
    state.ResumeTiming();
    mapper.step(1'000'000'000);
    benchmark::DoNotOptimize(mapper.map().grid().at(mapper.map().grid().origin()));
    features = mapper.counters().features - before;
  }
  state.counters["cells_classified"] = static_cast<double>(features);
}

void BM_TerrainRegisterRevolution(benchmark::State& state) {
  const auto images = bench::kitti_scans();
  auto mapper = std::move(TerrainMapper::create(TerrainConfig{}, kitti_mount(), kitti_shape(), &model()).mapper);
  std::size_t i = 0;
  for (auto _ : state) {
    mapper->align(*images[i++ % 2], nullptr);
    mapper->register_cloud();
  }
  state.counters["points"] = static_cast<double>(mapper->counters().points) / static_cast<double>(state.iterations());
}
BENCHMARK(BM_TerrainRegisterRevolution)->Unit(benchmark::kMillisecond);

// One step after `revolutions` KITTI revolutions were registered (0.5 m
// apart at the thesis' 1.2 m/s that is about four; twenty is a robot standing
// still for max_step_interval, 2 s, the most a real step gathers).
void BM_TerrainStep(benchmark::State& state) {
  const auto images = bench::kitti_scans();
  TerrainConfig config;
  auto filled = std::move(TerrainMapper::create(config, kitti_mount(), kitti_shape(), &model()).mapper);
  auto mapper = std::move(TerrainMapper::create(config, kitti_mount(), kitti_shape(), &model()).mapper);
  filled->align(*images[0], nullptr);
  filled->register_cloud();
  filled->step(0);  // opens the interval
  for (int r = 0; r < state.range(0); ++r) {
    filled->align(*images[static_cast<std::size_t>(r % 2)], nullptr);
    filled->register_cloud();
  }
  time_steps(state, *filled, *mapper);
}
BENCHMARK(BM_TerrainStep)->Arg(1)->Arg(4)->Arg(20)->Unit(benchmark::kMillisecond);

// Fills cells with 20 points each (random surfaces and remissions): every
// cell of the grid, or (`reachable`) every cell the lidar can have reached
// since the last step: within max_range of where the robot was, at most one
// step's travel (d) from where it is.
void fill_cells(TerrainMapper& mapper, const TerrainConfig& config, bool reachable) {
  mapper.step(0);
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> u(-0.1f, 0.1f);
  auto& g = mapper.work();
  const WorldPoint centre = g.cell_center({g.origin().x + g.size_x() / 2, g.origin().y + g.size_y() / 2});  // the robot
  const double radius = static_cast<double>(config.max_range) + static_cast<double>(config.step_distance);
  for (std::int32_t y = 0; y < g.size_y(); ++y) {
    for (std::int32_t x = 0; x < g.size_x(); ++x) {
      const CellIndex i{g.origin().x + x, g.origin().y + y};
      const WorldPoint c = g.cell_center(i);
      if (reachable && std::hypot(c.x - centre.x, c.y - centre.y) > radius) continue;
      CellStats& s = g.at(i).stats;
      const float tilt = u(rng) * 5.0f, base = 100.0f + 200.0f * (u(rng) + 0.1f);
      for (int k = 0; k < 20; ++k) {
        const float px = u(rng), py = u(rng);
        s.add(px, py, tilt * px + 0.05f * u(rng), base + 60.0f * u(rng));
      }
    }
  }
}

// The worst cases: every cell the lidar can reach, and every one of the
// 90 000 cells (the corners lie beyond max_range and never get points).
void BM_TerrainStepEveryCell(benchmark::State& state) {
  TerrainConfig config;
  auto filled = std::move(TerrainMapper::create(config, kitti_mount(), kitti_shape(), &model()).mapper);
  auto mapper = std::move(TerrainMapper::create(config, kitti_mount(), kitti_shape(), &model()).mapper);
  fill_cells(*filled, config, state.range(0) == 1);
  time_steps(state, *filled, *mapper);
}
BENCHMARK(BM_TerrainStepEveryCell)->ArgName("reachable_only")->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond);

void BM_ForestPerCell(benchmark::State& state) {
  const RandomForest& forest = model();
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<FeatureVector> cells(4096);
  for (FeatureVector& f : cells) f = {20.0f + 40.0f * u(rng), 15.0f + 30.0f * u(rng), 2.0f + 8.0f * u(rng), 2e-3f * u(rng) * u(rng), 90.0f * u(rng) * u(rng), 3.0f + 12.0f * u(rng)};
  ClassDistribution out;
  std::size_t i = 0;
  for (auto _ : state) {
    forest.predict(cells[i++ & 4095], out);
    benchmark::DoNotOptimize(out);
  }
  state.counters["trees"] = static_cast<double>(forest.trees());
}
BENCHMARK(BM_ForestPerCell);

void BM_TerrainFeaturePerCell(benchmark::State& state) {
  std::mt19937 rng(6);
  std::uniform_real_distribution<float> u(-0.1f, 0.1f);
  std::vector<CellStats> cells(1024);
  for (CellStats& c : cells) {
    for (int k = 0; k < 20; ++k) c.add(u(rng), u(rng), 0.3f * u(rng), 30.0f + 100.0f * u(rng));
  }
  // Four cells per call, as the classification step computes them.
  std::array<FeatureVector, 4> out;
  std::size_t i = 0;
  for (auto _ : state) {
    compute_terrain_features({&cells[i & 1023], &cells[(i + 1) & 1023], &cells[(i + 2) & 1023], &cells[(i + 3) & 1023]},
                             out);
    benchmark::DoNotOptimize(out);
    i += 4;
  }
  state.counters["per_cell"] = benchmark::Counter(4.0 * static_cast<double>(state.iterations()),
                                                  benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_TerrainFeaturePerCell);

}  // namespace

BENCHMARK_MAIN();
