#include "loop_eval.hpp"

#include <chrono>
#include <cmath>
#include <memory>

#include "trailnav/navigation/slam/arena.hpp"
#include "trailnav/navigation/slam/smf.hpp"

namespace trailnav::eval {

namespace reg = perception::registration;

namespace {

slam::Se2 se2_of(const Eigen::Isometry3d& t) noexcept {
  return {t.translation().x(), t.translation().y(), std::atan2(t.linear()(1, 0), t.linear()(0, 0))};
}

Eigen::Isometry3d iso_of(const slam::Se2& p) noexcept { return reg::to_isometry({p.x, p.y, p.theta}); }

double rms_error(std::span<const Eigen::Isometry3d> a, std::span<const Eigen::Isometry3d> b) {
  double sum = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) sum += (a[i].translation() - b[i].translation()).head<2>().squaredNorm();
  return a.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(a.size()));
}

}  // namespace

LoopEvalOptions default_loop_eval_options() {
  LoopEvalOptions o;
  // Keyframes every metre or 0.5 rad; the lidar odometry's error on this
  // kind of log (docs/registration.md: about 2 % and 25 deg/100 m) as the
  // odometry edges' noise.
  o.keyframes.spacing_m = 1.0;
  o.keyframes.spacing_rad = 0.5;
  o.keyframes.sigma_per_metre = 0.03;
  o.keyframes.sigma_theta_per_rad = 0.05;
  o.keyframes.sigma_theta_per_metre = 0.005;
  o.keyframes.sigma_floor_m = 0.02;
  o.keyframes.sigma_floor_rad = 0.005;
  o.keyframes.fix_first = true;
  o.keyframes.max_keyframes = 20000;
  o.loops.capacity = 20000;
  return o;
}

LoopEvalResult evaluate_loops(std::span<const reg::LaserScan2> scans, std::span<const Eigen::Isometry3d> odometry,
                              const LoopEvalOptions& options) {
  LoopEvalResult result;
  if (const std::string e = reg::check_loop_closure_config(options.loops); !e.empty()) {
    result.error = "loops: " + e;
    return result;
  }
  if (scans.size() != odometry.size() || scans.size() < 2) {
    result.error = "one odometry pose a scan, at least two scans";
    return result;
  }
  slam::KeyframeOptions ko = options.keyframes;
  ko.fix_first = true;
  ko.max_keyframes = std::min(ko.max_keyframes, options.loops.capacity);
  slam::KeyframeGraph graph(ko);
  graph.place_first(se2_of(odometry[0]));
  reg::LoopCloser closer(options.loops);
  slam::SmfOptions so;
  std::unique_ptr<slam::Arena> part_arena = std::make_unique<slam::Arena>(slam::smf_part_arena_bytes(slam::Se2::kDim, so.max_part));
  slam::SmfSolver<slam::Se2> solver(graph.capacity(), so, *part_arena);

  std::vector<reg::Point> cloud, points;
  cloud.reserve(static_cast<std::size_t>(options.scans_per_keyframe) * 4096);
  points.reserve(4096);
  std::vector<Eigen::Isometry3d> estimates;
  estimates.reserve(ko.max_keyframes);
  std::vector<std::size_t> keyframe_scan;
  double path = 0.0;
  for (std::size_t i = 0; i < scans.size(); ++i) {
    if (i > 0) path += (odometry[i].translation() - odometry[i - 1].translation()).head<2>().norm();
    if (graph.on_odometry(se2_of(odometry[i])) != slam::KeyframeGraph::Added::keyframe) continue;
    // The keyframe's cloud: its scan and those before it, by the odometry.
    cloud.clear();
    const std::size_t first = i + 1 >= static_cast<std::size_t>(options.scans_per_keyframe)
                                  ? i + 1 - static_cast<std::size_t>(options.scans_per_keyframe)
                                  : 0;
    const Eigen::Isometry3d to_keyframe = odometry[i].inverse();
    for (std::size_t j = first; j <= i; ++j) {
      points.clear();
      reg::scan_points(scans[j], options.max_range, 0.05f, points);
      const Eigen::Isometry3f t = (to_keyframe * odometry[j]).cast<float>();
      for (const reg::Point& p : points) {
        if (cloud.size() < cloud.capacity()) cloud.push_back(t * p);
      }
    }
    if (!closer.add_keyframe(cloud, path)) break;
    keyframe_scan.push_back(i);
    // The map's poses of every keyframe so far.
    estimates.clear();
    for (std::size_t k = 1; k <= graph.keyframe_count(); ++k) {
      estimates.push_back(iso_of(graph.graph().pose(static_cast<std::size_t>(graph.keyframe_vertex(k)))));
    }
    if (auto lc = closer.close(estimates)) {
      const Eigen::Isometry3d ref = reg::to_isometry(scans[keyframe_scan[lc->from]].pose).inverse() *
                                    reg::to_isometry(scans[keyframe_scan[lc->to]].pose);
      const Eigen::Isometry3d diff = ref.inverse() * lc->measurement;
      if (diff.translation().head<2>().norm() > options.false_m ||
          std::abs(std::atan2(diff.linear()(1, 0), diff.linear()(0, 0))) > options.false_rad) {
        ++result.false_closures;
      }
      graph.add_loop_closure(static_cast<std::int32_t>(lc->from + 1), static_cast<std::int32_t>(lc->to + 1),
                             se2_of(lc->measurement), lc->information);
      result.closures.emplace_back(lc->from, lc->to);
      const auto t0 = std::chrono::steady_clock::now();
      const slam::SmfReport r = solver.solve(graph.graph());
      result.solve_ms_max = std::max(
          result.solve_ms_max, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      if (r.ok) {
        ++result.optimisations;
      } else {
        ++result.failed_optimisations;
      }
    }
    if (options.progress) options.progress(static_cast<double>(i + 1) / static_cast<double>(scans.size()));
  }
  if (!result.closures.empty()) {
    const slam::SmfReport r = solver.solve(graph.graph());
    if (r.ok) ++result.optimisations;
  }
  result.keyframes = keyframe_scan.size();
  result.counters = closer.counters();
  for (std::size_t k = 0; k < keyframe_scan.size(); ++k) {
    result.reference.push_back(reg::to_isometry(scans[keyframe_scan[k]].pose));
    result.odometry.push_back(odometry[keyframe_scan[k]]);
    result.optimised.push_back(iso_of(graph.graph().pose(static_cast<std::size_t>(graph.keyframe_vertex(k + 1)))));
  }
  result.rpe_odometry = reg::relative_pose_error(result.reference, result.odometry, 10.0);
  result.rpe_loops = reg::relative_pose_error(result.reference, result.optimised, 10.0);
  if (!result.reference.empty()) {
    result.end_odometry_m = (result.odometry.back().translation() - result.reference.back().translation()).head<2>().norm();
    result.end_loops_m = (result.optimised.back().translation() - result.reference.back().translation()).head<2>().norm();
  }
  result.ate_odometry_m = rms_error(result.reference, result.odometry);
  result.ate_loops_m = rms_error(result.reference, result.optimised);
  return result;
}

}  // namespace trailnav::eval
