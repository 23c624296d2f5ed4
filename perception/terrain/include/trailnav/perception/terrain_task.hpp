// The terrain thread (thesis §7.3): a thin scheduler task around
// TerrainMapper, asynchronous to the obstacle thread. Each run takes the
// newest revolution the obstacle thread aligned and handed on (its points as
// aligned, RevolutionCloud::hand_over_aligned()), or, in a daemon without the
// obstacle thread, from its own reader of the lidar driver's revolutions with
// the poses the pose thread queued for it; after each classification step it
// publishes a copy of the class map through a Broadcast (the obstacle fusion,
// the DDS publisher and navigation each hold a reader). It never allocates
// after construction and never waits.
#pragma once

#include <cstdint>

#include "trailnav/perception/pose_track.hpp"
#include "trailnav/perception/terrain_mapper.hpp"
#include "trailnav/runtime/broadcast.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/status_board.hpp"
#include "trailnav/runtime/wakeup.hpp"

namespace trailnav::perception {

struct TerrainTaskCounters {
  std::uint64_t runs = 0;
  std::uint64_t revolutions = 0;  // processed
  std::uint64_t skipped = 0;      // revolutions that came and went between two runs
  // Each class map depends on every revolution before it: the end
  // (reference clock) of the last revolution taken before the first skip;
  // the maps up to it are as an offline run over every revolution makes
  // them. -1 while none was skipped.
  std::int64_t intact_until_ns = -1;
  std::uint64_t poses = 0;
  std::uint64_t published = 0;    // class-map snapshots
  std::uint64_t no_odometry = 0;  // revolutions left out: the odometry did not know the robot's motion then
  std::uint64_t pose_waits = 0;   // revolutions the pose track had not reached: waited for (PoseWait)
  std::uint64_t pose_late = 0;    // ... and left out, the pose not coming in time
  std::int64_t pose_wait_max_ns = 0;
  bool pose_behind = false;       // the newest revolution was left out for that reason
  std::int64_t last_step_ns = 0;  // sensor time of the newest step
  TerrainCounters mapper;
};

class TerrainTask final : public Task {
 public:
  // `poses` may be null (no pose stream: the map stays where it started).
  TerrainTask(TerrainMapper& mapper, Broadcast<velodyne::RangeImage>::Reader& revolutions, PoseQueue* poses,
              Broadcast<TerrainClassMap>& out, std::size_t pose_history = 512, PoseWait pose_wait = {});
  // Registers what the obstacle thread aligned (ObstacleTask::set_aligned()),
  // with the same alignment (TerrainMapper::create()).
  TerrainTask(TerrainMapper& mapper, Mailbox<AlignedRevolution>& aligned, Broadcast<TerrainClassMap>& out);

  // Woken after each published class map (the DDS publisher). Before the scheduler starts.
  void set_notify(Wakeup* wakeup) noexcept { notify_ = wakeup; }

  void run(const TaskTick& tick) override;
  const TerrainTaskCounters& counters() const noexcept { return counters_; }
  TerrainTaskCounters status() const noexcept { return shared_.read(); }

 private:
  // A revolution with this sequence number and end was taken: counts skips.
  void took(std::uint64_t sequence, std::int64_t reference_end_ns) noexcept;
  void run_aligned() noexcept;
  void publish() noexcept;

  TerrainMapper& mapper_;
  Broadcast<velodyne::RangeImage>::Reader* revolutions_ = nullptr;
  Mailbox<AlignedRevolution>* aligned_ = nullptr;
  PoseQueue* poses_;
  Broadcast<TerrainClassMap>& out_;
  PoseTrack track_;
  PoseWait pose_wait_;
  std::int64_t last_taken_end_ns_ = 0;
  std::uint64_t last_sequence_ = 0;
  TerrainTaskCounters counters_;
  StatusBoard<TerrainTaskCounters> shared_;
  Wakeup* notify_ = nullptr;
};

}  // namespace trailnav::perception
