#include "loop_eval.hpp"

#include <chrono>
#include <cmath>

#include "trailnav/navigation/slam/arena.hpp"
#include "trailnav/navigation/slam/smf.hpp"

namespace trailnav::eval {

namespace reg = perception::registration;

namespace {

slam::Se2 se2_of(const Eigen::Isometry3d& t) noexcept {
  const reg::Pose2 p = reg::to_pose2(t);
  return {p.x, p.y, p.theta};
}

Eigen::Isometry3d iso_of(const slam::Se2& p) noexcept { return reg::to_isometry({p.x, p.y, p.theta}); }

double rms_error(std::span<const Eigen::Isometry3d> a, std::span<const Eigen::Isometry3d> b) {
  double sum = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) sum += (a[i].translation() - b[i].translation()).head<2>().squaredNorm();
  return a.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(a.size()));
}

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
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
  o.keyframes.max_keyframes = 20000;
  o.loops.capacity = 20000;
  return o;
}

LoopEvalOptions default_loop_eval_options_3d() {
  LoopEvalOptions o = default_loop_eval_options();
  o.keyframes.spacing_m = 2.0;
  o.keyframes.spacing_rad = 0.5;
  o.keyframes.sigma_per_metre = 0.02;
  o.keyframes.sigma_theta_per_metre = 0.003;
  o.keyframes.max_keyframes = 5000;
  o.loops = reg::spinning_lidar_loop_config();
  o.loops.capacity = 5000;
  return o;
}

struct LoopMapper::Impl {
  LoopEvalOptions options;
  slam::KeyframeGraph graph;
  reg::LoopCloser closer;
  slam::SmfOptions smf;
  std::unique_ptr<slam::Arena> part_arena;
  slam::SmfSolver<slam::Se2> solver;
  std::vector<reg::Point> cloud;
  std::vector<Eigen::Isometry3d> estimates;
  std::vector<Eigen::Isometry3d> odometry_at, reference_at;  // per keyframe
  bool have_reference = true;
  Eigen::Isometry3d last = Eigen::Isometry3d::Identity();
  bool started = false;
  double path = 0.0;
  LoopEvalResult result;

  static slam::KeyframeOptions keyframe_options(const LoopEvalOptions& o) {
    slam::KeyframeOptions k = o.keyframes;
    k.fix_first = true;
    k.max_keyframes = std::min(k.max_keyframes, o.loops.capacity);
    return k;
  }
  explicit Impl(const LoopEvalOptions& o)
      : options(o),
        graph(keyframe_options(o)),
        closer(o.loops),
        part_arena(std::make_unique<slam::Arena>(slam::smf_part_arena_bytes(slam::Se2::kDim, smf.max_part))),
        solver(graph.capacity(), smf, *part_arena) {
    estimates.reserve(o.loops.capacity);
  }
};

LoopMapper::LoopMapper(const LoopEvalOptions& options) {
  if (const std::string e = reg::check_loop_closure_config(options.loops); !e.empty()) {
    error_ = "loops: " + e;
    return;
  }
  impl_ = std::make_unique<Impl>(options);
}

LoopMapper::~LoopMapper() = default;

void LoopMapper::add(const Eigen::Isometry3d& odometry, const Eigen::Isometry3d* reference,
                     const std::function<void(std::vector<reg::Point>&)>& cloud) {
  if (!impl_) return;
  Impl& m = *impl_;
  if (!m.started) {
    m.graph.place_first(se2_of(odometry));
    m.started = true;
  } else {
    m.path += (odometry.translation() - m.last.translation()).head<2>().norm();
  }
  m.last = odometry;
  if (m.graph.on_odometry(se2_of(odometry)) != slam::KeyframeGraph::Added::keyframe) return;
  m.cloud.clear();
  cloud(m.cloud);
  if (!m.closer.add_keyframe(m.cloud, m.path)) return;
  m.odometry_at.push_back(odometry);
  m.have_reference = m.have_reference && reference != nullptr;
  m.reference_at.push_back(reference != nullptr ? *reference : Eigen::Isometry3d::Identity());
  // The map's poses of every keyframe so far.
  m.estimates.clear();
  for (std::size_t k = 1; k <= m.graph.keyframe_count(); ++k) {
    m.estimates.push_back(iso_of(m.graph.graph().pose(static_cast<std::size_t>(m.graph.keyframe_vertex(k)))));
  }
  const auto t0 = std::chrono::steady_clock::now();
  const auto lc = m.closer.close(m.estimates);
  m.result.close_ms_max = std::max(m.result.close_ms_max, ms_since(t0));
  if (!lc) return;
  if (m.have_reference) {
    const Eigen::Isometry3d ref = m.reference_at[lc->from].inverse() * m.reference_at[lc->to];
    const Eigen::Isometry3d diff = ref.inverse() * lc->measurement;
    if (diff.translation().head<2>().norm() > m.options.false_m ||
        std::abs(std::atan2(diff.linear()(1, 0), diff.linear()(0, 0))) > m.options.false_rad) {
      ++m.result.false_closures;
    }
  }
  m.graph.add_loop_closure(static_cast<std::int32_t>(lc->from + 1), static_cast<std::int32_t>(lc->to + 1),
                           se2_of(lc->measurement), lc->information);
  m.result.closures.emplace_back(lc->from, lc->to);
  const auto t1 = std::chrono::steady_clock::now();
  const slam::SmfReport r = m.solver.solve(m.graph.graph());
  m.result.solve_ms_max = std::max(m.result.solve_ms_max, ms_since(t1));
  if (r.ok) {
    ++m.result.optimisations;
  } else {
    ++m.result.failed_optimisations;
  }
}

LoopEvalResult LoopMapper::finish() {
  if (!impl_) {
    LoopEvalResult r;
    r.error = error_;
    return r;
  }
  Impl& m = *impl_;
  LoopEvalResult& result = m.result;
  if (!result.closures.empty()) {
    const slam::SmfReport r = m.solver.solve(m.graph.graph());
    if (r.ok) ++result.optimisations;
  }
  result.keyframes = m.odometry_at.size();
  result.counters = m.closer.counters();
  result.odometry = m.odometry_at;
  for (std::size_t k = 0; k < result.keyframes; ++k) {
    result.optimised.push_back(iso_of(m.graph.graph().pose(static_cast<std::size_t>(m.graph.keyframe_vertex(k + 1)))));
  }
  if (m.have_reference && result.keyframes > 0) {
    result.reference = m.reference_at;
    result.rpe_odometry = reg::relative_pose_error(result.reference, result.odometry, 10.0);
    result.rpe_loops = reg::relative_pose_error(result.reference, result.optimised, 10.0);
    result.end_odometry_m = (result.odometry.back().translation() - result.reference.back().translation()).head<2>().norm();
    result.end_loops_m = (result.optimised.back().translation() - result.reference.back().translation()).head<2>().norm();
    result.ate_odometry_m = rms_error(result.reference, result.odometry);
    result.ate_loops_m = rms_error(result.reference, result.optimised);
  }
  return std::move(result);
}

LoopEvalResult evaluate_loops(std::span<const reg::LaserScan2> scans, std::span<const Eigen::Isometry3d> odometry,
                              const LoopEvalOptions& options) {
  if (scans.size() != odometry.size() || scans.size() < 2) {
    LoopEvalResult r;
    r.error = "one odometry pose a scan, at least two scans";
    return r;
  }
  LoopMapper mapper(options);
  if (!mapper.error().empty()) {
    LoopEvalResult r;
    r.error = mapper.error();
    return r;
  }
  std::vector<reg::Point> points;
  points.reserve(4096);
  for (std::size_t i = 0; i < scans.size(); ++i) {
    const Eigen::Isometry3d reference = reg::to_isometry(scans[i].pose);
    mapper.add(odometry[i], &reference, [&](std::vector<reg::Point>& cloud) {
      // The keyframe's scan and those before it, put in its frame by the odometry.
      const std::size_t n = static_cast<std::size_t>(options.scans_per_keyframe);
      const std::size_t first = i + 1 >= n ? i + 1 - n : 0;
      const Eigen::Isometry3d to_keyframe = odometry[i].inverse();
      for (std::size_t j = first; j <= i; ++j) {
        points.clear();
        reg::scan_points(scans[j], options.max_range, 0.05f, points);
        const Eigen::Isometry3f t = (to_keyframe * odometry[j]).cast<float>();
        for (const reg::Point& p : points) cloud.push_back(t * p);
      }
    });
    if (options.progress) options.progress(static_cast<double>(i + 1) / static_cast<double>(scans.size()));
  }
  return mapper.finish();
}

}  // namespace trailnav::eval
