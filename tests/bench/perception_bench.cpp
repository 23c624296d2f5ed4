// The obstacle thread's hot path per HDL-64E revolution on the real KITTI
// scans (about 123 k points): alignment, smoothing + features, and the map
// update for PW, PS and PC with a terrain-class map, alone and together.
#include <benchmark/benchmark.h>

#include <array>
#include <memory>

#include "trailnav/perception/kitti.hpp"
#include "trailnav/perception/obstacle_pipeline.hpp"

namespace {

using namespace trailnav;
using namespace trailnav::perception;

struct Fixture {
  Fixture(FusionModel model) {
    ObstacleConfig config;
    config.model = model;
    pipeline = std::move(ObstaclePipeline::create(config, kitti_shape()).pipeline);
    std::vector<float> buffer;
    for (int i = 0; i < 2; ++i) {
      images.push_back(std::make_unique<velodyne::RangeImage>(kitti_shape()));
      const std::string path = "../shared/data/kitti/00000" + std::to_string(i) + ".bin";
      if (!load_kitti_scan(path, buffer, *images.back())) throw std::runtime_error("cannot read " + path);
    }
    // A terrain map whose cells mix street, dirt and grass.
    auto& g = terrain.grid();
    for (std::int32_t y = 0; y < g.size_y(); ++y) {
      for (std::int32_t x = 0; x < g.size_x(); ++x) {
        const float a = static_cast<float>((x * 7 + y * 3) % 10) / 10.0f;
        g.at({g.origin().x + x, g.origin().y + y}).set({a, 0.9f - a, 0.05f, 0.03f, 0.02f});
      }
    }
  }
  std::unique_ptr<ObstaclePipeline> pipeline;
  std::vector<std::unique_ptr<velodyne::RangeImage>> images;
  TerrainClassMap terrain;
};

void points_counter(benchmark::State& state, const Fixture& f) {
  state.counters["points"] = static_cast<double>(f.images[0]->points);
  state.counters["points_per_s"] = benchmark::Counter(static_cast<double>(state.iterations()) * f.images[0]->points,
                                                      benchmark::Counter::kIsRate);
}

void BM_Align(benchmark::State& state) {
  Fixture f(FusionModel::pc);
  PoseTrack poses(8);
  poses.push({-1'000'000, 0, 0, 0, 0.01, -0.02, 0.1});
  poses.push({200'000'000, 0.2, 0.01, 0, 0.012, -0.018, 0.12});
  std::size_t i = 0;
  for (auto _ : state) f.pipeline->align(*f.images[i++ % 2], &poses);
  points_counter(state, f);
}
BENCHMARK(BM_Align)->Unit(benchmark::kMillisecond);

void BM_Features(benchmark::State& state) {
  Fixture f(FusionModel::pc);
  std::size_t i = 0;
  for (auto _ : state) {
    state.PauseTiming();
    f.pipeline->align(*f.images[i++ % 2], nullptr);
    state.ResumeTiming();
    f.pipeline->features();
  }
  points_counter(state, f);
}
BENCHMARK(BM_Features)->Unit(benchmark::kMillisecond);

void BM_MapUpdate(benchmark::State& state) {
  Fixture f(static_cast<FusionModel>(state.range(0)));
  f.pipeline->align(*f.images[0], nullptr);
  f.pipeline->features();
  for (auto _ : state) f.pipeline->update_maps(&f.terrain);
  state.SetLabel(std::string(fusion_model_name(static_cast<FusionModel>(state.range(0)))));
  points_counter(state, f);
}
BENCHMARK(BM_MapUpdate)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

void BM_Revolution(benchmark::State& state) {
  Fixture f(static_cast<FusionModel>(state.range(0)));
  PoseTrack poses(8);
  poses.push({-1'000'000, 0, 0, 0, 0.01, -0.02, 0.1});
  poses.push({200'000'000, 0.2, 0.01, 0, 0.012, -0.018, 0.12});
  std::size_t i = 0;
  for (auto _ : state) f.pipeline->process(*f.images[i++ % 2], &poses, &f.terrain);
  state.SetLabel(std::string(fusion_model_name(static_cast<FusionModel>(state.range(0)))) + ": align + features + map");
  points_counter(state, f);
}
BENCHMARK(BM_Revolution)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
