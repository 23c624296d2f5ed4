#include "trailnav/drivers/can/wheel_odometry.hpp"

#include <cmath>

namespace trailnav::can {

WheelOdometry::Created WheelOdometry::create(const Dbc& dbc, const WheelOdometryOptions& o) {
  Created r;
  std::unique_ptr<WheelOdometry> w(new WheelOdometry());
  w->options_ = o;
  auto bind = [&](const SignalRef& ref, const char* role, Bound& b) -> bool {
    const DbcMessage* m = dbc.message(ref.message);
    if (!m) {
      r.error = dbc.file + ": no message '" + ref.message + "' (odometry " + role + ")";
      return false;
    }
    const DbcSignal* s = m->signal(ref.signal);
    if (!s) {
      r.error = dbc.file + ": message " + ref.message + " has no signal '" + ref.signal + "' (odometry " + role + ")";
      return false;
    }
    if (s->multiplexed_by || s->multiplexer) {
      r.error = dbc.file + ":" + std::to_string(s->line) + ": " + ref.message + "." + ref.signal +
                " is multiplexed, which the odometry does not support";
      return false;
    }
    b.id = m->id | (m->extended ? kEffFlag : 0u);
    b.signal = *s;
    b.used = true;
    b.range = std::ldexp(1.0, s->length) * std::abs(s->factor);
    return true;
  };
  if (o.left.empty() || o.right.empty()) {
    r.error = "odometry: the left and right wheel signals must both be configured";
    return r;
  }
  if (!bind(o.left, "left", w->left_) || !bind(o.right, "right", w->right_)) return r;
  if (!(o.track > 0.0)) {
    r.error = "odometry: track must be positive (m between the wheels)";
    return r;
  }
  if (o.input == WheelInput::ticks && !(o.ticks_per_metre > 0.0)) {
    r.error = "odometry: ticks input needs ticks_per_metre > 0";
    return r;
  }
  if (o.input == WheelInput::speed && !(o.speed_scale > 0.0)) {
    r.error = "odometry: speed_scale must be positive";
    return r;
  }
  if (!o.steering.empty()) {
    if (o.platform != Platform::ackermann) {
      r.error = "odometry: a steering signal needs platform ackermann";
      return r;
    }
    if (!(o.wheelbase > 0.0) || o.steering_scale == 0.0) {
      r.error = "odometry: steering needs wheelbase > 0 and a non-zero steering_scale";
      return r;
    }
    if (!bind(o.steering, "steering", w->steering_)) return r;
  }
  if (!(o.max_speed > 0.0) || !(o.max_gap > 0.0)) {
    r.error = "odometry: max_speed and max_gap must be positive";
    return r;
  }
  r.odometry = std::move(w);
  return r;
}

std::size_t WheelOdometry::ids(std::uint32_t* out, std::size_t capacity) const noexcept {
  std::size_t n = 0;
  for (const Bound* b : {&left_, &right_, &steering_}) {
    if (!b->used) continue;
    bool seen = false;
    for (std::size_t i = 0; i < n; ++i) seen = seen || out[i] == b->id;
    if (!seen && n < capacity) out[n++] = b->id;
  }
  return n;
}

bool WheelOdometry::on_frame(const Frame& f) noexcept {
  if (f.error() || f.remote()) return false;
  const std::uint32_t id = f.identifier() | (f.extended() ? kEffFlag : 0u);
  bool matched = false;
  for (Bound* b : {&left_, &right_, &steering_}) {
    if (!b->used || b->id != id) continue;
    matched = true;
    double v = 0.0;
    if (decode_signal(b->signal, f.payload(), v) != SignalError::none) {
      ++counters_.decode_errors;
      continue;
    }
    b->value = v;
    b->fresh = true;
  }
  if (!matched) return false;
  ++counters_.frames;
  if (!left_.fresh || !right_.fresh) return false;
  integrate(f.time_ns);
  return true;
}

void WheelOdometry::integrate(std::int64_t time_ns) noexcept {
  left_.fresh = right_.fresh = false;
  const double dt = have_reading_ ? static_cast<double>(time_ns - last_reading_) * 1e-9 : 0.0;
  last_reading_ = time_ns;
  have_reading_ = true;
  if (dt < 0.0) ++counters_.time_back;
  double vl = 0.0, vr = 0.0;
  if (options_.input == WheelInput::speed) {
    vl = left_.value * options_.speed_scale;
    vr = right_.value * options_.speed_scale;
  } else {
    // Ticks: distance since the last reading, across the counter's wrap.
    auto delta = [&](Bound& b) {
      double d = b.have_ticks ? b.value - b.last_ticks : 0.0;
      if (d > b.range / 2) d -= b.range;
      if (d < -b.range / 2) d += b.range;
      b.last_ticks = b.value;
      b.have_ticks = true;
      return d / options_.ticks_per_metre;
    };
    const double dl = delta(left_), dr = delta(right_);
    if (dt <= 0.0 || dt > options_.max_gap) {
      if (dt > options_.max_gap) ++counters_.gaps;
      state_.time_ns = time_ns;
      return;
    }
    vl = dl / dt;
    vr = dr / dt;
  }
  if (std::abs(vl) > options_.max_speed || std::abs(vr) > options_.max_speed || !std::isfinite(vl) ||
      !std::isfinite(vr)) {
    ++counters_.implausible;
    return;
  }
  const double v = 0.5 * (vl + vr);
  double w = (vr - vl) / options_.track;
  if (steering_.used && steering_.fresh) {
    w = v * std::tan(steering_.value * options_.steering_scale) / options_.wheelbase;
    steering_.fresh = false;
  }
  if (dt > options_.max_gap) {
    ++counters_.gaps;
  } else if (dt > 0.0) {
    // Midpoint rule over the interval, with the new speeds.
    const double mid = state_.yaw + 0.5 * w * dt;
    state_.x += v * dt * std::cos(mid);
    state_.y += v * dt * std::sin(mid);
    state_.yaw = std::remainder(state_.yaw + w * dt, 2.0 * M_PI);
    state_.distance += std::abs(v) * dt;
  }
  state_.speed = v;
  state_.yaw_rate = w;
  state_.time_ns = time_ns;
  ++state_.updates;
  ++counters_.updates;
}

}  // namespace trailnav::can
