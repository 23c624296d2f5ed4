// trailnav's GICP side by side with PCL's (pcl::GeneralizedIterativeClosestPoint,
// Debian's libpcl-dev; built only where PCL is installed:
// toolchain/registration-side-by-side.sh installs it and runs this pinned to
// one core). The same pairs for both, each from the identity: the real KITTI
// scan 0 onto itself moved by a known motion (3° yaw, 1° pitch, (0.6, 0.2,
// 0.05) m) and voxel-filtered again after the motion (the truth is the
// motion), and scan 0 onto scan 1 (no truth: forward and backward must
// compose to the identity). Both at 0.25 m, k = 20 neighbours for the
// covariances, a 1 m association gate, at most 100 iterations; timed from
// the voxel-filtered source to the answer (each computes the source's
// covariances; the target's are computed once, before timing). Counters:
// the error against the truth (mm, degrees) or the loop's.
#include <benchmark/benchmark.h>

#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/registration/gicp.h>

#include "trailnav/perception/registration/cloud.hpp"
#include "trailnav/perception/registration/gicp.hpp"

#ifdef TRAILNAV_SMALL_GICP
#include <small_gicp/ann/kdtree.hpp>
#include <small_gicp/points/point_cloud.hpp>
#include <small_gicp/registration/registration_helper.hpp>
#include <small_gicp/util/normal_estimation_omp.hpp>
#endif

#include "registration_data.hpp"

namespace {

using namespace trailnav::perception::registration;


Eigen::Isometry3d truth_motion() {
  Eigen::Isometry3d m = Eigen::Isometry3d::Identity();
  m.linear() = (Eigen::AngleAxisd(3.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()) *
                Eigen::AngleAxisd(1.0 * M_PI / 180.0, Eigen::Vector3d::UnitY()))
                   .toRotationMatrix();
  m.translation() = Eigen::Vector3d(0.6, 0.2, 0.05);
  return m;
}

// Case 0: the moved scan (source) onto scan 0 (target); case 1: scan 0 onto scan 1.
struct Case {
  Cloud source, target;
  bool has_truth = false;
  Eigen::Isometry3d truth = Eigen::Isometry3d::Identity();
};
Case make_case(int which) {
  Case c;
  if (which == 0) {
    const std::vector<Point> raw = kitti(0);
    c.truth = truth_motion();
    c.has_truth = true;
    std::vector<Point> moved;
    for (const Point& p : raw) moved.push_back((c.truth.inverse() * p.cast<double>()).cast<float>());
    c.source = downsampled(moved, 0.25f);
    c.target = downsampled(raw, 0.25f);
  } else {
    c.source = downsampled(kitti(0), 0.25f);
    c.target = downsampled(kitti(1), 0.25f);
  }
  return c;
}

double rotation_deg(const Eigen::Matrix3d& r) { return Eigen::AngleAxisd(r).angle() * 180.0 / M_PI; }

void report(benchmark::State& state, const Case& c, const Eigen::Isometry3d& forward, const Eigen::Isometry3d& backward) {
  if (c.has_truth) {
    const Eigen::Isometry3d e = c.truth.inverse() * forward;
    state.counters["error_mm"] = 1000.0 * e.translation().norm();
    state.counters["error_deg"] = rotation_deg(e.linear());
  } else {
    const Eigen::Isometry3d loop = forward * backward;
    state.counters["loop_mm"] = 1000.0 * loop.translation().norm();
    state.counters["loop_deg"] = rotation_deg(loop.linear());
  }
}

void BM_Trailnav(benchmark::State& state) {
  const Case c = make_case(static_cast<int>(state.range(0)));
  CovarianceEstimator est(20);
  Target target, back;
  target.cloud = c.target;
  prepare_target(target, est);
  back.cloud = c.source;
  prepare_target(back, est);
  GicpConfig config;
  config.max_iterations = 100;
  config.max_correspondence_distance = 1.0f;
  Gicp gicp(config, std::max(c.source.size(), c.target.size()));
  KdTree scratch;
  std::vector<Point> normals;
  Cloud source;
  GicpResult r;
  for (auto _ : state) {
    source = c.source;
    prepare_source(source, est, scratch, normals);
    r = gicp.align(source, target);
    benchmark::DoNotOptimize(r.transform.data());
  }
  const GicpResult b = gicp.align(target.cloud, back);  // backward: scan 1 onto scan 0 (target.cloud has its covariances)
  report(state, c, r.transform, b.transform);
  state.counters["iterations"] = r.iterations;
}
BENCHMARK(BM_Trailnav)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

pcl::PointCloud<pcl::PointXYZ>::Ptr to_pcl(const Cloud& c) {
  auto out = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  for (const Point& p : c.points) out->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  return out;
}

Eigen::Isometry3d pcl_align(pcl::GeneralizedIterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ>& gicp,
                            const pcl::PointCloud<pcl::PointXYZ>::Ptr& source) {
  gicp.setInputSource(source);
  pcl::PointCloud<pcl::PointXYZ> aligned;
  gicp.align(aligned);
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.matrix() = gicp.getFinalTransformation().cast<double>();
  return t;
}

void configure(pcl::GeneralizedIterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ>& gicp) {
  gicp.setMaximumIterations(100);
  gicp.setMaxCorrespondenceDistance(1.0);
  gicp.setCorrespondenceRandomness(20);
}

void BM_Pcl(benchmark::State& state) {
  const Case c = make_case(static_cast<int>(state.range(0)));
  const auto source = to_pcl(c.source);
  const auto target = to_pcl(c.target);
  pcl::GeneralizedIterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ> gicp;
  configure(gicp);
  gicp.setInputTarget(target);
  Eigen::Isometry3d forward = Eigen::Isometry3d::Identity();
  for (auto _ : state) {
    // A new source each time: PCL computes its covariances in align().
    forward = pcl_align(gicp, pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>(*source));
    benchmark::DoNotOptimize(forward.data());
  }
  pcl::GeneralizedIterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ> back;
  configure(back);
  back.setInputTarget(source);
  const Eigen::Isometry3d backward = pcl_align(back, target);
  report(state, c, forward, backward);
  state.counters["converged"] = gicp.hasConverged() ? 1 : 0;
}
BENCHMARK(BM_Pcl)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

#ifdef TRAILNAV_SMALL_GICP
// small_gicp (Koide, fetched and built outside the repository by
// toolchain/registration-side-by-side.sh --small-gicp DIR): its GICP on one
// thread with the same k, gate, iteration cap and convergence thresholds as
// trailnav's; timed like trailnav's from the voxel-filtered source (its
// covariances) to the answer.
std::vector<Eigen::Vector4d> homogeneous(const Cloud& c) {
  std::vector<Eigen::Vector4d> v;
  for (const Point& p : c.points) v.emplace_back(p.x(), p.y(), p.z(), 1.0);
  return v;
}

void BM_SmallGicp(benchmark::State& state) {
  const Case c = make_case(static_cast<int>(state.range(0)));
  small_gicp::RegistrationSetting setting;
  setting.type = small_gicp::RegistrationSetting::GICP;
  setting.num_threads = 1;
  setting.max_correspondence_distance = 1.0;
  setting.max_iterations = 100;
  setting.rotation_eps = GicpConfig{}.rotation_epsilon;
  setting.translation_eps = GicpConfig{}.translation_epsilon;
  auto prepare = [](const Cloud& cloud) {
    auto pc = std::make_shared<small_gicp::PointCloud>(homogeneous(cloud));
    auto tree = std::make_shared<small_gicp::KdTree<small_gicp::PointCloud>>(pc);
    small_gicp::estimate_covariances_omp(*pc, *tree, 20, 1);
    return std::make_pair(pc, tree);
  };
  const auto [target, target_tree] = prepare(c.target);
  const std::vector<Eigen::Vector4d> source_points = homogeneous(c.source);
  small_gicp::RegistrationResult r;
  for (auto _ : state) {
    small_gicp::PointCloud source(source_points);
    small_gicp::estimate_covariances_omp(source, 20, 1);
    r = small_gicp::align(*target, source, *target_tree, Eigen::Isometry3d::Identity(), setting);
    benchmark::DoNotOptimize(r.T_target_source.data());
  }
  const auto [back_target, back_tree] = prepare(c.source);
  const small_gicp::RegistrationResult b =
      small_gicp::align(*back_target, *target, *back_tree, Eigen::Isometry3d::Identity(), setting);
  report(state, c, r.T_target_source, b.T_target_source);
  state.counters["iterations"] = static_cast<double>(r.iterations);
  state.counters["converged"] = r.converged ? 1 : 0;
}
BENCHMARK(BM_SmallGicp)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);
#endif

}  // namespace

BENCHMARK_MAIN();
