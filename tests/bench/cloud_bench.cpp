// Point clouds from files (drivers/cloud) on the real SemanticKITTI scan
// (123,389 points, HDL-64E): parsing the KITTI .bin from memory, and
// filling the range image from the cloud (rows from the elevation, columns
// from the azimuth). Issue 39's goal: 1 ms for 125,000 points.
#include <benchmark/benchmark.h>

#include <array>
#include <cstring>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <vector>

#include "trailnav/drivers/cloud/cloud_file.hpp"
#include "trailnav/drivers/cloud/cloud_image.hpp"
#include "obstacle_run.hpp"
#include "trailnav/perception/kitti.hpp"
#include "trailnav/perception/obstacle_config.hpp"
#include "trailnav/perception/obstacle_pipeline.hpp"

namespace {

using namespace trailnav::cloud;

const std::vector<std::uint8_t>& scan_bytes() {
  static const std::vector<std::uint8_t> bytes = [] {
    std::ifstream in("../shared/data/semantickitti/000000.bin", std::ios::binary);
    if (!in) throw std::runtime_error("run from the repository: ../shared/data/semantickitti/000000.bin");
    return std::vector<std::uint8_t>((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  }();
  return bytes;
}

void BM_CloudReadKitti(benchmark::State& state) {
  PointCloud cloud(130000);
  CloudScratch scratch;
  for (auto _ : state) {
    if (!read_cloud(scan_bytes(), CloudFormat::kitti_bin, "scan", cloud, scratch)) throw std::runtime_error("read");
    benchmark::DoNotOptimize(cloud.x.data());
  }
  state.counters["points"] = static_cast<double>(cloud.size);
}
BENCHMARK(BM_CloudReadKitti)->Unit(benchmark::kMillisecond);

// The same scan as a sensor_msgs/PointCloud2 (x, y, z, intensity float32,
// 16 bytes a point, one row): what trailnavd's point-cloud input reads from
// every message (board/dds/cloud_reader.hpp), ten a second.
void BM_ReadPointCloud2(benchmark::State& state) {
  const std::vector<std::uint8_t>& b = scan_bytes();
  const std::array<PointFieldView, 4> fields{{{"x", 0, 7, 1}, {"y", 4, 7, 1}, {"z", 8, 7, 1}, {"intensity", 12, 7, 1}}};
  PointCloud2View m;
  m.width = static_cast<std::uint32_t>(b.size() / 16);
  m.fields = fields;
  m.point_step = 16;
  m.row_step = 16 * m.width;
  m.data = b;
  PointCloud cloud(130000);
  for (auto _ : state) {
    if (!read_pointcloud2(m, "bench", cloud)) throw std::runtime_error("read");
    benchmark::DoNotOptimize(cloud.x.data());
  }
  state.counters["points"] = static_cast<double>(cloud.size);
}
BENCHMARK(BM_ReadPointCloud2)->Unit(benchmark::kMillisecond);

// The peer in the same run: the KITTI loader (perception/kitti.cpp) from the
// same points in memory to its one-layer image (it drops a cell's second point).
void BM_KittiLoader(benchmark::State& state) {
  const std::vector<std::uint8_t>& b = scan_bytes();
  std::vector<float> points(b.size() / 4);
  std::memcpy(points.data(), b.data(), points.size() * 4);
  trailnav::velodyne::RangeImage image(trailnav::perception::kitti_shape());
  for (auto _ : state) {
    if (!trailnav::perception::kitti_to_range_image(points, "scan", image)) throw std::runtime_error("kitti");
    benchmark::DoNotOptimize(image.points);
  }
  state.counters["points"] = static_cast<double>(points.size() / 4);
}
BENCHMARK(BM_KittiLoader)->Unit(benchmark::kMillisecond);

void BM_CloudImage(benchmark::State& state) {
  PointCloud cloud(130000);
  CloudScratch scratch;
  if (!read_cloud(scan_bytes(), CloudFormat::kitti_bin, "scan", cloud, scratch)) throw std::runtime_error("read");
  CloudImageOptions o{255.0f, 0.1, state.range(1) != 0 ? RingSource::order : RingSource::elevation};
  o.lanes = static_cast<int>(state.range(2));
  CloudImager imager(*ring_layout_preset("HDL-64E"), static_cast<int>(state.range(0)), o);
  trailnav::velodyne::RangeImage image(imager.shape());
  CloudImageStats stats;
  for (auto _ : state) {
    imager.fill(cloud, image, stats);
    benchmark::DoNotOptimize(image.points);
  }
  state.counters["points"] = static_cast<double>(stats.points);
}
// order 0: rows from the elevation; 1: from the sensor's order (KITTI's
// files); lanes: points at a time for the polar coordinates (8: AVX2 where
// the CPU has it).
// The same placement without the image: each cell's first point by its index.
void BM_CloudIndex(benchmark::State& state) {
  PointCloud cloud(130000);
  CloudScratch scratch;
  if (!read_cloud(scan_bytes(), CloudFormat::kitti_bin, "scan", cloud, scratch)) throw std::runtime_error("read");
  CloudImager imager(*ring_layout_preset("HDL-64E"), 2, CloudImageOptions{255.0f, 0.1, RingSource::order});
  std::vector<PointPlace> places(130000);
  CloudImageStats stats;
  for (auto _ : state) {
    const ScanCells cells = imager.index(cloud, stats, places);
    benchmark::DoNotOptimize(cells.first);
  }
  state.counters["points"] = static_cast<double>(stats.points);
}
BENCHMARK(BM_CloudIndex)->Unit(benchmark::kMillisecond);

BENCHMARK(BM_CloudImage)
    ->ArgNames({"layers", "order", "lanes"})
    ->Args({1, 0, 8})
    ->Args({2, 0, 8})
    ->Args({2, 1, 8})
    ->Args({2, 1, 4})
    ->Args({2, 1, 1})
    ->Unit(benchmark::kMillisecond);

// A scan to its per-point answers, as `trailnav obstacles SCAN.bin --config
// board/robots/kitti-car.yaml --labels-out` makes them: the file's bytes
// parsed, the range image (the sensor's order, two layers), alignment,
// smoothing, features, the height above the ground, and every point's
// answer; second argument 1: the obstacle map updated too. The side by
// side with Patchwork++ (toolchain/patchwork-side-by-side.sh) runs this.
void BM_ScanToAnswers(benchmark::State& state) {
  auto loaded = trailnav::perception::load_obstacle_config("board/robots/kitti-car.yaml");
  if (!loaded.config) throw std::runtime_error(loaded.error);
  trailnav::perception::ObstacleConfig config = *loaded.config;
  config.features.self_box = trailnav::perception::kKittiCarBox;
  PointCloud cloud(130000);
  CloudScratch scratch;
  RingLayout layout = *ring_layout_preset("HDL-64E");
  layout.columns = trailnav::perception::kKittiColumns;
  CloudImager imager(layout, 2, CloudImageOptions{255.0f, 0.1, RingSource::order});
  trailnav::velodyne::RangeImage image(imager.shape());
  std::vector<PointPlace> places(130000);
  auto made = trailnav::perception::ObstaclePipeline::create(config, imager.shape());
  if (!made.pipeline) throw std::runtime_error(made.error);
  made.pipeline->keep_point_fates();
  std::vector<trailnav::eval::ScanPointAnswer> answers(130000);
  const bool map = state.range(0) != 0;
  const bool through_image = state.range(1) != 0;
  CloudImageStats stats;
  for (auto _ : state) {
    if (!read_cloud(scan_bytes(), CloudFormat::kitti_bin, "scan", cloud, scratch)) throw std::runtime_error("read");
    if (through_image) {
      imager.fill(cloud, image, stats, places);
      made.pipeline->align(image, nullptr);
    } else {
      made.pipeline->align_scan(imager.index(cloud, stats, places));
    }
    made.pipeline->features();
    if (map) made.pipeline->update_maps(nullptr);
    trailnav::eval::answer_scan_points(cloud, {places.data(), cloud.size}, *made.pipeline, nullptr, answers);
    benchmark::DoNotOptimize(answers.data());
  }
  state.SetLabel(std::string(map ? "kitti-car.yaml, with the map" : "kitti-car.yaml, per-point answers") +
                 (through_image ? ", through a range image" : ""));
  state.counters["points"] = static_cast<double>(cloud.size);
}
// image 0: the file's points straight into the pipeline (CloudImager::index,
// ObstaclePipeline::align_scan), what `trailnav obstacles` does with a
// point-cloud file; 1: through a range image (fill, align), the way the
// daemon takes a PointCloud2.
BENCHMARK(BM_ScanToAnswers)
    ->ArgNames({"map", "image"})
    ->Args({0, 0})
    ->Args({1, 0})
    ->Args({0, 1})
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
