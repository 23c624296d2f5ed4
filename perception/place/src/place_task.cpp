#include "trailnav/perception/place/place_task.hpp"

#include <cmath>
#include <numbers>

namespace trailnav::perception::place {

PlaceTask::PlaceTask(const PlaceDatabase& database, OnlinePlace& place, Mailbox<drivers::camera::CameraFrame>& frames,
                     Mailbox<PlaceSnapshot>& out, const PlaceTaskOptions& options)
    : place_(place), frames_(frames), out_(out), options_(options) {
  poses_.reserve(database.entries.size());
  for (const PlaceEntry& e : database.entries) poses_.push_back({e.time_ns, e.x, e.y, e.yaw, e.lat, e.lon});
  frames_ring_.resize(static_cast<std::size_t>(place.lag()) + 1);
}

void PlaceTask::run(const TaskTick&) {
  const drivers::camera::CameraFrame* f = frames_.try_read();
  if (f == nullptr) return;
  frames_seen_.fetch_add(1, std::memory_order_relaxed);
  const std::uint64_t step = place_.steps();
  frames_ring_[step % frames_ring_.size()] = {f->stamp_ns, f->sequence};
  place_.step(place_.describe(f->pixels, f->width));
  if (place_.steps() == step) return;  // no database
  // The answer for the frame `lag` steps back (the newest when there is no lag).
  const LaggedEstimate& e = place_.lagged();
  if (!e.valid || e.index < 0 || static_cast<std::size_t>(e.index) >= poses_.size()) return;
  const Frame& answered = frames_ring_[e.step % frames_ring_.size()];
  ++steps_;
  if (e.in_sequence) ++in_sequence_;
  // The belief within the window: its mass, and the weighted spread of the
  // database's poses there (yaw about the peak's, wrapped).
  const std::span<const double> bel = place_.lagged_belief();
  const int n = static_cast<int>(bel.size());
  const int lo = std::max(0, e.index - options_.window), hi = std::min(n - 1, e.index + options_.window);
  const Pose& p = poses_[static_cast<std::size_t>(e.index)];
  double mass = 0.0, mx = 0.0, my = 0.0, myaw = 0.0, mlat = 0.0, mlon = 0.0;
  for (int j = lo; j <= hi; ++j) {
    const double w = bel[static_cast<std::size_t>(j)];
    const Pose& q = poses_[static_cast<std::size_t>(j)];
    mass += w;
    mx += w * q.x;
    my += w * q.y;
    myaw += w * std::remainder(q.yaw - p.yaw, 2.0 * std::numbers::pi);
    // Latitude and longitude as the peak's plus weighted differences (a
    // window spans metres: linear in degrees is exact enough; NaN spreads).
    mlat += w * (q.lat - p.lat);
    mlon += w * (q.lon - p.lon);
  }
  PlaceSnapshot& s = out_.write_slot();
  s.stamp_ns = answered.stamp_ns;
  s.frame_sequence = answered.sequence;
  s.lag = place_.lag();
  s.chain = e.chain;
  s.in_sequence = e.in_sequence;
  s.number = steps_;
  s.index = e.index;
  s.peak = e.probability;
  s.probability = mass;
  s.database_stamp_ns = p.t;
  s.lat = p.lat;
  s.lon = p.lon;
  if (mass > 0.0) {
    mx /= mass;
    my /= mass;
    myaw /= mass;
    s.lat = p.lat + mlat / mass;
    s.lon = p.lon + mlon / mass;
  } else {
    mx = p.x;
    my = p.y;
    myaw = 0.0;
  }
  double cxx = 0.0, cxy = 0.0, cyy = 0.0, cyaw = 0.0;
  for (int j = lo; j <= hi && mass > 0.0; ++j) {
    const double w = bel[static_cast<std::size_t>(j)] / mass;
    const Pose& q = poses_[static_cast<std::size_t>(j)];
    const double dx = q.x - mx, dy = q.y - my;
    const double dyaw = std::remainder(q.yaw - p.yaw, 2.0 * std::numbers::pi) - myaw;
    cxx += w * dx * dx;
    cxy += w * dx * dy;
    cyy += w * dy * dy;
    cyaw += w * dyaw * dyaw;
  }
  s.x = mx;
  s.y = my;
  s.yaw = std::remainder(p.yaw + myaw, 2.0 * std::numbers::pi);
  s.cov_xx = cxx + options_.position_floor_m * options_.position_floor_m;
  s.cov_xy = cxy;
  s.cov_yy = cyy + options_.position_floor_m * options_.position_floor_m;
  s.var_yaw = cyaw + options_.yaw_floor_rad * options_.yaw_floor_rad;
  if (second_out_ != nullptr) {
    second_out_->write_slot() = s;
    second_out_->publish();
  }
  out_.publish();
  steps_seen_.store(steps_, std::memory_order_relaxed);
  in_sequence_seen_.store(in_sequence_, std::memory_order_relaxed);
  last_probability_.store(mass, std::memory_order_relaxed);
  last_index_.store(e.index, std::memory_order_relaxed);
  if (notify_ != nullptr) notify_->notify();
}

PlaceCounters PlaceTask::counters() const noexcept {
  PlaceCounters c;
  c.frames = frames_seen_.load(std::memory_order_relaxed);
  c.steps = steps_seen_.load(std::memory_order_relaxed);
  c.in_sequence = in_sequence_seen_.load(std::memory_order_relaxed);
  c.last_probability = last_probability_.load(std::memory_order_relaxed);
  c.last_index = last_index_.load(std::memory_order_relaxed);
  return c;
}

}  // namespace trailnav::perception::place
