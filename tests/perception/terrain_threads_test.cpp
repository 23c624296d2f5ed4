// The obstacle and terrain threads together (thesis §7.3: two asynchronous
// threads, two maps): real KITTI revolutions go out through one Broadcast
// to both; the terrain thread classifies with the shipped model and hands
// its class maps to the obstacle fusion and to a reader standing in for the
// DDS publisher. Run under the scheduler after arm(): the maps flow, no
// thread touches the heap, and (in the tsan preset) no data race is reported.
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "test_data.hpp"
#include "trailnav/perception/kitti.hpp"
#include "trailnav/perception/obstacle_task.hpp"
#include "trailnav/perception/terrain_task.hpp"
#include "trailnav/runtime/alloc_guard.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "../support/no_allocations.hpp"

namespace trailnav::perception {
namespace {

// Stands in for the lidar driver: every run publishes the next revolution
// (two real scans in turn, 0.1 s apart, the robot driving 0.2 m per
// revolution) and the poses for both threads. With `parts` > 1 it fills each
// revolution in that many runs, storing its progress word and waking the
// obstacle thread after each, as the driver does for a streaming reader.
class Feeder final : public Task {
 public:
  Feeder(const std::array<velodyne::RangeImage, 2>& scans, Broadcast<velodyne::RangeImage>& out, PoseQueue& a,
         PoseQueue& b, TaskEvent& event, int parts = 1)
      : scans_(scans), out_(out), a_(a), b_(b), event_(event), parts_(parts) {}
  void run(const TaskTick& tick) override {
    if (parts_ > 1) {
      run_part(tick);
      return;
    }
    ++n_;
    const std::int64_t t = n_ * 100'000'000LL;
    const Pose p{t, 0.2 * static_cast<double>(n_), 0.0, 0.0, 0.0, 0.0, 0.0};
    a_.try_push(p);
    b_.try_push(p);
    velodyne::RangeImage& slot = out_.write_slot();
    slot = scans_[static_cast<std::size_t>(n_ % 2)];  // same shape: no allocation
    slot.sequence = static_cast<std::uint64_t>(n_);
    slot.start_ns = t - 100'000'000LL;
    slot.end_ns = t;
    out_.publish();
    event_.signal(tick.started);
  }

  void run_part(const TaskTick& tick) {
    if (part_ == 0) ++n_;
    const std::int64_t t = n_ * 100'000'000LL;
    const velodyne::RangeImage& scan = scans_[static_cast<std::size_t>(n_ % 2)];
    velodyne::RangeImage& slot = out_.write_slot();
    const int columns = scan.columns();
    if (part_ == 0) {
      slot.begin(columns);
      slot.start_ns = t - 100'000'000LL;
      slot.cut_azimuth = scan.cut_azimuth;
      slot.azimuth_spread = scan.azimuth_spread;
      slot.clock_offset_ns = 0;
    }
    const int first = part_ * columns / parts_;
    const int end = (part_ + 1) * columns / parts_;
    for (int ring = 0; ring < scan.rings(); ++ring) {
      for (int c = first; c < end; ++c) slot.at(0, ring, c) = scan.at(0, ring, c);
    }
    slot.mark_received(first, end);
    for (int c = first; c < end; ++c) slot.set_column_time(c, c + 1, scan.column_time_ns(c) + slot.start_ns);
    // The poses reach the part's end.
    const Pose p{slot.start_ns + 100'000'000LL * end / columns, 0.2 * (static_cast<double>(n_) - 1.0 + 1.0 * end / columns),
                 0.0, 0.0, 0.0, 0.0, 0.0};
    a_.try_push(p);
    b_.try_push(p);
    if (++part_ < parts_) {
      out_.progress(velodyne::revolution_progress(static_cast<std::uint32_t>(n_), end));
    } else {
      part_ = 0;
      slot.sequence = static_cast<std::uint64_t>(n_);
      slot.end_ns = t;
      slot.finish();
      out_.publish();
    }
    event_.signal(tick.started);
  }

 private:
  const std::array<velodyne::RangeImage, 2>& scans_;
  Broadcast<velodyne::RangeImage>& out_;
  PoseQueue& a_;
  PoseQueue& b_;
  TaskEvent& event_;
  int parts_;
  int part_ = 0;
  std::int64_t n_ = 0;
};

// `shared`: the terrain thread registers the points the obstacle thread
// aligned and handed over (as in trailnavd), else it reads the revolutions
// and the poses itself. `streaming`: the obstacle thread works on each
// revolution while the feeder fills it in eight parts.
void run_together(bool shared, bool streaming = false) {
  ASSERT_TRUE(alloc_guard::hook_installed());
  alloc_guard::set_fatal(false);
  alloc_guard::reset_counters();

  std::array<velodyne::RangeImage, 2> scans{velodyne::RangeImage(kitti_shape()), velodyne::RangeImage(kitti_shape())};
  std::vector<float> buffer;
  ASSERT_TRUE(load_kitti_scan(test::shared_data("kitti/000000.bin"), buffer, scans[0]));
  ASSERT_TRUE(load_kitti_scan(test::shared_data("kitti/000001.bin"), buffer, scans[1]));
  auto model = RandomForest::load("board/models/terrain-sim.tnrf");
  ASSERT_TRUE(model.forest) << model.error;

  ObstacleConfig oc;
  oc.mount.translation = {0.0, 0.0, 1.73};
  auto pipeline = ObstaclePipeline::create(oc, kitti_shape());
  ASSERT_TRUE(pipeline.pipeline) << pipeline.error;
  TerrainConfig tc;
  auto mapper = TerrainMapper::create(tc, oc.mount, kitti_shape(), &*model.forest);
  ASSERT_TRUE(mapper.mapper) << mapper.error;

  Broadcast<velodyne::RangeImage> revolutions(2, kitti_shape());
  Broadcast<TerrainClassMap> classes(2, tc.map);
  Mailbox<ObstacleSnapshot> snapshots(oc.map.size, oc.map.size);
  PoseQueue obstacle_poses, terrain_poses;
  TaskEvent revolution;
  const int parts = streaming ? 8 : 1;
  Feeder feeder(scans, revolutions, obstacle_poses, terrain_poses, revolution, parts);
  ObstacleTask obstacles(*pipeline.pipeline, revolutions.reader(0), &obstacle_poses, &classes.reader(0), snapshots);
  obstacles.set_streaming(streaming);
  Mailbox<AlignedRevolution> aligned(CloudShape{kitti_shape().rings, kitti_shape().max_columns});
  std::unique_ptr<TerrainTask> own, taking;
  if (shared) {
    taking = std::make_unique<TerrainTask>(*mapper.mapper, aligned, classes);
    obstacles.set_aligned(&aligned);
  } else {
    own = std::make_unique<TerrainTask>(*mapper.mapper, revolutions.reader(1), &terrain_poses, classes);
  }
  TerrainTask& terrain = shared ? *taking : *own;

  MonotonicClock clock;
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  ASSERT_TRUE(scheduler.add({"lidar", TaskKind::periodic, 10.0 * parts, (streaming ? 10 : 50) * kNanosPerMilli, 0, -1}, feeder));
  ASSERT_TRUE(scheduler.add({"obstacles", TaskKind::event, 0.0, 200 * kNanosPerMilli, 0, -1}, obstacles, &revolution));
  ASSERT_TRUE(scheduler.add({"terrain", TaskKind::periodic, 10.0, 100 * kNanosPerMilli, 0, -1}, terrain));
  ASSERT_TRUE(scheduler.start());
  ASSERT_TRUE(alloc_guard::arm());

  // The publisher's side: reads snapshots of both maps (not real-time).
  std::uint64_t class_maps = 0, obstacle_maps = 0, known_cells = 0;
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(90);
  // Until everything asserted below has happened (a slow sanitizer build on a loaded machine takes longer).
  while ((obstacles.status().terrain_maps < 3 || terrain.status().published < 5 || obstacles.status().revolutions <= 10 ||
          terrain.status().mapper.features <= 1000) &&
         std::chrono::steady_clock::now() < give_up) {
    if (const TerrainClassMap* m = classes.reader(1).try_read()) {
      ++class_maps;
      known_cells = 0;
      for (std::int32_t y = 0; y < m->grid().size_y(); y += 4) {
        for (std::int32_t x = 0; x < m->grid().size_x(); x += 4) {
          known_cells += m->grid().at({m->grid().origin().x + x, m->grid().origin().y + y}).known ? 1u : 0u;
        }
      }
    }
    if (snapshots.try_read() != nullptr) ++obstacle_maps;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  scheduler.stop();
  alloc_guard::disarm();

  const ObstacleTaskCounters oc_status = obstacles.status();
  const TerrainTaskCounters tc_status = terrain.status();
  EXPECT_GE(tc_status.published, 5u);
  EXPECT_GE(oc_status.terrain_maps, 3u);  // the fusion took class maps from the terrain thread
  EXPECT_GT(oc_status.revolutions, 10u);
  EXPECT_GT(tc_status.mapper.features, 1000u);
  EXPECT_GT(class_maps, 0u);
  EXPECT_GT(known_cells, 50u);
  EXPECT_GT(obstacle_maps, 0u);
  if (shared) {
    // It aligned nothing itself, and took only revolutions the obstacle thread mapped.
    EXPECT_EQ(tc_status.mapper.align.points, 0u);
    EXPECT_GT(tc_status.mapper.points, 0u);
    EXPECT_LE(tc_status.revolutions, oc_status.revolutions);
  } else {
    EXPECT_GT(tc_status.mapper.align.points, 0u);
  }
  if (streaming) {
    // Revolutions taken while they arrived (how many depends on how fast
    // this machine is: one the thread falls behind on it maps whole).
    EXPECT_GT(oc_status.streamed, 0u);
    EXPECT_GT(oc_status.early_blocks, 0u);
    EXPECT_EQ(oc_status.abandoned, 0u);
  } else {
    EXPECT_EQ(oc_status.streamed, 0u);
  }
  test::expect_no_realtime_allocations();
}

TEST(TerrainAndObstacleThreads, RunTogetherOnTheSchedulerWithoutHeapOrRaces) { run_together(false); }

TEST(TerrainAndObstacleThreads, TheTerrainThreadTakesTheObstacleThreadsAlignedPointsWithoutHeapOrRaces) {
  run_together(true);
}

TEST(TerrainAndObstacleThreads, TheObstacleThreadTakesEachRevolutionWhileItArrivesWithoutHeapOrRaces) {
  run_together(true, true);
}

}  // namespace
}  // namespace trailnav::perception
