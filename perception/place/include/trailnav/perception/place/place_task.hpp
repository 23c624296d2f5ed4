// The place task of trailnavd (issue 41, thesis chapter 5 on the robot): each
// new camera frame (drivers/camera/camera_driver.hpp's mailbox) described and
// stepped through the forward filter over a place database recorded on an
// earlier drive (database.hpp), and the answer published as a snapshot: the
// database image most likely seen, the belief's mass within ±window images
// of it (its probability), and the pose the robot had there with a
// covariance: the belief-weighted spread of the database's poses within the
// window, plus a floor (the database's own spacing and the camera's offset
// from where the image was taken are not known better).
//
// With a lag L (OnlineConfig::lag) the answer is for the frame L frames
// back, from the fixed-lag smoothed belief, and says whether it passed the
// online sequence test; its stamp is that frame's.
//
// Runs with normal scheduling (a step over 10,000 images is about a
// millisecond, docs/place.md) on the camera's thread. Nothing allocated after
// construction.
#pragma once

#include <atomic>
#include <cstdint>
#include <vector>

#include "trailnav/drivers/camera/camera_driver.hpp"
#include "trailnav/perception/place/database.hpp"
#include "trailnav/perception/place/online.hpp"
#include "trailnav/perception/place/place_snapshot.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/wakeup.hpp"

namespace trailnav::perception::place {

struct PlaceTaskOptions {
  int window = 10;              // database images either side of the peak
  double position_floor_m = 2.0;  // σ added to the spread in x and y
  double yaw_floor_rad = 0.17;  // σ added in yaw (about 10°)
};

struct PlaceCounters {
  std::uint64_t frames = 0;  // camera frames taken
  std::uint64_t steps = 0;     // answers published
  std::uint64_t in_sequence = 0;  // of them, in a sequence
  double last_probability = 0.0;
  int last_index = -1;
};

class PlaceTask final : public Task {
 public:
  // `database`'s poses are kept (copied) here; `place` holds its codes.
  PlaceTask(const PlaceDatabase& database, OnlinePlace& place, Mailbox<drivers::camera::CameraFrame>& frames,
            Mailbox<PlaceSnapshot>& out, const PlaceTaskOptions& options);
  void run(const TaskTick& tick) override;
  void set_notify(Wakeup* wakeup) noexcept { notify_ = wakeup; }
  // Every answer also into this mailbox (the pose thread's). Before the
  // scheduler starts.
  void set_second_output(Mailbox<PlaceSnapshot>* out) noexcept { second_out_ = out; }
  PlaceCounters counters() const noexcept;

 private:
  struct Pose {
    std::int64_t t;
    double x, y, yaw, lat, lon;
  };
  struct Frame {
    std::int64_t stamp_ns = 0;
    std::uint32_t sequence = 0;
  };
  std::vector<Pose> poses_;
  std::vector<Frame> frames_ring_;  // lag + 1: the frames stepped, by step number
  OnlinePlace& place_;
  Mailbox<drivers::camera::CameraFrame>& frames_;
  Mailbox<PlaceSnapshot>& out_;
  PlaceTaskOptions options_;
  Wakeup* notify_ = nullptr;
  Mailbox<PlaceSnapshot>* second_out_ = nullptr;
  std::uint64_t steps_ = 0;
  std::uint64_t in_sequence_ = 0;
  std::atomic<std::uint64_t> frames_seen_{0}, steps_seen_{0}, in_sequence_seen_{0};
  std::atomic<double> last_probability_{0.0};
  std::atomic<int> last_index_{-1};
};

}  // namespace trailnav::perception::place
