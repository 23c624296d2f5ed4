// A short history of the robot's pose in the local odometry frame, for
// gravity alignment and motion compensation of a lidar revolution.
//
// The odometry frame is gravity-aligned: z points up, x and y are
// horizontal, and the robot drifts in it only as its odometry does. The pose
// thread pushes samples in time order; the obstacle thread asks for the pose
// at any firing time and gets it interpolated (linear in position, along the
// shorter arc in angles). The storage is a ring allocated at construction.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "trailnav/runtime/spsc_queue.hpp"

namespace trailnav::perception {

struct Pose {
  std::int64_t t_ns = 0;
  double x = 0.0;  // m, odometry frame
  double y = 0.0;
  double z = 0.0;
  double roll = 0.0;  // rad: R = Rz(yaw) * Ry(pitch) * Rx(roll), robot to odometry frame
  double pitch = 0.0;
  double yaw = 0.0;
  // False while the odometry could not measure the robot's motion: the wheel
  // speeds lost (the position stands still), or the IMU lost once heard (the
  // wheels' yaw rate alone turns the pose, and wheel slip turns it wrong).
  // The obstacle and terrain threads do not map with it.
  bool motion_known = true;
};

// Pose samples from the pose thread to the obstacle (and terrain) thread.
inline constexpr std::size_t kPoseQueueCapacity = 1024;
using PoseQueue = SpscQueue<Pose, kPoseQueueCapacity>;

enum class PoseLookup : std::uint8_t {
  interpolated,  // between two samples
  before_first,  // earlier than the oldest sample: the oldest one
  after_last,    // later than the newest sample: the newest one
  empty,         // no samples
};

class PoseTrack {
 public:
  explicit PoseTrack(std::size_t capacity);

  // Appends a sample; false (and counted) when it is not later than the newest.
  bool push(const Pose& pose) noexcept;
  // Moves every queued sample into the track; returns how many were queued.
  std::uint64_t drain(PoseQueue& queue) noexcept {
    std::uint64_t n = 0;
    Pose p;
    while (queue.try_pop(p)) {
      push(p);
      ++n;
    }
    return n;
  }
  void clear() noexcept { count_ = 0; }

  std::size_t size() const noexcept { return count_; }
  std::size_t capacity() const noexcept { return samples_.size(); }
  const Pose& newest() const noexcept { return get(count_ - 1); }  // precondition: size() > 0
  const Pose& oldest() const noexcept { return get(0); }

  PoseLookup at(std::int64_t t_ns, Pose& out) const noexcept;
  // Whether the odometry measured the robot's motion over [from, to]: every
  // sample in it and the two around it have motion_known (an empty
  // track knows nothing better: true). What the obstacle and terrain threads
  // ask before mapping a revolution.
  bool motion_known(std::int64_t from_ns, std::int64_t to_ns) const noexcept;
  // How far the newest sample lies before `t_ns` (0 when at or after it, or
  // when the track is empty: nothing to wait for).
  std::int64_t lag(std::int64_t t_ns) const noexcept {
    return count_ == 0 || newest().t_ns >= t_ns ? 0 : t_ns - newest().t_ns;
  }

  std::uint64_t rejected() const noexcept { return rejected_; }

 private:
  const Pose& get(std::size_t i) const noexcept { return samples_[(head_ + i) % samples_.size()]; }

  std::vector<Pose> samples_;
  std::size_t head_ = 0;  // oldest
  std::size_t count_ = 0;
  std::uint64_t rejected_ = 0;
};

// Waiting for the pose thread. A revolution placed with poses that end before
// it does would be placed, for its last columns, where the robot was at the
// newest pose: when the pose thread falls behind (it lost its core to other
// work), the cells the robot has moved past since would be mapped from the
// wrong place, and free cells the lidar has not seen would follow. So the
// obstacle and terrain threads map a revolution only once the track reaches
// its end within `max_lag_ns`, waiting (asleep, in `step_ns` naps, no
// allocation) at most `max_wait_ns` for the pose thread to catch up.
struct PoseWait {
  std::int64_t max_lag_ns = 30'000'000;   // a pose period and the IMU's, with room
  std::int64_t max_wait_ns = 60'000'000;  // under a revolution: the next one is not delayed
  std::int64_t step_ns = 1'000'000;
};

struct PoseWaitResult {
  bool ready = false;          // the track reaches the time (within the lag)
  std::int64_t waited_ns = 0;  // time spent asleep
  std::uint64_t poses = 0;     // samples drained meanwhile
};

// Drains `queue` into `track` until the track's lag behind `t_ns` is at most
// `wait.max_lag_ns` or `wait.max_wait_ns` has passed; `may_wait` false only
// checks (after a revolution that waited in vain, not to wait on each one
// while the pose is down).
PoseWaitResult wait_for_pose(PoseTrack& track, PoseQueue& queue, std::int64_t t_ns, const PoseWait& wait,
                             bool may_wait) noexcept;

// What the obstacle and terrain tasks do with it, on their counters (fields
// poses, pose_waits, pose_late, pose_wait_max_ns, pose_behind): wait unless
// the last revolution already waited in vain, count, and say whether the
// revolution may be mapped.
template <class Counters>
bool await_pose(PoseTrack& track, PoseQueue& queue, std::int64_t t_ns, const PoseWait& wait, Counters& c) noexcept {
  const PoseWaitResult w = wait_for_pose(track, queue, t_ns, wait, !c.pose_behind);
  c.poses += w.poses;
  if (w.waited_ns > 0) {
    ++c.pose_waits;
    if (w.waited_ns > c.pose_wait_max_ns) c.pose_wait_max_ns = w.waited_ns;
  }
  c.pose_behind = !w.ready;
  if (!w.ready) ++c.pose_late;
  return w.ready;
}

}  // namespace trailnav::perception
