// The terrain thread's hot paths (thesis §7.2) on real HDL-64E data (the
// KITTI scans): registering a revolution into the 300 x 300 grid, one
// classification step (features + forest + Bayes update of every cell with
// enough points) over a map filled by several revolutions, and the forest
// alone per cell with the shipped model.
#include <benchmark/benchmark.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <memory>
#include <random>
#include <stdexcept>
#include <vector>

#include "kitti_scans.hpp"
#include "trailnav/perception/kitti.hpp"
#include "trailnav/perception/random_forest.hpp"
#include "trailnav/perception/terrain_mapper.hpp"
#include "trailnav/perception/trav_layer.hpp"
#include "trailnav/perception/trav_model_file.hpp"
#include "trailnav/perception/trav_online.hpp"
#include "trailnav/perception/trav_recorder.hpp"
#include "trailnav/runtime/atomic_file.hpp"

namespace {

using namespace trailnav;
using namespace trailnav::perception;
namespace trav = trailnav::perception::trav;

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

// A mapper whose interval was opened by one KITTI revolution and which then
// registered `revolutions` more (the state a step starts from).
std::unique_ptr<TerrainMapper> filled_mapper(const TerrainConfig& config, int revolutions) {
  const auto images = bench::kitti_scans();
  auto filled = std::move(TerrainMapper::create(config, kitti_mount(), kitti_shape(), &model()).mapper);
  filled->align(*images[0], nullptr);
  filled->register_cloud();
  filled->step(0);  // opens the interval
  for (int r = 0; r < revolutions; ++r) {
    filled->align(*images[static_cast<std::size_t>(r % 2)], nullptr);
    filled->register_cloud();
  }
  return filled;
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
  TerrainConfig config;
  auto filled = filled_mapper(config, static_cast<int>(state.range(0)));
  auto mapper = std::move(TerrainMapper::create(config, kitti_mount(), kitti_shape(), &model()).mapper);
  time_steps(state, *filled, *mapper);
}
BENCHMARK(BM_TerrainStep)->Arg(1)->Arg(4)->Arg(20)->Unit(benchmark::kMillisecond);

// The traversability's share of a step (docs/traversability.md): the same
// step as BM_TerrainStep/4, with the recorder taking every cell's sums (its
// feature from the terrain's, its word, the local map's entry).
void BM_TravStep(benchmark::State& state) {
  TerrainConfig config;
  auto filled = filled_mapper(config, 4);
  auto mapper = std::move(TerrainMapper::create(config, kitti_mount(), kitti_shape(), &model()).mapper);
  const trav::Vocabulary vocabulary{trav::VocabularyConfig{}};
  trav::RecorderConfig rc;
  rc.max_words = 200'000;
  trav::TravRecorder recorder(rc, vocabulary, config.map.size_x, config.map.size_y, config.map.resolution);
  recorder.drive(0.0, 0.0, 0.0);
  mapper->set_sums_sink(&recorder);
  trav::WordCounts counts(vocabulary.size());
  std::uint64_t words = 0;
  for (auto _ : state) {
    state.PauseTiming();
    mapper->copy_state_from(*filled);
    const std::uint64_t before = recorder.counters().words;
    state.ResumeTiming();
    mapper->step(1'000'000'000);
    words = recorder.counters().words - before;
    state.PauseTiming();
    recorder.finish_local_map(counts);
    state.ResumeTiming();
  }
  state.counters["words"] = static_cast<double>(words);
}
BENCHMARK(BM_TravStep)->Unit(benchmark::kMillisecond);

// The traversability's own work in one step, apart from the terrain's
// (whose time this noisy machine varies by more than the difference): the
// cells a real step over four KITTI revolutions handed over (their sums and
// terrain features, captured once), given to the recorder (feature, word,
// entry), to the layer (feature, word, the word into its cell's evidence
// for eight terrain models and POS) or to both, as the terrain thread does.
void BM_TravWords(benchmark::State& state) {
  TerrainConfig config;
  auto mapper = filled_mapper(config, 4);
  struct Handed {
    CellIndex cell;
    CellStats sums;
    FeatureVector feature;
    bool has_feature;
    double x, y;
  };
  struct Capture final : CellSumsSink {
    std::vector<Handed> cells;
    void cell_sums(CellIndex c, const CellStats& s, const FeatureVector* f, double x, double y) noexcept override {
      cells.push_back({c, s, f != nullptr ? *f : FeatureVector{}, f != nullptr, x, y});
    }
  } capture;
  mapper->set_sums_sink(&capture);
  mapper->step(1'000'000'000);
  const trav::Vocabulary vocabulary{trav::VocabularyConfig{}};
  trav::RecorderConfig rc;
  rc.max_words = 200'000;
  trav::TravRecorder recorder(rc, vocabulary, config.map.size_x, config.map.size_y, config.map.resolution);
  recorder.drive(0.0, 0.0, 0.0);
  // Eight terrain models, each word in use.
  trav::TravModels models(vocabulary, trav::LearnerConfig{});
  std::vector<trav::WordCounts> counts;
  for (std::uint32_t m = 0; m < 8; ++m) {
    counts.emplace_back(vocabulary.size());
    for (std::uint32_t w = 0; w < vocabulary.size(); ++w) counts.back().add(w, (w + m) % 3 == 0, 1 + (w * 7 + m) % 13);
  }
  models.set_models(counts);
  auto layer = trav::TravLayer::create(models, trav::Method::pnb, 20.0, 20.0, config.map.size_x, config.map.size_y,
                                       config.map.resolution);
  if (!layer.layer) throw std::runtime_error(layer.error);
  layer.layer->move_to(0.0, 0.0);
  // mode 0: the recorder alone; 1: trailnavd's demonstration mode, recorder
  // and layer behind TravOnline (one ground and word per cell for both);
  // 2: the layer alone (the robot classifying, no demonstration).
  const auto mode = state.range(0);
  trav::WordCounts scratch(vocabulary.size());
  Mailbox<trav::LocalMapWords> local_maps(vocabulary.size());
  trav::TravOnline online(*layer.layer, &recorder, &local_maps);
  CellSumsSink* sink = mode == 0 ? static_cast<CellSumsSink*>(&recorder)
                       : mode == 1 ? static_cast<CellSumsSink*>(&online)
                                   : static_cast<CellSumsSink*>(layer.layer.get());
  for (auto _ : state) {
    for (const Handed& h : capture.cells) sink->cell_sums(h.cell, h.sums, h.has_feature ? &h.feature : nullptr, h.x, h.y);
    state.PauseTiming();
    recorder.finish_local_map(scratch);
    state.ResumeTiming();
  }
  state.counters["cells"] = static_cast<double>(capture.cells.size());
  state.counters["models"] = static_cast<double>(models.models());
}
BENCHMARK(BM_TravWords)->ArgName("mode")->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

// The demonstration task's work per local map (trailnavd's `demonstration`
// task, docs/traversability.md "On the robot"): a local map of 60 000 words
// (20 m of driving: 40 steps of about 1 500 cells) with 2 % positives,
// trained into models that already hold `models` terrain models (the χ²
// test against each, the merge, the tables recomputed), then (`save`) the
// model serialised and written with AtomicFile to /tmp (fsync included:
// the disk's speed, not the CPU's, decides that part).
void BM_TravTrainLocalMap(benchmark::State& state) {
  const trav::Vocabulary vocabulary{trav::VocabularyConfig{}};
  trav::LearnerConfig lc;
  lc.max_models = 8;
  trav::TravModels start(vocabulary, lc);
  std::mt19937 rng(6);
  const auto held = static_cast<std::uint32_t>(state.range(0));
  std::vector<trav::WordCounts> counts;
  for (std::uint32_t m = 0; m < held; ++m) {
    counts.emplace_back(vocabulary.size());
    std::uniform_int_distribution<std::uint32_t> word(m * 200, m * 200 + 400);
    for (int k = 0; k < 60'000; ++k) counts.back().add(word(rng) % vocabulary.size(), k % 50 == 0);
  }
  start.set_models(counts);
  trav::WordCounts local(vocabulary.size());
  std::uniform_int_distribution<std::uint32_t> word(0, 600);
  for (int k = 0; k < 60'000; ++k) local.add(word(rng), k % 50 == 0);
  const bool save = state.range(1) != 0;
  const AtomicFile file((std::filesystem::temp_directory_path() / "trailnav-bench-trav.tntrav").string());
  std::vector<std::uint8_t> bytes;
  bytes.reserve(trav::trav_model_bound(8, vocabulary.size(), lc.max_models));
  trav::TravModels models = start;
  for (auto _ : state) {
    state.PauseTiming();
    models = start;
    state.ResumeTiming();
    benchmark::DoNotOptimize(models.train(local));
    if (save) {
      trav::serialize_trav_models("bench", models, bytes);
      if (file.write(bytes) != 0) throw std::runtime_error("cannot write " + file.path());
    }
  }
  state.counters["models"] = static_cast<double>(models.models());
  if (save) state.counters["bytes"] = static_cast<double>(bytes.size());
  std::filesystem::remove(file.path());
}
BENCHMARK(BM_TravTrainLocalMap)->ArgNames({"models", "save"})->Args({1, 0})->Args({8, 0})->Args({8, 1})->Unit(benchmark::kMillisecond);

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
