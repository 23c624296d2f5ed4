#include "station_world.hpp"

#include <cmath>
#include <limits>
#include <numbers>

#include "random.hpp"

namespace trailnav::sim::station {

Eigen::Isometry3d to_isometry(const Pose2& p) noexcept {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = Eigen::AngleAxisd(p.theta, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  t.translation() = Eigen::Vector3d(p.x, p.y, 0.0);
  return t;
}

Pose2 compose(const Pose2& a, const Pose2& b) noexcept {
  const double c = std::cos(a.theta), s = std::sin(a.theta);
  return {a.x + c * b.x - s * b.y, a.y + s * b.x + c * b.y, std::remainder(a.theta + b.theta, 2.0 * std::numbers::pi)};
}

Pose2 inverse(const Pose2& p) noexcept {
  const double c = std::cos(p.theta), s = std::sin(p.theta);
  return {-(c * p.x + s * p.y), -(-s * p.x + c * p.y), -p.theta};
}

namespace {

Eigen::Vector2d apply(const Pose2& p, const Eigen::Vector2d& v) {
  const double c = std::cos(p.theta), s = std::sin(p.theta);
  return {p.x + c * v.x() - s * v.y(), p.y + s * v.x() + c * v.y()};
}

void add_box(std::vector<Segment>& out, const Pose2& pose, const Rect& r) {
  const double hw = 0.5 * r.w, hh = 0.5 * r.h;
  const Eigen::Vector2d c[4] = {apply(pose, {r.cx - hw, r.cy - hh}), apply(pose, {r.cx + hw, r.cy - hh}),
                                apply(pose, {r.cx + hw, r.cy + hh}), apply(pose, {r.cx - hw, r.cy + hh})};
  for (int i = 0; i < 4; ++i) out.push_back({c[i], c[(i + 1) % 4]});
}

// Looking from `view` at the object's centre.
Pose2 facing(const Eigen::Vector2d& view, const Pose2& object) {
  return {view.x(), view.y(), std::atan2(object.y - view.y(), object.x - view.x())};
}

std::array<Eigen::Vector2d, 4> marked(const Pose2& pose, double hw, double hh) {
  return {apply(pose, {-hw, -hh}), apply(pose, {hw, -hh}), apply(pose, {hw, hh}), apply(pose, {-hw, hh})};
}

}  // namespace

World thesis_world() {
  World w;
  auto wall = [&](double x0, double y0, double x1, double y1) { w.walls.push_back({{x0, y0}, {x1, y1}}); };
  // The outline, 8 m x 6 m.
  wall(0, 0, 8, 0);
  wall(8, 0, 8, 6);
  wall(8, 6, 0, 6);
  wall(0, 6, 0, 0);
  // Between the two lower rooms, a door at y 2.4–3.3 m.
  wall(4, 0, 4, 2.4);
  wall(4, 3.3, 4, 3.5);
  // The upper room's wall, doors at x 1.0–1.9 m and 5.5–6.4 m.
  wall(0, 3.5, 1.0, 3.5);
  wall(1.9, 3.5, 5.5, 3.5);
  wall(6.4, 3.5, 8, 3.5);
  // A pillar and a cupboard: the surroundings are not only flat walls.
  add_box(w.walls, {2.9, 2.6, 0.0}, {0, 0, 0.3, 0.3});
  add_box(w.walls, {7.7, 5.0, 0.0}, {0, 0, 0.6, 1.2});

  ObjectShape box{"box", {{0.0, 0.0, 0.6, 0.4}}, {6.2, 1.1, 0.3}, {}, {}};
  box.view = facing({5.15, 2.15}, box.pose);  // diagonally: two faces and the corner between them
  box.mark = marked(box.pose, 0.45, 0.35);
  // A U-shaped shelf, 1.0 m x 0.45 m of 3 cm boards, open towards +y.
  ObjectShape shelf{"shelf", {{0.0, -0.21, 1.0, 0.03}, {-0.485, 0.0, 0.03, 0.45}, {0.485, 0.0, 0.03, 0.45}},
                    {1.9, 0.9, -0.1}, {}, {}};
  shelf.view = facing({1.7, 2.5}, shelf.pose);
  shelf.mark = marked(shelf.pose, 0.6, 0.33);
  // A table of 1.2 m x 0.8 m: the laser sees its four 5 cm legs.
  ObjectShape table{"table", {{-0.55, -0.35, 0.05, 0.05}, {0.55, -0.35, 0.05, 0.05}, {-0.55, 0.35, 0.05, 0.05}, {0.55, 0.35, 0.05, 0.05}},
                    {5.6, 4.9, 0.15}, {}, {}};
  table.view = facing({4.6, 3.9}, table.pose);
  table.mark = marked(table.pose, 0.68, 0.48);
  w.objects = {box, shelf, table};
  return w;
}

std::vector<Segment> object_segments(const World& w, const std::vector<Pose2>& poses) {
  std::vector<Segment> out;
  for (std::size_t k = 0; k < w.objects.size() && k < poses.size(); ++k) {
    for (const Rect& r : w.objects[k].parts) add_box(out, poses[k], r);
  }
  return out;
}

std::vector<Eigen::Vector3f> cast(const std::vector<Segment>& segments, const Pose2& sensor, const LaserConfig& laser,
                                  std::uint64_t noise_key) {
  std::vector<Eigen::Vector3f> points;
  const int beams = static_cast<int>(std::lround(laser.fov / laser.step)) + 1;
  points.reserve(static_cast<std::size_t>(beams));
  const Eigen::Vector2d o(sensor.x, sensor.y);
  for (int i = 0; i < beams; ++i) {
    const double a = -0.5 * laser.fov + laser.step * i;
    const Eigen::Vector2d d(std::cos(sensor.theta + a), std::sin(sensor.theta + a));
    double best = std::numeric_limits<double>::infinity();
    for (const Segment& s : segments) {
      // o + t d = s.a + u (s.b − s.a), t > 0, u in [0, 1].
      const Eigen::Vector2d e = s.b - s.a;
      const double den = d.x() * e.y() - d.y() * e.x();
      if (std::abs(den) < 1e-12) continue;
      const Eigen::Vector2d w = s.a - o;
      const double t = (w.x() * e.y() - w.y() * e.x()) / den;
      const double u = (w.x() * d.y() - w.y() * d.x()) / den;
      if (t > 1e-6 && u >= 0.0 && u <= 1.0 && t < best) best = t;
    }
    if (!(best <= laser.max_range)) continue;
    const double r = best + laser.sigma * gaussian(hash(noise_key, static_cast<std::uint64_t>(i)));
    points.emplace_back(static_cast<float>(r * std::cos(a)), static_cast<float>(r * std::sin(a)), 0.0f);
  }
  return points;
}

Pose2 move_of(const ObjectShape& o, const MoveSet& set, std::uint64_t key) noexcept {
  const double direction = 2.0 * std::numbers::pi * unit(hash(key, 1));
  const double sign = unit(hash(key, 2)) < 0.5 ? -1.0 : 1.0;
  const double phi = sign * set.rotation;
  // p' = R(φ)(p − c) + c + t.
  const double c = std::cos(phi), s = std::sin(phi);
  const double tx = set.translation * std::cos(direction), ty = set.translation * std::sin(direction);
  return {o.pose.x - (c * o.pose.x - s * o.pose.y) + tx, o.pose.y - (s * o.pose.x + c * o.pose.y) + ty, phi};
}

namespace {

// The odometry's increments between consecutive true poses, noisy as the
// velocity motion model over 0.1 s (σ 0.1 m/s and 0.1 rad/s).
void odometry_of(Drive& d, std::uint64_t key, double scale) {
  constexpr double kDt = 0.1;
  const double kSigmaV = 0.1 * scale, kSigmaW = 0.1 * scale;
  d.odometry.assign(d.truth.size(), Pose2{});
  Rng rng(key, 7);
  for (std::size_t k = 1; k < d.truth.size(); ++k) {
    Pose2 inc = compose(inverse(d.truth[k - 1]), d.truth[k]);
    inc.x += kSigmaV * kDt * rng.normal();
    inc.y += kSigmaV * kDt * rng.normal();
    inc.theta += kSigmaW * kDt * rng.normal();
    d.odometry[k] = inc;
  }
}

}  // namespace

Drive teach_drive(const ObjectShape& o, int scans, std::uint64_t key, double odometry_noise) {
  Drive d;
  const double r = std::hypot(o.view.x - o.pose.x, o.view.y - o.pose.y);
  const double a0 = std::atan2(o.view.y - o.pose.y, o.view.x - o.pose.x);
  constexpr double kSpan = 70.0 * std::numbers::pi / 180.0;
  for (int k = 0; k < scans; ++k) {
    const double a = a0 + kSpan * ((scans > 1 ? static_cast<double>(k) / (scans - 1) : 0.5) - 0.5);
    const Eigen::Vector2d at(o.pose.x + r * std::cos(a), o.pose.y + r * std::sin(a));
    d.truth.push_back(facing(at, o.pose));
  }
  odometry_of(d, key, odometry_noise);
  return d;
}

Drive visit_drive(const ObjectShape& o, int scans, std::uint64_t key, double odometry_noise) {
  Drive d;
  const double back = 0.6, lateral = 0.3 * (2.0 * unit(hash(key, 3)) - 1.0);
  const double turn = (10.0 * std::numbers::pi / 180.0) * (2.0 * unit(hash(key, 4)) - 1.0);
  const double c = std::cos(o.view.theta), s = std::sin(o.view.theta);
  const Pose2 start{o.view.x - back * c - lateral * s, o.view.y - back * s + lateral * c,
                    std::remainder(o.view.theta + turn, 2.0 * std::numbers::pi)};
  for (int k = 0; k < scans; ++k) {
    const double f = scans > 1 ? static_cast<double>(k) / (scans - 1) : 1.0;
    d.truth.push_back({start.x + f * (o.view.x - start.x), start.y + f * (o.view.y - start.y),
                       start.theta + f * std::remainder(o.view.theta - start.theta, 2.0 * std::numbers::pi)});
  }
  odometry_of(d, key, odometry_noise);
  return d;
}

}  // namespace trailnav::sim::station
