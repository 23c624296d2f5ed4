#include "trailnav/perception/pose_track.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <time.h>

namespace trailnav::perception {

namespace {

double lerp_angle(double a, double b, double f) noexcept {
  double d = b - a;
  d -= 2.0 * std::numbers::pi * std::floor((d + std::numbers::pi) / (2.0 * std::numbers::pi));
  return a + f * d;
}

}  // namespace

PoseTrack::PoseTrack(std::size_t capacity) : samples_(std::max<std::size_t>(capacity, 2)) {}

bool PoseTrack::push(const Pose& pose) noexcept {
  if (count_ > 0 && pose.t_ns <= newest().t_ns) {
    ++rejected_;
    return false;
  }
  if (count_ == samples_.size()) {
    samples_[head_] = pose;
    head_ = (head_ + 1) % samples_.size();
  } else {
    samples_[(head_ + count_) % samples_.size()] = pose;
    ++count_;
  }
  return true;
}

bool PoseTrack::motion_known(std::int64_t from_ns, std::int64_t to_ns) const noexcept {
  if (count_ == 0) return true;
  // The last sample at or before `from` (or the oldest), then on to the
  // first sample at or after `to` (or the newest).
  std::size_t lo = 0, hi = count_;  // first sample later than from_ns
  while (lo < hi) {
    const std::size_t mid = lo + (hi - lo) / 2;
    if (get(mid).t_ns <= from_ns) {
      lo = mid + 1;
    } else {
      hi = mid;
    }
  }
  for (std::size_t i = lo > 0 ? lo - 1 : 0; i < count_; ++i) {
    const Pose& p = get(i);
    if (!p.motion_known) return false;
    if (p.t_ns >= to_ns) break;
  }
  return true;
}

PoseLookup PoseTrack::at(std::int64_t t_ns, Pose& out) const noexcept {
  if (count_ == 0) return PoseLookup::empty;
  if (t_ns <= oldest().t_ns) {
    out = oldest();
    out.t_ns = t_ns;
    return t_ns == oldest().t_ns ? PoseLookup::interpolated : PoseLookup::before_first;
  }
  if (t_ns >= newest().t_ns) {
    out = newest();
    out.t_ns = t_ns;
    return t_ns == newest().t_ns ? PoseLookup::interpolated : PoseLookup::after_last;
  }
  // The first sample later than t: binary search over the ring.
  std::size_t lo = 0;
  std::size_t hi = count_ - 1;  // get(hi).t_ns > t_ns, get(lo).t_ns <= t_ns
  while (hi - lo > 1) {
    const std::size_t mid = lo + (hi - lo) / 2;
    if (get(mid).t_ns <= t_ns) {
      lo = mid;
    } else {
      hi = mid;
    }
  }
  const Pose& a = get(lo);
  const Pose& b = get(hi);
  const double f = static_cast<double>(t_ns - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns);
  out.t_ns = t_ns;
  out.x = a.x + f * (b.x - a.x);
  out.y = a.y + f * (b.y - a.y);
  out.z = a.z + f * (b.z - a.z);
  out.roll = lerp_angle(a.roll, b.roll, f);
  out.pitch = lerp_angle(a.pitch, b.pitch, f);
  out.yaw = lerp_angle(a.yaw, b.yaw, f);
  out.motion_known = a.motion_known && b.motion_known;
  return PoseLookup::interpolated;
}

PoseWaitResult wait_for_pose(PoseTrack& track, PoseQueue& queue, std::int64_t t_ns, const PoseWait& wait,
                             bool may_wait) noexcept {
  PoseWaitResult r;
  r.poses = track.drain(queue);
  if (track.lag(t_ns) <= wait.max_lag_ns) {
    r.ready = true;
    return r;
  }
  if (!may_wait) return r;
  timespec start{};
  clock_gettime(CLOCK_MONOTONIC, &start);
  for (;;) {
    const timespec nap{0, static_cast<long>(wait.step_ns)};
    nanosleep(&nap, nullptr);
    r.poses += track.drain(queue);
    timespec now{};
    clock_gettime(CLOCK_MONOTONIC, &now);
    r.waited_ns = (now.tv_sec - start.tv_sec) * 1'000'000'000LL + (now.tv_nsec - start.tv_nsec);
    if (track.lag(t_ns) <= wait.max_lag_ns) {
      r.ready = true;
      return r;
    }
    if (r.waited_ns >= wait.max_wait_ns) return r;
  }
}

}  // namespace trailnav::perception
