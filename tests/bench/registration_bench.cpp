// The registration's hot paths on the two real KITTI HDL-64E scans (run from
// the repository root, pinned: `taskset -c 0 build/release/bin/trailnav_registration_bench`):
// the voxel filter of a whole revolution (124 k points, 0.25 m), a target's
// set-up (k-d tree and GICP covariances, k = 20) and one registration of
// scan 0 onto scan 1 from the identity in each metric (the issue's "one GICP
// registration of two KITTI revolutions downsampled to 0.25 m").
#include <benchmark/benchmark.h>

#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "trailnav/perception/registration/cloud.hpp"
#include "trailnav/perception/registration/gicp.hpp"

namespace {

using namespace trailnav::perception::registration;

std::vector<Point> kitti(int i) {
  const std::string path = "../shared/data/kitti/00000" + std::to_string(i) + ".bin";
  std::ifstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error("cannot read " + path);
  std::vector<Point> p;
  float x[4];
  while (f.read(reinterpret_cast<char*>(x), sizeof x)) p.emplace_back(x[0], x[1], x[2]);
  return p;
}

Cloud downsampled(const std::vector<Point>& points, float voxel) {
  VoxelFilter filter(points.size());
  Cloud c;
  c.points.reserve(points.size());
  filter.filter(points, voxel, c);
  return c;
}

void BM_VoxelFilter(benchmark::State& state) {
  const std::vector<Point> raw = kitti(0);
  VoxelFilter filter(raw.size());
  Cloud out;
  out.points.reserve(raw.size());
  for (auto _ : state) {
    filter.filter(raw, 0.25f, out);
    benchmark::DoNotOptimize(out.points.data());
  }
  state.counters["points"] = static_cast<double>(raw.size());
  state.counters["voxels"] = static_cast<double>(out.size());
}
BENCHMARK(BM_VoxelFilter)->Unit(benchmark::kMillisecond);

void BM_PrepareTarget(benchmark::State& state) {
  const Cloud cloud = downsampled(kitti(1), 0.25f);
  CovarianceEstimator est(20);
  for (auto _ : state) {
    Target t;
    t.cloud = cloud;
    prepare_target(t, est);
    benchmark::DoNotOptimize(t.cloud.covariances.data());
  }
  state.counters["points"] = static_cast<double>(cloud.size());
}
BENCHMARK(BM_PrepareTarget)->Unit(benchmark::kMillisecond);

// Argument: the metric (0 plane-to-plane, 1 point-to-plane, 2 point-to-point).
void BM_GicpAlign(benchmark::State& state) {
  Target target;
  target.cloud = downsampled(kitti(1), 0.25f);
  CovarianceEstimator est(20);
  prepare_target(target, est);
  Cloud source = downsampled(kitti(0), 0.25f);
  KdTree scratch;
  std::vector<Point> normals;
  prepare_source(source, est, scratch, normals);
  GicpConfig config;
  config.metric = static_cast<Metric>(state.range(0));
  config.max_iterations = 100;
  Gicp gicp(config, source.size());
  GicpResult r;
  for (auto _ : state) {
    r = gicp.align(source, target);
    benchmark::DoNotOptimize(r.transform.data());
  }
  state.counters["points"] = static_cast<double>(source.size());
  state.counters["iterations"] = r.iterations;
  state.counters["converged"] = r.converged ? 1 : 0;
}
BENCHMARK(BM_GicpAlign)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
