#include "trailnav/navigation/slam/mapping_task.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <new>

#include "trailnav/perception/registration/carmen.hpp"
#include "trailnav/runtime/heap_redirect.hpp"

namespace trailnav::slam {

namespace {

KeyframeOptions keyframe_options(const MappingOptions& o) {
  KeyframeOptions k = o.keyframes;
  k.fix_first = !o.use_gps;  // without GPS the first keyframe is the gauge
  k.gps_white_sigma = o.gps_white_sigma;
  k.gps_bias_time = o.gps_bias_time;
  return k;
}

SmfOptions smf_options(const MappingOptions& o) {
  SmfOptions s;
  s.max_part = o.max_part;
  s.lm.max_iterations = o.max_iterations;
  return s;
}

// The graph's origin in UTM: a fix's position rounded to 100 m.
double origin_of(double v) { return 100.0 * std::round(v / 100.0); }

}  // namespace

const char* mapping_state_name(MappingState s) noexcept {
  switch (s) {
    case MappingState::waiting_alignment: return "waiting for the GPS alignment";
    case MappingState::mapping: return "mapping";
    case MappingState::full: return "full";
  }
  return "?";
}

std::string check_mapping_options(const MappingOptions& o) {
  const KeyframeOptions& k = o.keyframes;
  if (k.max_keyframes < 2) return "max_keyframes must be at least 2";
  if (k.max_keyframes > 10'000'000) return "max_keyframes must be at most 10000000";
  if (!(k.spacing_m > 0.0)) return "spacing_m must be positive";
  if (!(k.spacing_rad > 0.0)) return "spacing_rad must be positive";
  if (!(k.sigma_per_metre >= 0.0) || !(k.sigma_theta_per_rad >= 0.0) || !(k.sigma_theta_per_metre >= 0.0)) {
    return "odometry noise (sigma_per_metre, sigma_theta_per_rad, sigma_theta_per_metre) must not be negative";
  }
  if (!(k.sigma_floor_m > 0.0) || !(k.sigma_floor_rad > 0.0)) return "sigma_floor_m and sigma_floor_rad must be positive";
  if (!(k.gps_max_distance >= 0.0)) return "gps_max_distance must not be negative";
  if (o.max_part < 10 || o.max_part > 5000) return "max_part must be 10 to 5000";
  if (o.max_iterations < 1) return "max_iterations must be at least 1";
  if (!(o.optimize_period > 0.0)) return "optimize_period must be positive";
  return {};
}

MappingTask::MappingTask(const MappingOptions& options, perception::PoseQueue& poses, pose::MappingFixQueue* fixes,
                         Mailbox<MappingSnapshot>& out)
    : options_(options),
      poses_(poses),
      fixes_(fixes),
      out_(out),
      graph_(keyframe_options(options)),
      part_arena_(std::make_unique<Arena>(smf_part_arena_bytes(Se2::kDim, options.max_part))),
      solver_(graph_.capacity(), smf_options(options), *part_arena_),
      keyframe_odometry_(graph_.capacity().vertices),
      keyframe_time_(graph_.capacity().vertices, 0),
      backup_(graph_.capacity().vertices) {
  if (!options_.use_gps) local_.state = MappingState::mapping;
  if (options_.loops) {
    perception::registration::LoopClosureConfig lc = *options_.loops;
    lc.capacity = options_.keyframes.max_keyframes;  // a cloud for every keyframe the graph can hold
    loops_ = std::make_unique<perception::registration::LoopCloser>(lc);
    loop_arena_ = std::make_unique<Arena>(options_.loop_arena_bytes);
    recent_ = std::make_unique<perception::PoseTrack>(perception::kPoseQueueCapacity);
    cloud_.reserve(lc.max_input_points > 0 ? lc.max_input_points : lc.max_points * 8);
    estimates_.reserve(lc.capacity);
    local_.loop_arena_capacity = loop_arena_->capacity();
  }
  local_.capacity_vertices = graph_.capacity().vertices;
  local_.capacity_edges = graph_.capacity().edges;
  local_.hierarchy_capacity = solver_.hierarchy_arena().capacity();
  local_.part_capacity = part_arena_->capacity();
  shared_.post(local_);
}

MappingTask::~MappingTask() {
  // What the loop closer holds from its arena (the last verification's
  // k-d tree and normals) goes back there, not to the heap.
  if (loop_arena_) {
    heap_redirect::ArenaRedirect redirect(*loop_arena_);
    const heap_redirect::Scope scope(redirect);
    loops_.reset();
  }
}

Se2 MappingTask::correction() const noexcept {
  if (graph_.keyframe_count() < 1) return start_transform_;
  const auto k = static_cast<std::size_t>(graph_.latest_vertex());
  return graph_.graph().pose(k) * keyframe_odometry_[k].inverse();
}

bool MappingTask::add_loop_closure(std::int32_t from, std::int32_t to, const Se2& measurement,
                                   const Se2::Matrix& information) {
  return graph_.add_loop_closure(from, to, measurement, information);
}

void MappingTask::take_pose(const perception::Pose& p) {
  ++local_.poses;
  if (!p.motion_known) {
    ++local_.poses_unmeasured;
    return;
  }
  if (!started_) {
    if (options_.use_gps) {
      ++local_.poses_before_start;
      return;
    }
    started_ = true;  // the map is the odometry frame at start: start_transform_ is the identity
  }
  const Se2 o{p.x, p.y, p.yaw};
  if (loops_) {
    recent_->push(p);
    if (have_last_) path_ += std::hypot(o.x - last_pose_.x, o.y - last_pose_.y);
    last_pose_ = o;
    have_last_ = true;
  }
  if (graph_.keyframe_count() == 0) graph_.place_first(start_transform_ * o);
  switch (graph_.on_odometry(o)) {
    case KeyframeGraph::Added::keyframe: {
      const auto k = static_cast<std::size_t>(graph_.latest_vertex());
      keyframe_odometry_[k] = o;
      keyframe_time_[k] = p.t_ns;
      alignment_at_keyframe_ = alignment_;
      if (loops_) {
        // It waits for a revolution; a full queue lets its oldest go without a cloud.
        if (waiting_count_ == waiting_.size()) pop_waiting({});
        waiting_[waiting_count_++] = {p.t_ns, o, path_};
      }
      break;
    }
    case KeyframeGraph::Added::full: local_.state = MappingState::full; break;
    case KeyframeGraph::Added::none: break;
  }
}

void MappingTask::take_revolution(const velodyne::RangeImage& image) {
  const std::int64_t r = image.reference_end_ns();
  perception::Pose at;
  if (waiting_count_ == 0) return;
  const perception::PoseLookup found = recent_->at(r, at);
  // The robot's odometry at the revolution's end: a revolution newer than
  // the poses taken (by more than a few of the pose thread's periods) waits
  // for the next run's, not placed where the robot was before it.
  if (found == perception::PoseLookup::empty ||
      (found == perception::PoseLookup::after_last && r - recent_->newest().t_ns > 50'000'000)) {
    return;
  }
  const Se2 robot_at_r{at.x, at.y, at.yaw};
  const std::int64_t gap = static_cast<std::int64_t>(options_.loop_max_gap * 1e9);
  while (waiting_count_ > 0) {
    const Waiting& w = waiting_[0];
    if (w.t_ns - r > gap) break;  // the revolution is too old for it (and for the ones after)
    if (r - w.t_ns > gap) {       // too late for this keyframe: it goes without a cloud
      pop_waiting({});
      continue;
    }
    // The revolution's points in the keyframe's frame: the mount, then the
    // odometry from the keyframe to the revolution's end.
    const Se2 rel = w.odometry.inverse() * robot_at_r;
    const Eigen::Isometry3f to_keyframe = perception::registration::to_isometry({rel.x, rel.y, rel.theta}).cast<float>() * mount_;
    cloud_.clear();
    for (int ring = 0; ring < image.rings() && cloud_.size() < cloud_.capacity(); ++ring) {
      for (const velodyne::RangeCell& c : image.row(0, ring)) {
        if (!c.valid() || c.distance < min_range_ || c.distance > max_range_) continue;
        if (cloud_.size() == cloud_.capacity()) break;
        cloud_.push_back(to_keyframe * Eigen::Vector3f(c.x, c.y, c.z));
      }
    }
    pop_waiting(cloud_);
  }
}

void MappingTask::give_up_waiting(std::int64_t now_ns) {
  const std::int64_t gap = static_cast<std::int64_t>(options_.loop_max_gap * 1e9);
  while (waiting_count_ > 0 && now_ns - waiting_[0].t_ns > gap) pop_waiting({});
}

void MappingTask::pop_waiting(std::span<const perception::registration::Point> cloud) {
  // Keyframes reach the loop closer in the graph's order, each with its
  // cloud or none (counted): its k-th keyframe is the graph's (k + 1)-th.
  loops_->add_keyframe(cloud, waiting_[0].path);
  for (std::size_t i = 1; i < waiting_count_; ++i) waiting_[i - 1] = waiting_[i];
  --waiting_count_;
  if (cloud.empty()) {
    ++local_.loop_no_cloud;
    return;
  }
  close_loops();
}

void MappingTask::close_loops() {
  // The map's poses of every keyframe (the newest ones as placed from the
  // last solve and the odometry since).
  estimates_.clear();
  const PoseGraph2d& g = graph_.graph();
  for (std::size_t k = 1; k <= graph_.keyframe_count() && estimates_.size() < estimates_.capacity(); ++k) {
    const Se2& p = g.pose(static_cast<std::size_t>(graph_.keyframe_vertex(k)));
    estimates_.push_back(perception::registration::to_isometry({p.x, p.y, p.theta}));
  }
  const auto t0 = std::chrono::steady_clock::now();
  std::optional<perception::registration::LoopClosure> lc;
  {
    heap_redirect::ArenaRedirect redirect(*loop_arena_);
    const heap_redirect::Scope scope(redirect);
    try {
      lc = loops_->close(estimates_);
    } catch (const std::bad_alloc&) {
      ++local_.loop_arena_failures;
    }
  }
  local_.loop_ms_max = std::max(local_.loop_ms_max,
                                std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  local_.loops = loops_->counters();
  local_.loop_arena_high_water = loop_arena_->high_water();
  if (!lc) return;
  const perception::registration::Pose2 m = perception::registration::to_pose2(lc->measurement);
  const Se2 z{m.x, m.y, m.theta};
  graph_.add_loop_closure(static_cast<std::int32_t>(lc->from + 1), static_cast<std::int32_t>(lc->to + 1), z,
                          lc->information);
}

void MappingTask::take_fix(const pose::MappingFix& f) {
  ++local_.fixes;
  if (!options_.use_gps) return;
  if (f.aligned) alignment_ = Se2{f.east, f.north_m, f.rotation};
  if (!started_) {
    if (!f.aligned) {
      ++local_.fixes_before_start;
      return;
    }
    // The map starts here: the UTM zone's frame, shifted by an origin near the robot.
    zone_ = f.zone;
    north_ = f.north;
    origin_e_ = origin_of(f.fix.utm.x());
    origin_n_ = origin_of(f.fix.utm.y());
    start_transform_ = Se2{f.east - origin_e_, f.north_m - origin_n_, f.rotation};
    started_ = true;
    if (local_.state == MappingState::waiting_alignment) local_.state = MappingState::mapping;
  }
  if (graph_.keyframe_count() < 1) {
    ++local_.fixes_before_start;  // no keyframe yet to attach it to
    return;
  }
  // The robot's position at the fix, in the map: the antenna's, less the
  // antenna's offset from the robot turned from the odometry frame into the map's.
  const double phi = correction().theta, c = std::cos(phi), s = std::sin(phi);
  const double ox = f.fix.antenna_odom.x() - f.fix.x, oy = f.fix.antenna_odom.y() - f.fix.y;
  const double px = f.fix.utm.x() - origin_e_ - (c * ox - s * oy);
  const double py = f.fix.utm.y() - origin_n_ - (s * ox + c * oy);
  GpsMeasurement m;
  m.x = px;
  m.y = py;
  m.sigma = f.fix.sigma;
  m.time_ns = f.fix.time_ns;
  m.odometry = Se2{f.fix.x, f.fix.y, f.fix.yaw};
  graph_.on_gps(m);
}

void MappingTask::optimise() {
  PoseGraph2d& g = graph_.graph();
  const std::size_t n = g.vertex_count();
  for (std::size_t v = 0; v < n; ++v) backup_[v] = g.pose(v);
  const auto t0 = std::chrono::steady_clock::now();
  const SmfReport r = solver_.solve(g);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  local_.solve_ms = ms;
  if (ms > local_.solve_max_ms) local_.solve_max_ms = ms;
  if (!r.ok) {
    for (std::size_t v = 0; v < n; ++v) g.pose(v) = backup_[v];
    ++local_.failures;
    std::snprintf(local_.error.data(), local_.error.size(), "%s", r.error.c_str());
    return;
  }
  ++local_.optimisations;
  local_.error[0] = '\0';
  if (options_.use_gps) {
    // The map's correction of the alignment at the newest keyframe.
    const Se2 c = correction();
    const Se2 map_from_odom{c.x + origin_e_, c.y + origin_n_, c.theta};
    const Se2 delta = map_from_odom * alignment_at_keyframe_.inverse();
    const auto k = static_cast<std::size_t>(graph_.latest_vertex());
    const Se2 by_map = map_from_odom * keyframe_odometry_[k], by_alignment = alignment_at_keyframe_ * keyframe_odometry_[k];
    local_.correction_m = std::hypot(by_map.x - by_alignment.x, by_map.y - by_alignment.y);
    local_.correction_rad = delta.theta;
    if (corrections_ != nullptr) {
      pose::MapCorrection& out = corrections_->write_slot();
      out.valid = true;
      out.revision = local_.optimisations;
      out.x = delta.x;
      out.y = delta.y;
      out.yaw = delta.theta;
      corrections_->publish();
    }
  }
  local_.levels = r.levels;
  local_.iterations = r.iterations;
  local_.initial_chi2 = r.initial_chi2;
  local_.chi2 = r.chi2;
}

void MappingTask::publish() {
  const PoseGraph2d& g = graph_.graph();
  MappingSnapshot& s = out_.write_slot();
  s.georeferenced = options_.use_gps;
  s.zone = zone_;
  s.north = north_;
  s.optimised = local_.optimisations > 0;
  const Se2 c = correction();
  s.x = c.x + origin_e_;
  s.y = c.y + origin_n_;
  s.yaw = c.theta;
  s.path_count = 0;
  for (std::size_t i = 1; i <= graph_.keyframe_count() && s.path_count < s.path.size(); ++i) {
    const auto k = static_cast<std::size_t>(graph_.keyframe_vertex(i));
    const Se2& p = g.pose(k);
    s.path[s.path_count++] = {keyframe_time_[k], p.x + origin_e_, p.y + origin_n_, p.theta};
  }
  s.time_ns = graph_.keyframe_count() > 0 ? keyframe_time_[static_cast<std::size_t>(graph_.latest_vertex())] : 0;
  out_.publish();
  ++local_.published;
  if (notify_ != nullptr) notify_->notify();
}

void MappingTask::run(const TaskTick& tick) {
  ++local_.runs;
  // Both queues, merged by time: a fix is taken after the poses up to its time.
  std::size_t np = 0, nf = 0;
  while (np < pose_batch_.size() && poses_.try_pop(pose_batch_[np])) ++np;
  if (fixes_ != nullptr) {
    while (nf < fix_batch_.size() && fixes_->try_pop(fix_batch_[nf])) ++nf;
  }
  std::size_t i = 0, j = 0;
  while (i < np || j < nf) {
    if (j < nf && (i == np || fix_batch_[j].fix.time_ns <= pose_batch_[i].t_ns)) {
      take_fix(fix_batch_[j++]);
    } else {
      take_pose(pose_batch_[i++]);
    }
  }
  // The newest revolution for the keyframes waiting for one; those that
  // waited too long go without.
  if (loops_ && revolutions_ != nullptr) {
    if (const velodyne::RangeImage* image = revolutions_->try_read()) take_revolution(*image);
    if (recent_->size() > 0) give_up_waiting(recent_->newest().t_ns);
  }

  const PoseGraph2d& g = graph_.graph();
  const bool changed = g.vertex_count() != solved_vertices_ || g.edge_count() != solved_edges_;
  const Nanos period = seconds_to_nanos(options_.optimize_period);
  if (changed && graph_.keyframe_count() > 0 && (last_optimise_ < 0 || tick.started - last_optimise_ >= period)) {
    last_optimise_ = tick.started;
    const KeyframeCounters& k = graph_.counters();
    // Something to optimise: two GPS constraints (position and heading of
    // the whole map), or without GPS a loop closure.
    const bool constrained = options_.use_gps ? k.gps_edges >= 2 : k.loop_closures >= 1;
    if (constrained) optimise();
    solved_vertices_ = g.vertex_count();
    solved_edges_ = g.edge_count();
    publish();
  }

  local_.keyframes = graph_.counters();
  local_.vertices = g.vertex_count();
  local_.edges = g.edge_count();
  local_.hierarchy_high_water = solver_.hierarchy_arena().high_water();
  local_.part_high_water = part_arena_->high_water();
  shared_.post(local_);
}

}  // namespace trailnav::slam
