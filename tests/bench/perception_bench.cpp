// The obstacle thread's hot path per HDL-64E revolution: alignment,
// smoothing + features, and the map update for PW, PS and PC with a
// terrain-class map, alone and together. Two sources (the first argument):
// 0 the real KITTI scans (about 123 k points), 1 simulated HDL-64E
// revolutions of the meadow-block scenario (tall grass, about 105 k points).
#include <benchmark/benchmark.h>

#include <array>
#include <filesystem>
#include <memory>
#include <stdexcept>

#include "obstacle_run.hpp"
#include "simulator.hpp"
#include "kitti_scans.hpp"
#include "trailnav/perception/kitti.hpp"
#include "trailnav/perception/ground_height.hpp"
#include "trailnav/perception/obstacle_pipeline.hpp"

namespace {

using namespace trailnav;
using namespace trailnav::perception;

using Images = std::vector<std::unique_ptr<velodyne::RangeImage>>;


// Two revolutions of a simulated HDL-64E in meadow-block, made once.
const Images& sim_images() {
  static const Images images = [] {
    const auto dir = std::filesystem::temp_directory_path() / "trailnav-perception-bench";
    sim::SimOptions o;
    o.scenario = "meadow-block";
    o.duration = 1.6;
    o.lidar = "HDL-64E";
    o.out = dir.string();
    const sim::SimReport made = sim::run_simulation(o);
    if (!made.error.empty()) throw std::runtime_error(made.error);
    Images out;
    eval::ObstacleRunOptions r;
    r.inputs = {dir.string()};
    r.score_every = 0;
    r.on_revolution = [&](const velodyne::RangeImage& image) {
      if (image.points > 50'000 && out.size() < 2) out.push_back(std::make_unique<velodyne::RangeImage>(image));
    };
    const eval::ObstacleRunReport report = eval::run_obstacles(r);
    if (!report.error.empty()) throw std::runtime_error(report.error);
    std::filesystem::remove_all(dir);
    if (out.size() < 2) throw std::runtime_error("the simulation gave fewer than two full revolutions");
    return out;
  }();
  return images;
}

struct Fixture {
  Fixture(int source, FusionModel model) {
    if (source == 0) {
      owned = bench::kitti_scans();
      for (auto& i : owned) images.push_back(i.get());
    } else {
      for (const auto& i : sim_images()) images.push_back(i.get());
    }
    ObstacleConfig config;
    config.model = model;
    pipeline = std::move(ObstaclePipeline::create(config, images[0]->shape()).pipeline);
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
  Images owned;
  std::vector<const velodyne::RangeImage*> images;
  TerrainClassMap terrain;
};

const char* source_name(std::int64_t source) { return source == 0 ? "KITTI" : "simulated meadow"; }

void points_counter(benchmark::State& state, const Fixture& f) {
  state.counters["points"] = static_cast<double>(f.images[0]->points);
  state.counters["points_per_s"] = benchmark::Counter(static_cast<double>(state.iterations()) * f.images[0]->points,
                                                      benchmark::Counter::kIsRate);
}

void BM_Align(benchmark::State& state) {
  Fixture f(static_cast<int>(state.range(0)), FusionModel::pc);
  PoseTrack poses(8);
  poses.push({-1'000'000, 0, 0, 0, 0.01, -0.02, 0.1});
  poses.push({200'000'000, 0.2, 0.01, 0, 0.012, -0.018, 0.12});
  std::size_t i = 0;
  for (auto _ : state) f.pipeline->align(*f.images[i++ % 2], &poses);
  state.SetLabel(source_name(state.range(0)));
  points_counter(state, f);
}
BENCHMARK(BM_Align)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

void BM_Features(benchmark::State& state) {
  Fixture f(static_cast<int>(state.range(0)), FusionModel::pc);
  std::size_t i = 0;
  for (auto _ : state) {
    state.PauseTiming();
    f.pipeline->align(*f.images[i++ % 2], nullptr);
    state.ResumeTiming();
    f.pipeline->features();
  }
  state.SetLabel(source_name(state.range(0)));
  points_counter(state, f);
}
BENCHMARK(BM_Features)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// The two stages of features() apart, on one aligned revolution: the
// smoothing, and the neighbour search with each kernel (second argument: 0
// the fastest, eight-wide where the CPU has AVX2; 1 four-wide; 2 the portable
// one-at-a-time search).
struct CloudFixture {
  explicit CloudFixture(int source) : fixture(source, FusionModel::pc) {
    const velodyne::RangeImage& image = *fixture.images[0];
    cloud = std::make_unique<RevolutionCloud>(CloudShape{image.rings(), image.shape().max_columns});
    CloudAligner aligner(config.mount, config.features);
    aligner.align(image, nullptr, *cloud);
  }
  Fixture fixture;
  ObstacleConfig config;
  std::unique_ptr<RevolutionCloud> cloud;
};

void BM_Smoothing(benchmark::State& state) {
  CloudFixture f(static_cast<int>(state.range(0)));
  // Reads the aligned coordinates, writes the smoothed ones: the same work each time.
  for (auto _ : state) smooth_rings(*f.cloud, f.config.features);
  state.SetLabel(source_name(state.range(0)));
  points_counter(state, f.fixture);
}
BENCHMARK(BM_Smoothing)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

void BM_FeatureSearch(benchmark::State& state) {
  CloudFixture f(static_cast<int>(state.range(0)));
  smooth_rings(*f.cloud, f.config.features);
  const auto kernel = state.range(1) == 0   ? FeatureKernel::fastest
                      : state.range(1) == 1 ? FeatureKernel::four_wide
                                            : FeatureKernel::portable;
  FeatureCounters counters;
  // Searching again finds the same: the states stay valid-like (measured, flat).
  for (auto _ : state) compute_features(*f.cloud, f.config.features, counters, kernel);
  const char* how = kernel == FeatureKernel::portable ? ", portable"
                    : kernel == FeatureKernel::fastest && wide_features_available() ? ", eight-wide (AVX2)"
                    : simd_features_available() ? ", four-wide" : ", portable";
  state.SetLabel(std::string(source_name(state.range(0))) + how);
  points_counter(state, f.fixture);
}
BENCHMARK(BM_FeatureSearch)->ArgsProduct({{0, 1}, {0, 1, 2}})->Unit(benchmark::kMillisecond);

// The height above the ground (ground_height.hpp) on one smoothed, featured
// revolution: the grid built (second argument 0), applied to the points (1),
// both (2). The steps it changes stay changed: the same work each time.
void BM_GroundHeight(benchmark::State& state) {
  CloudFixture f(static_cast<int>(state.range(0)));
  smooth_rings(*f.cloud, f.config.features);
  FeatureCounters counters;
  compute_features(*f.cloud, f.config.features, counters);
  GroundGrid ground(GroundParams{true}, f.config.features.max_range, f.cloud->x.size());
  std::vector<float> height(f.cloud->x.size());
  ground.build(*f.cloud);
  const auto what = state.range(1);
  for (auto _ : state) {
    if (what != 1) ground.build(*f.cloud);
    if (what != 0) ground.apply(*f.cloud, height);
    benchmark::ClobberMemory();
  }
  state.SetLabel(std::string(source_name(state.range(0))) + (what == 0 ? ", build" : what == 1 ? ", apply" : ", both"));
  points_counter(state, f.fixture);
}
BENCHMARK(BM_GroundHeight)->ArgsProduct({{0, 1}, {0, 1, 2}})->Unit(benchmark::kMillisecond);

void BM_MapUpdate(benchmark::State& state) {
  Fixture f(static_cast<int>(state.range(0)), static_cast<FusionModel>(state.range(1)));
  f.pipeline->align(*f.images[0], nullptr);
  f.pipeline->features();
  for (auto _ : state) f.pipeline->update_maps(&f.terrain);
  state.SetLabel(std::string(source_name(state.range(0))) + ", " +
                 std::string(fusion_model_name(static_cast<FusionModel>(state.range(1)))));
  points_counter(state, f);
}
BENCHMARK(BM_MapUpdate)->ArgsProduct({{0, 1}, {0, 1, 2}})->Unit(benchmark::kMillisecond);

// The snapshot the obstacle task publishes after every revolution: the whole
// map as 0-100 / -1 (nav_msgs/OccupancyGrid's data).
void BM_ExportOccupancy(benchmark::State& state) {
  Fixture f(0, FusionModel::pc);
  f.pipeline->align(*f.images[0], nullptr);
  f.pipeline->features();
  f.pipeline->update_maps(&f.terrain);
  const ObstacleMap& map = f.pipeline->map();
  std::vector<std::int8_t> out(static_cast<std::size_t>(map.grid().size_x()) * static_cast<std::size_t>(map.grid().size_y()));
  for (auto _ : state) {
    map.export_occupancy(out);
    benchmark::DoNotOptimize(out.data());
  }
  state.counters["cells"] = static_cast<double>(out.size());
}
BENCHMARK(BM_ExportOccupancy)->Unit(benchmark::kMillisecond);

void BM_Revolution(benchmark::State& state) {
  Fixture f(static_cast<int>(state.range(0)), static_cast<FusionModel>(state.range(1)));
  PoseTrack poses(8);
  poses.push({-1'000'000, 0, 0, 0, 0.01, -0.02, 0.1});
  poses.push({200'000'000, 0.2, 0.01, 0, 0.012, -0.018, 0.12});
  std::size_t i = 0;
  for (auto _ : state) f.pipeline->process(*f.images[i++ % 2], &poses, &f.terrain);
  state.SetLabel(std::string(source_name(state.range(0))) + ", " +
                 std::string(fusion_model_name(static_cast<FusionModel>(state.range(1)))) + ": align + features + map");
  points_counter(state, f);
}
BENCHMARK(BM_Revolution)->ArgsProduct({{0, 1}, {0, 1, 2}})->Unit(benchmark::kMillisecond);

// The same revolution taken as trailnavd takes it while it arrives: begun,
// advanced in `steps` equal parts, finished (the same maps, test
// ObstacleStreaming.*): what the blocks cost over the whole at once.
void BM_RevolutionInSteps(benchmark::State& state) {
  Fixture f(static_cast<int>(state.range(0)), FusionModel::pw);
  PoseTrack poses(8);
  poses.push({-1'000'000, 0, 0, 0, 0.01, -0.02, 0.1});
  poses.push({200'000'000, 0.2, 0.01, 0, 0.012, -0.018, 0.12});
  const auto steps = static_cast<int>(state.range(1));
  std::size_t i = 0;
  for (auto _ : state) {
    const velodyne::RangeImage& image = *f.images[i++ % 2];
    f.pipeline->begin(image, &poses, &f.terrain);
    for (int s = 1; s < steps; ++s) f.pipeline->advance(image, &poses, image.columns() * s / steps);
    f.pipeline->finish(image, &poses);
  }
  state.SetLabel(std::string(source_name(state.range(0))) + ", PW, " + std::to_string(steps) + " steps");
  points_counter(state, f);
}
BENCHMARK(BM_RevolutionInSteps)->ArgsProduct({{0, 1}, {1, 10}})->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
