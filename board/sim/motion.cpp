#include "motion.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "random.hpp"

namespace trailnav::sim {
namespace {

constexpr double kPi = std::numbers::pi;

double wrap(double a) {
  while (a > kPi) a -= 2 * kPi;
  while (a < -kPi) a += 2 * kPi;
  return a;
}

// Route progress: the nearest point within a window around the last one, so
// the robot never jumps to another pass of a crossing.
double progress(const Polyline& route, const Vec2& p, double last) {
  double best = last;
  double best_d = 1e300;
  const double lo = std::max(0.0, last - 2.0);
  const double hi = std::min(route.length(), last + 6.0);
  for (double a = lo; a <= hi; a += 0.05) {
    const double d = (route.at(a) - p).squaredNorm();
    if (d < best_d) {
      best_d = d;
      best = a;
    }
  }
  return best;
}

// Heading change per metre over the next `span` metres of the route.
double curvature_ahead(const Polyline& route, double arc, double span) {
  double kmax = 0.0;
  for (double a = arc; a < std::min(arc + span, route.length() - 1.0); a += 0.5) {
    const Vec2 t0 = route.tangent(a);
    const Vec2 t1 = route.tangent(a + 1.0);
    const double k = std::abs(std::atan2(t0.x() * t1.y() - t0.y() * t1.x(), t0.dot(t1)));
    kmax = std::max(kmax, k);
  }
  return kmax;
}

}  // namespace

Eigen::Matrix3d rotation(double roll, double pitch, double yaw) noexcept {
  return (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

PoseSample Trajectory::at(double t) const noexcept {
  if (samples.empty()) return {};
  const double f = t * kRate;
  if (f <= 0.0) return samples.front();
  const auto i = static_cast<std::size_t>(f);
  if (i + 1 >= samples.size()) return samples.back();
  const double w = f - static_cast<double>(i);
  const PoseSample& a = samples[i];
  const PoseSample& b = samples[i + 1];
  PoseSample s;
  s.t = t;
  s.p = a.p + (b.p - a.p) * w;
  s.roll = a.roll + (b.roll - a.roll) * w;
  s.pitch = a.pitch + (b.pitch - a.pitch) * w;
  s.yaw = a.yaw + (b.yaw - a.yaw) * w;
  s.v = a.v + (b.v - a.v) * w;
  s.yaw_rate = a.yaw_rate + (b.yaw_rate - a.yaw_rate) * w;
  s.v_left = a.v_left + (b.v_left - a.v_left) * w;
  s.v_right = a.v_right + (b.v_right - a.v_right) * w;
  s.arc = a.arc + (b.arc - a.arc) * w;
  return s;
}

Trajectory drive(const Scenario& s, const RoadNetwork& roads, const World& world, double duration, std::uint64_t seed) {
  const RobotSpec& r = s.robot;
  const Polyline& route = roads.route;
  const double dt = 1.0 / Trajectory::kRate;
  const std::uint64_t k_wander = hash(seed, 0x3A3A);

  double arc = std::min(r.start_offset, route.length() - 1.0);
  Vec2 xy = route.at(arc);
  const Vec2 t0 = route.tangent(arc);
  double yaw = std::atan2(t0.y(), t0.x());
  double v = 0.0;
  double omega = 0.0;
  // Suspension state.
  double z = world.ground(xy.x(), xy.y());
  double roll = 0.0, pitch = 0.0;
  double z_rate = 0.0, roll_rate = 0.0, pitch_rate = 0.0;
  bool settled = false;

  Trajectory traj;
  double stopped_for = 0.0;
  for (long step = 0;; ++step) {
    const double t = static_cast<double>(step) * dt;
    if (duration > 0.0 && t > duration + 1e-9) break;
    if (duration <= 0.0 && stopped_for > 1.0) break;
    if (t > 36000.0) break;

    // Ground under the wheels.
    const double c = std::cos(yaw), sn = std::sin(yaw);
    auto wheel = [&](double fx, double fy) {
      return world.ground(xy.x() + c * fx - sn * fy, xy.y() + sn * fx + c * fy);
    };
    const double hw = r.wheelbase / 2, ht = r.track / 2;
    const double fl = wheel(hw, ht), fr = wheel(hw, -ht), rl = wheel(-hw, ht), rr = wheel(-hw, -ht);
    const double z_target = (fl + fr + rl + rr) / 4;
    const double pitch_target = std::atan2(((rl + rr) - (fl + fr)) / 2, r.wheelbase);
    const double roll_target = std::atan2(((fl + rl) - (fr + rr)) / 2, r.track);
    if (!settled) {
      z = z_target;
      roll = roll_target;
      pitch = pitch_target;
      settled = true;
    }
    // A critically damped suspension at 3 Hz: bumps reach the body smoothed,
    // with bounded accelerations.
    const double w = 2.0 * kPi * 3.0;
    auto spring = [&](double target, double& x, double& rate) {
      rate += (w * w * (target - x) - 2.0 * w * rate) * dt;
      x += rate * dt;
    };
    spring(z_target, z, z_rate);
    spring(roll_target, roll, roll_rate);
    spring(pitch_target, pitch, pitch_rate);

    PoseSample ps;
    ps.t = t;
    ps.p = {xy.x(), xy.y(), z};
    ps.roll = roll;
    ps.pitch = pitch;
    ps.yaw = yaw;
    ps.v = v;
    ps.yaw_rate = omega;
    ps.v_left = v - omega * r.track / 2;
    ps.v_right = v + omega * r.track / 2;
    ps.arc = arc;
    traj.samples.push_back(ps);

    // Speed: acceleration limit, curvature ahead, stop at the end.
    arc = progress(route, xy, arc);
    const double remaining = route.length() - arc;
    double v_target = r.max_speed;
    const double k = curvature_ahead(route, arc, 4.0);
    if (k > 1e-3) v_target = std::min(v_target, std::sqrt(r.lateral_acceleration / k));
    v_target = std::min(v_target, std::sqrt(std::max(0.0, 2.0 * r.acceleration * (remaining - 0.3))));
    if (remaining < 0.3) v_target = 0.0;
    v += std::clamp(v_target - v, -r.acceleration * dt, r.acceleration * dt);
    v = std::max(v, 0.0);
    stopped_for = (v == 0.0 && remaining < 0.5) ? stopped_for + dt : 0.0;

    // Steering: pure pursuit plus a little human-like wander.
    const Vec2 goal = route.at(arc + r.lookahead);
    const double bearing = wrap(std::atan2(goal.y() - xy.y(), goal.x() - xy.x()) - yaw);
    const double ld = std::max((goal - xy).norm(), 0.5);
    double omega_cmd = v * 2.0 * std::sin(bearing) / ld + 0.03 * v * value_noise(k_wander, t, 0.0, 4.0);
    omega_cmd = std::clamp(omega_cmd, -0.8, 0.8);
    omega += std::clamp(omega_cmd - omega, -2.0 * dt, 2.0 * dt);

    yaw += omega * dt;
    xy += Vec2(std::cos(yaw), std::sin(yaw)) * v * dt;
  }
  return traj;
}

}  // namespace trailnav::sim
