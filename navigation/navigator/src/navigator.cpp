#include "trailnav/navigation/navigator/navigator.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <optional>

namespace trailnav::nav {

namespace {

constexpr double kBehind = 5.0;   // m: the tracking window reaches this far back ...
constexpr double kAhead = 30.0;   // m ... and this far ahead of the last arc

bool finite(double v) noexcept { return std::isfinite(v); }

}  // namespace

std::string check_navigator_config(const NavigatorConfig& c) {
  const bool no_goal = std::isnan(c.goal_lat) && std::isnan(c.goal_lon);
  if (!no_goal &&
      (!finite(c.goal_lat) || !finite(c.goal_lon) || std::abs(c.goal_lat) > 84.0 || std::abs(c.goal_lon) > 180.0)) {
    return "goal: needs [latitude, longitude] in degrees (latitude within +-84)";
  }
  if (!(c.spacing >= 0.5 && c.spacing <= 100.0)) return "spacing: must be 0.5 .. 100 m";
  if (!(c.reach > 0.0 && c.reach < c.spacing)) return "reach: must be above 0 and below the spacing";
  if (!(c.lookahead >= c.reach + c.spacing && c.lookahead <= 500.0)) {
    return "lookahead: must be at least reach + spacing (so the active subgoal is always aligned) and at most 500 m";
  }
  if (!(c.goal_tolerance > 0.0 && c.goal_tolerance <= 100.0)) return "goal_tolerance: must be above 0 and at most 100 m";
  if (!(c.max_snap > 0.0)) return "max_snap: must be above 0 m";
  if (!(c.leave_distance > 0.0)) return "leave_distance: must be above 0 m";
  if (!(c.leave_time >= 0.0) || !(c.replan_interval >= 0.0)) return "leave_time and replan_interval must not be negative";
  if (!(c.max_position_sigma > 0.0)) return "max_position_sigma: must be above 0 m";
  if (c.path_poses < 1 || c.path_poses > 100000) return "path_poses: must be 1 .. 100000";
  return subgoals::check_aligner_config(c.aligner);
}

const char* nav_state_name(NavState state) noexcept {
  switch (state) {
    case NavState::idle: return "idle";
    case NavState::planning: return "planning";
    case NavState::following: return "following";
    case NavState::reached: return "reached";
    case NavState::failed: return "failed";
    case NavState::cancelled: return "cancelled";
  }
  return "?";
}

const char* goal_frame_name(GoalFrame frame) noexcept {
  switch (frame) {
    case GoalFrame::geographic: return "geographic";
    case GoalFrame::utm: return "utm";
    case GoalFrame::odom: return "odom";
    case GoalFrame::unknown: return "unknown";
  }
  return "?";
}

Navigator::Created Navigator::create(const osm::RoadGraph& graph, const NavigatorConfig& config,
                                     const perception::TerrainMapShape& map_shape) {
  Created out;
  if (std::string problem = check_navigator_config(config); !problem.empty()) {
    out.error = problem;
    return out;
  }
  if (graph.segments().empty()) {
    out.error = "the road network is empty";
    return out;
  }
  const bool has_goal = !std::isnan(config.goal_lat);
  double gx = 0.0, gy = 0.0;
  std::optional<osm::RoadProjection> goal;
  if (has_goal) {
    if (!graph.to_utm(config.goal_lat, config.goal_lon, gx, gy)) {
      out.error = "goal: cannot be projected to UTM";
      return out;
    }
    goal = graph.project(gx, gy);
    if (!goal || goal->distance > config.max_snap) {
      char text[200];
      std::snprintf(text, sizeof text, "goal: %.6f, %.6f lies %.0f m from the nearest routable way (max_snap %.0f m)",
                    config.goal_lat, config.goal_lon, goal ? goal->distance : 0.0, config.max_snap);
      out.error = text;
      return out;
    }
  }
  // The longest simple path uses every segment once at most.
  double total = 0.0;
  for (std::uint32_t s = 0; s < graph.segments().size(); ++s) total += graph.segment_length(s);
  const std::size_t capacity = static_cast<std::size_t>(std::ceil(total / config.spacing)) + 8;
  std::unique_ptr<Navigator> n(new Navigator(graph, config, map_shape, capacity));
  if (has_goal) {
    n->goal_ = *goal;
    n->goal_x_ = gx;
    n->goal_y_ = gy;
    n->goal_lat_ = config.goal_lat;
    n->goal_lon_ = config.goal_lon;
    n->has_goal_ = true;
    n->state_ = NavState::planning;
    ++n->counters_.goals;
    ++n->goal_revision_;
  } else {
    n->state_ = NavState::idle;
  }
  out.navigator = std::move(n);
  return out;
}

Navigator::Navigator(const osm::RoadGraph& graph, const NavigatorConfig& config, const perception::TerrainMapShape& shape,
                     std::size_t subgoal_capacity)
    : graph_(graph), config_(config), router_(graph) {
  config_.aligner.max_subgoals = subgoal_capacity;
  aligner_ = std::make_unique<subgoals::SubgoalAligner>(config_.aligner, shape);
  router_.reserve_path(route_);
  router_.reserve_path(candidate_);
  route_arc_.reserve(route_.capacity());
  subgoals_.reserve(subgoal_capacity);
  subgoal_arc_.reserve(subgoal_capacity);
  raw_.resize(subgoal_capacity);
}

double Navigator::nearest_on_route(double x, double y, double lo, double hi, double& arc) const noexcept {
  double best = std::numeric_limits<double>::max();
  arc = lo;
  // First segment whose end lies at or beyond lo.
  std::size_t i = static_cast<std::size_t>(std::lower_bound(route_arc_.begin(), route_arc_.end(), lo) - route_arc_.begin());
  i = std::max<std::size_t>(i, 1);
  for (; i < route_.size() && route_arc_[i - 1] <= hi; ++i) {
    const osm::Point2& a = route_[i - 1];
    const osm::Point2& b = route_[i];
    const double dx = b.x - a.x, dy = b.y - a.y, l2 = dx * dx + dy * dy;
    const double t = l2 > 0.0 ? std::clamp(((x - a.x) * dx + (y - a.y) * dy) / l2, 0.0, 1.0) : 0.0;
    const double d = std::hypot(x - a.x - t * dx, y - a.y - t * dy);
    if (d < best) {
      best = d;
      arc = route_arc_[i - 1] + t * (route_arc_[i] - route_arc_[i - 1]);
    }
  }
  return best;
}

void Navigator::clear_route() noexcept {
  route_.clear();
  route_arc_.clear();
  subgoals_.clear();
  subgoal_arc_.clear();
  aligner_->reset();
  active_ = 0;
  robot_arc_ = 0.0;
  ++active_revision_;
  ++path_revision_;
}

void Navigator::refuse(const char* why) noexcept {
  std::snprintf(refusal_text_, sizeof refusal_text_, "%s", why);
  ++counters_.goals_refused;
  ++goal_revision_;
}

bool Navigator::plan(const pose::UtmPose& utm, std::int64_t now, const osm::RoadProjection& goal) noexcept {
  last_plan_ns_ = now;
  off_route_since_ = -1;
  const auto t0 = std::chrono::steady_clock::now();
  const auto from = graph_.project(utm.easting, utm.northing);
  if (!from || from->distance > config_.max_snap) {
    message_ = "the robot is farther than max_snap from every routable way";
    ++counters_.plan_failures;
    return false;
  }
  // Into its own buffer: a new goal that cannot be routed leaves the route
  // being followed as it is.
  const osm::RouteStats st = router_.route(*from, goal, candidate_);
  counters_.last_plan_expanded = st.expanded;
  counters_.last_plan_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  if (!st.found || candidate_.empty()) {
    message_ = "no route from the robot's position to the goal (disconnected network or one-way streets)";
    ++counters_.plan_failures;
    return false;
  }
  route_.swap(candidate_);  // both reserved alike: no allocation
  route_arc_.clear();
  route_arc_.push_back(0.0);
  for (std::size_t i = 1; i < route_.size(); ++i) {
    route_arc_.push_back(route_arc_.back() + std::hypot(route_[i].x - route_[i - 1].x, route_[i].y - route_[i - 1].y));
  }
  const double length = route_arc_.back();
  // subsample_path keeps within the reserved capacity: at most length / spacing + 2 points.
  osm::subsample_path(route_, config_.spacing, subgoals_);
  subgoal_arc_.clear();
  for (std::size_t i = 0; i < subgoals_.size(); ++i) {
    subgoal_arc_.push_back(std::min(static_cast<double>(i) * config_.spacing, length));
  }
  subgoal_arc_.back() = length;
  aligner_->reset();
  active_ = 0;
  robot_arc_ = 0.0;
  cross_track_ = from->distance;
  message_ = "";
  ++counters_.plans;
  ++active_revision_;
  ++path_revision_;
  state_ = NavState::following;
  return true;
}

subgoals::Vec2 Navigator::to_local(const osm::Point2& p) const noexcept {
  const double dx = p.x - utm_e_, dy = p.y - utm_n_;
  return {local_.x + cos_ * dx - sin_ * dy, local_.y + sin_ * dx + cos_ * dy};
}

subgoals::Vec2 Navigator::raw_local(std::size_t i) const noexcept { return to_local(subgoals_[i]); }

subgoals::Vec2 Navigator::corrected(std::size_t i) const noexcept {
  return is_corrected(i) ? aligner_->estimate(i) : raw_local(i);
}

StepResult Navigator::step(const pose::LocalPose& local, const pose::UtmPose& utm,
                           const perception::TerrainClassMap* map) noexcept {
  StepResult result;
  ++counters_.steps;
  if (!utm.position_valid || !utm.heading_valid || utm.sigma_position() > config_.max_position_sigma) return result;
  // A pose that is no position at all is not planned or followed from.
  if (!finite(utm.easting) || !finite(utm.northing) || !finite(utm.yaw) || !finite(local.x) || !finite(local.y) ||
      !finite(local.yaw)) {
    return result;
  }
  local_ = local;
  rot_ = local.yaw - utm.yaw;
  cos_ = std::cos(rot_);
  sin_ = std::sin(rot_);
  utm_e_ = utm.easting;
  utm_n_ = utm.northing;
  have_pose_ = true;
  const std::int64_t now = local.time_ns;
  const auto interval_ns = static_cast<std::int64_t>(config_.replan_interval * 1e9);

  if (replan_now_) {
    // A new goal from outside: taken if it can be routed from here.
    replan_now_ = false;
    const bool had_route = state_ == NavState::following || state_ == NavState::reached;
    const bool planned = plan(utm, now, pending_goal_);
    if (planned || !had_route) {
      goal_ = pending_goal_;
      goal_x_ = pending_x_;
      goal_y_ = pending_y_;
      goal_lat_ = pending_lat_;
      goal_lon_ = pending_lon_;
      has_goal_ = true;
    }
    if (planned) {
      result.planned = true;
    } else {
      refuse(message_);
      if (!had_route) {
        // Nothing to keep: the goal stays and is tried again every
        // replan_interval from where the robot gets to.
        clear_route();
        state_ = NavState::failed;
        return result;
      }
      message_ = "";  // the route being followed is fine
    }
  }
  if (state_ == NavState::idle || state_ == NavState::cancelled) return result;
  if (state_ == NavState::planning || (state_ == NavState::failed && now - last_plan_ns_ >= interval_ns)) {
    result.planned = plan(utm, now, goal_);
    if (!result.planned) {
      if (state_ != NavState::failed) clear_route();
      state_ = NavState::failed;
      return result;
    }
  }
  if (state_ == NavState::failed) return result;

  // Where the robot is along the route.
  double arc = robot_arc_;
  cross_track_ = nearest_on_route(utm.easting, utm.northing, robot_arc_ - kBehind, robot_arc_ + kAhead, arc);
  if (cross_track_ > config_.leave_distance) {
    if (off_route_since_ < 0) off_route_since_ = now;
    if (static_cast<double>(now - off_route_since_) * 1e-9 >= config_.leave_time && now - last_plan_ns_ >= interval_ns &&
        state_ != NavState::reached) {
      ++counters_.replans;
      result.planned = plan(utm, now, goal_);
      if (!result.planned) {
        clear_route();
        state_ = NavState::failed;
        return result;
      }
      cross_track_ = nearest_on_route(utm.easting, utm.northing, 0.0, kAhead, arc);
    }
  } else {
    off_route_since_ = -1;
    robot_arc_ = std::max(robot_arc_, arc);  // progress along a route never goes back
  }
  if (state_ == NavState::following && robot_arc_ >= route_length() - config_.goal_tolerance) {
    state_ = NavState::reached;
    ++active_revision_;
    ++path_revision_;
  }

  // Subgoals known to the aligner: those up to `lookahead` ahead. Their raw
  // odometry-frame positions through this step's pose.
  const std::size_t n = subgoals_.size();
  std::size_t want = aligner_->count();
  while (want < n && subgoal_arc_[want] <= robot_arc_ + config_.lookahead) ++want;
  want = std::max<std::size_t>(want, 1);
  if (map != nullptr) {
    const std::size_t back = static_cast<std::size_t>(config_.aligner.sequence) + 2;
    const std::size_t from = std::min(aligner_->count(), want) > back ? std::min(aligner_->count(), want) - back : 0;
    // The route a few subgoals beyond them shapes the aligner's corner model.
    const std::size_t ahead = std::min(n, want + subgoals::SubgoalAligner::kAhead);
    for (std::size_t i = from; i < ahead; ++i) raw_[i] = raw_local(i);
    const std::span<const subgoals::Vec2> raw(raw_.data(), ahead);
    // The route's own vertices over the same stretch (and the one before
    // it): the corner model turns where the map's way turns, not where the
    // 4 m subgoals cut the corner.
    std::size_t v = static_cast<std::size_t>(std::lower_bound(route_arc_.begin(), route_arc_.end(), subgoal_arc_[from]) -
                                             route_arc_.begin());
    v = v > 0 ? v - 1 : 0;
    const double until = subgoal_arc_[ahead - 1];
    std::size_t np = 0;
    for (; v < route_.size() && np < shape_points_.size(); ++v) {
      shape_points_[np] = to_local(route_[v]);
      shape_arc_[np++] = route_arc_[v];
      if (route_arc_[v] >= until) break;
    }
    const subgoals::RouteShape shape{std::span<const subgoals::Vec2>(shape_points_.data(), np),
                                     std::span<const double>(shape_arc_.data(), np), subgoal_arc_};
    // Subgoals that join together (the robot's place on the route jumps where
    // the map is off, as at a junction mapped too far along): once the window
    // is full, each push after the first is preceded by an update, so every
    // subgoal leaves the window estimated with newer ones after it, as one at
    // a time would (not frozen where it was last the newest), and none leaves
    // it unseen. None while the window fills.
    const std::size_t k = static_cast<std::size_t>(config_.aligner.sequence);
    std::size_t pushed = 0;
    while (aligner_->count() < want) {
      if (aligner_->count() >= k && (pushed > 0 || !aligner_->estimated(aligner_->window_begin()))) {
        aligner_->update(*map, raw, shape);
        ++counters_.catch_up_updates;
      }
      if (!aligner_->push(raw, shape)) break;
      ++pushed;
    }
    aligner_->update(*map, raw, shape);
    ++counters_.updates;
    ++path_revision_;
    ++active_revision_;
    result.updated = true;
  }

  // The active subgoal: the first one more than `reach` ahead.
  std::size_t next = active_;
  while (next + 1 < n && subgoal_arc_[next] <= robot_arc_ + config_.reach) ++next;
  if (state_ == NavState::reached) next = n - 1;
  if (next != active_) {
    result.reached_begin = active_;
    result.reached_end = next;
    counters_.subgoals_reached += next - active_;
    active_ = next;
    ++active_revision_;
    ++path_revision_;
  }
  return result;
}

bool Navigator::set_goal(const GoalRequest& g) noexcept {
  ++counters_.goals;
  char why[160];
  if (g.frame == GoalFrame::unknown) {
    std::snprintf(why, sizeof why, "goal refused: frame '%.*s' is neither the odometry frame nor the map frame",
                  static_cast<int>(strnlen(g.frame_id.data(), g.frame_id.size())), g.frame_id.data());
    refuse(why);
    return false;
  }
  if (!finite(g.a) || !finite(g.b)) {
    std::snprintf(why, sizeof why, "goal refused: its %s coordinates are not finite numbers", goal_frame_name(g.frame));
    refuse(why);
    return false;
  }
  double x = g.a, y = g.b, lat = 0.0, lon = 0.0;
  switch (g.frame) {
    case GoalFrame::geographic: {
      lat = g.a;
      lon = g.b;
      const int zone = osm::standard_utm_zone(lat, lon);
      const int dz = zone == 0 ? 99 : std::min(std::abs(zone - graph_.zone()), 60 - std::abs(zone - graph_.zone()));
      // A neighbouring zone is fine (the network is projected across its
      // edge, and max_snap below decides whether the goal is near it).
      if (dz > 1 || (lat >= 0.0) != graph_.north()) {
        if (zone == 0) {
          std::snprintf(why, sizeof why, "goal refused: %.6f, %.6f is no position UTM covers (latitude within +-84, longitude within +-180)", lat, lon);
        } else {
          std::snprintf(why, sizeof why, "goal refused: %.6f, %.6f lies outside the map's UTM zone %d%c (it is in %d%c)", lat, lon,
                        graph_.zone(), graph_.north() ? 'N' : 'S', zone, lat >= 0.0 ? 'N' : 'S');
        }
        refuse(why);
        return false;
      }
      if (!graph_.to_utm(lat, lon, x, y)) {
        refuse("goal refused: cannot be projected to UTM");
        return false;
      }
      break;
    }
    case GoalFrame::utm:
      graph_.to_latlon(x, y, lat, lon);
      break;
    case GoalFrame::unknown:
      return false;  // refused above
    case GoalFrame::odom: {
      if (!have_pose_) {
        refuse("goal refused: in the odometry frame, but there is no UTM pose yet to place it");
        return false;
      }
      // The inverse of to_local through the newest pose pair.
      const double dx = g.a - local_.x, dy = g.b - local_.y;
      x = utm_e_ + cos_ * dx + sin_ * dy;
      y = utm_n_ - sin_ * dx + cos_ * dy;
      graph_.to_latlon(x, y, lat, lon);
      break;
    }
  }
  const auto projected = graph_.project(x, y);
  if (!projected || projected->distance > config_.max_snap) {
    std::snprintf(why, sizeof why, "goal refused: %.6f, %.6f lies %.0f m from the nearest routable way (max_snap %.0f m)", lat,
                  lon, projected ? projected->distance : 0.0, config_.max_snap);
    refuse(why);
    return false;
  }
  pending_goal_ = *projected;
  pending_x_ = x;
  pending_y_ = y;
  pending_lat_ = lat;
  pending_lon_ = lon;
  replan_now_ = true;
  refusal_text_[0] = '\0';
  ++goal_revision_;
  if (state_ == NavState::idle || state_ == NavState::cancelled) state_ = NavState::planning;
  return true;
}

void Navigator::cancel() noexcept {
  ++counters_.cancels;
  ++goal_revision_;
  replan_now_ = false;
  if (state_ == NavState::idle) return;
  clear_route();
  state_ = NavState::cancelled;
}

void Navigator::report(NavigationStatusReport& out) const noexcept {
  out.time_ns = local_.time_ns;
  out.state = state_;
  out.has_goal = has_goal_;
  out.goal_easting = goal_x_;
  out.goal_northing = goal_y_;
  out.goal_lat = goal_lat_;
  out.goal_lon = goal_lon_;
  out.remaining = state_ == NavState::following ? std::max(0.0, route_length() - robot_arc_) : 0.0;
  out.route_length = route_length();
  out.subgoals = subgoals_.size();
  out.active = active_;
  out.zone = graph_.zone();
  out.north = graph_.north();
  out.counters = counters_;
  out.message = message_;
  std::memcpy(out.refusal.data(), refusal_text_, out.refusal.size());
}

void Navigator::snapshot(NavigationSnapshot& out) const noexcept {
  out.state = state_;
  out.goal_revision = goal_revision_;
  report(out.report);
  out.time_ns = local_.time_ns;
  out.robot = local_;
  out.plan = counters_.plans;
  out.active_revision = active_revision_;
  out.path_revision = path_revision_;
  out.subgoals = subgoals_.size();
  out.active = active_;
  out.zone = graph_.zone();
  out.north = graph_.north();
  out.route_length = route_length();
  out.progress = robot_arc_;
  out.cross_track = cross_track_;
  out.counters = counters_;
  out.message = message_;
  out.has_active = (state_ == NavState::following || state_ == NavState::reached) && active_ < subgoals_.size();
  out.path_count = 0;
  if (!out.has_active) return;
  const std::size_t n = subgoals_.size();
  auto pose_of = [&](std::size_t i) {
    PathPose p;
    const subgoals::Vec2 v = corrected(i);
    p.x = v.x;
    p.y = v.y;
    p.corrected = is_corrected(i);
    // Heading: towards the next subgoal (from the previous one at the end).
    const subgoals::Vec2 a = i + 1 < n ? v : (i > 0 ? corrected(i - 1) : v);
    const subgoals::Vec2 b = i + 1 < n ? corrected(i + 1) : v;
    p.yaw = (a.x == b.x && a.y == b.y) ? local_.yaw : std::atan2(b.y - a.y, b.x - a.x);
    return p;
  };
  out.active_pose = pose_of(active_);
  out.active_easting = subgoals_[active_].x;
  out.active_northing = subgoals_[active_].y;
  const std::size_t count = std::min({out.path.size(), config_.path_poses, n - active_});
  for (std::size_t k = 0; k < count; ++k) out.path[k] = pose_of(active_ + k);
  out.path_count = count;
}

}  // namespace trailnav::nav
