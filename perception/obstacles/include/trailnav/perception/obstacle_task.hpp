// The obstacle thread: a thin scheduler task around ObstaclePipeline.
//
// Each run takes the newest revolution from the lidar driver's mailbox (if a
// new one arrived), the newest terrain-class map from the terrain thread's
// mailbox (if any), the pose samples queued by the pose thread, updates the
// obstacle map and publishes a snapshot of it through its own mailbox. It
// never allocates after construction; it waits only for a pose thread that
// has fallen behind the revolution, and at most PoseWait::max_wait_ns.
//
// Streaming (set_streaming()): the task follows the revolution the lidar
// task is filling (Broadcast::Reader::follow()) and works on its blocks as
// the lidar's progress word vouches for them (ObstaclePipeline::advance()),
// the pose track permitting; when the revolution is published only its last
// blocks are left. A revolution it did not follow from its start it maps
// whole, as without streaming. The maps are the same bits either way.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "trailnav/perception/obstacle_pipeline.hpp"
#include "trailnav/perception/pose_track.hpp"
#include "trailnav/runtime/broadcast.hpp"
#include "trailnav/runtime/histogram.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/spsc_queue.hpp"
#include "trailnav/runtime/status_board.hpp"
#include "trailnav/runtime/wakeup.hpp"

namespace trailnav::perception {

// What planners and publishers get: the map as 0..100 / -1 (unknown).
struct ObstacleSnapshot {
  ObstacleSnapshot(std::int32_t cells_x, std::int32_t cells_y)
      : size_x(cells_x), size_y(cells_y),
        occupancy(static_cast<std::size_t>(cells_x) * static_cast<std::size_t>(cells_y), std::int8_t{-1}) {}

  std::int32_t size_x;
  std::int32_t size_y;
  double resolution = 0.0;
  double origin_x = 0.0;  // odometry frame, m: the lower-left corner of cell (0, 0)
  double origin_y = 0.0;
  double robot_x = 0.0;  // the pose the revolution was placed with (odometry frame, at time_ns)
  double robot_y = 0.0;
  double robot_yaw = 0.0;
  double robot_z = 0.0, robot_roll = 0.0, robot_pitch = 0.0;
  std::int64_t time_ns = 0;           // end of the revolution, reference clock (what the map is stamped with)
  std::int64_t received_ns = 0;       // host receive time of the packet that completed it (0 offline)
  std::uint64_t revolution = 0;       // the range image's sequence number
  std::uint64_t terrain_sequence = 0; // terrain map used (0: none)
  std::vector<std::int8_t> occupancy; // row-major, row 0 = lowest y
};

// One revolution's points for viewers (sensor_msgs/PointCloud2 on the
// publisher's side): odometry frame, with what trailnav made of each.
struct CloudPoint {
  float x = 0.0f, y = 0.0f, z = 0.0f;  // m, odometry frame
  float intensity = 0.0f;              // 0..255
  float time = 0.0f;                   // s after the revolution's first firing
  float p_obstacle = 0.0f;             // the smooth model's P(obstacle) for the point's terrain class
  std::uint16_t ring = 0;              // 0 = lowest laser
  std::uint8_t obstacle = 0;           // 1: the Dirac model says obstacle
  std::uint8_t terrain = 0;            // the class the point was fused with (docs/terrain.md order)
};

struct PointsSnapshot {
  explicit PointsSnapshot(std::size_t capacity = 0) : points(capacity) {}
  std::int64_t time_ns = 0;  // end of the revolution, reference clock (as the map's stamp)
  std::size_t count = 0;     // points used
  std::vector<CloudPoint> points;  // capacity: rings x columns of the lidar
};

// Fills `out` with the last processed revolution's valid points (no
// allocation: at most out.points.size()).
void take_points(const ObstaclePipeline& pipeline, const TerrainClassMap* terrain, PointsSnapshot& out) noexcept;

struct ObstacleTaskCounters {
  std::uint64_t runs = 0;
  std::uint64_t revolutions = 0;       // processed
  std::uint64_t skipped = 0;           // revolutions replaced in the mailbox before this task saw them
  std::uint64_t poses = 0;
  std::uint64_t terrain_maps = 0;
  std::uint64_t point_clouds = 0;      // revolutions handed over as points for viewers
  // Revolutions not mapped because the odometry did not know the robot's
  // motion then (wheel speeds lost), and how often the map was forgotten
  // when it knew again.
  std::uint64_t no_odometry = 0;
  std::uint64_t map_resets = 0;
  bool odometry_lost = false;  // the newest revolution was not mapped for that reason
  // Revolutions whose end the pose track had not reached (within
  // PoseWait::max_lag_ns) when they came: those the task waited for, those
  // it then mapped, and those left out because the pose did not come in time.
  std::uint64_t pose_waits = 0;
  std::uint64_t pose_late = 0;
  std::int64_t pose_wait_max_ns = 0;  // longest wait
  bool pose_behind = false;           // the newest revolution was left out for that reason
  // Streaming: revolutions mapped while they arrived, blocks worked on before
  // their revolution was complete, and revolutions followed that the lidar
  // started anew (a jump in its clock) before completing them.
  std::uint64_t streamed = 0;
  std::uint64_t early_blocks = 0;
  std::uint64_t abandoned = 0;
  PipelineCounters pipeline;
};


class ObstacleTask final : public Task {
 public:
  // `poses` and `terrain` may be null.
  ObstacleTask(ObstaclePipeline& pipeline, Broadcast<velodyne::RangeImage>::Reader& revolutions, PoseQueue* poses,
               Broadcast<TerrainClassMap>::Reader* terrain, Mailbox<ObstacleSnapshot>& out, std::size_t pose_history = 512,
               PoseWait pose_wait = {});

  // Woken after each published snapshot (the DDS publisher). Before the scheduler starts.
  void set_notify(Wakeup* wakeup) noexcept { notify_ = wakeup; }
  // Also hands a revolution's points to `out` at most every `period_ns`
  // (viewers; off unless set). Before the scheduler starts.
  void set_points(Mailbox<PointsSnapshot>* out, std::int64_t period_ns) noexcept {
    points_out_ = out;
    points_period_ns_ = period_ns;
  }
  // Also hands every revolution it takes to `out`: its points as aligned
  // (before smoothing), or why it was not mapped (the terrain thread, which
  // then need not align it again). Before the scheduler starts.
  void set_aligned(Mailbox<AlignedRevolution>* out) noexcept { aligned_out_ = out; }
  // Works on each revolution while it arrives (above). Before the scheduler starts.
  void set_streaming(bool on) noexcept { streaming_ = on; }

  void run(const TaskTick& tick) override;
  // The task thread's own counters.
  const ObstacleTaskCounters& counters() const noexcept { return counters_; }
  // A copy for other threads (health).
  ObstacleTaskCounters status() const noexcept { return shared_.read(); }
  // Host time from the receipt of the packet that completed a revolution to
  // its map's snapshot published (the lidar task's pick-up, this task's
  // wake-up and the work left at the revolution's end); any thread.
  DurationSummary map_delay() const noexcept { return map_delay_.summary(); }

 private:
  void take_terrain() noexcept;
  // Maps a complete revolution not followed: the whole of it.
  void map_whole(const velodyne::RangeImage& image) noexcept;
  // The checks before mapping `image`, whole or at its end: false when not
  // to publish it (its outcome handed over).
  bool pose_ready(const velodyne::RangeImage& image) noexcept;
  bool odometry_ready(const velodyne::RangeImage& image) noexcept;
  // After the pipeline mapped `image`: snapshot, points, hand-over.
  void publish(const velodyne::RangeImage& image) noexcept;
  // Streaming: one step on the revolution followed; false when there is
  // nothing more to do this run.
  bool follow_step() noexcept;
  // The columns of `image`, of those final, whose poses the track has (within the lag).
  int posed_columns(const velodyne::RangeImage& image, int final_columns) const noexcept;

  ObstaclePipeline& pipeline_;
  Broadcast<velodyne::RangeImage>::Reader& revolutions_;
  PoseQueue* poses_;
  Broadcast<TerrainClassMap>::Reader* terrain_;
  Mailbox<ObstacleSnapshot>& out_;
  PoseTrack track_;
  PoseWait pose_wait_;
  const TerrainClassMap* terrain_map_ = nullptr;
  std::uint64_t last_sequence_ = 0;
  ObstacleTaskCounters counters_;
  StatusBoard<ObstacleTaskCounters> shared_;
  Wakeup* notify_ = nullptr;
  Mailbox<PointsSnapshot>* points_out_ = nullptr;
  Mailbox<AlignedRevolution>* aligned_out_ = nullptr;
  std::int64_t points_period_ns_ = 0;
  std::int64_t last_points_ns_ = 0;
  bool streaming_ = false;
  DurationHistogram map_delay_;
  // The revolution followed: none, followed (slot held), begun (in the pipeline).
  const velodyne::RangeImage* followed_ = nullptr;
  bool begun_ = false;
  std::uint32_t generation_ = 0;
};

// Fills a snapshot from a map (no allocation when the sizes match).
void take_snapshot(const ObstacleMap& map, const RevolutionCloud& cloud, ObstacleSnapshot& out) noexcept;

}  // namespace trailnav::perception
