// trailnavd's mapping thread closing loops (navigation/slam/mapping_task.hpp,
// issue 40) on a simulated lap round a block (`block-loop`, simulated truth):
// the recording's wheels and IMU through the pose estimator as the pose
// thread's odometry, its Velodyne revolutions through a revolution reader of
// the task's own, the task run as the scheduler would run it (without GPS:
// the map is the odometry frame until a closure). The keyframes end nearer
// the truth than the odometry does, and no run touches the heap.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>

#include "pose_eval.hpp"
#include "revolution_source.hpp"
#include "sim_truth.hpp"
#include "simulator.hpp"
#include "trailnav/navigation/slam/mapping_task.hpp"
#include "trailnav/runtime/alloc_guard.hpp"
#include "trailnav/runtime/heap_redirect.hpp"

namespace trailnav {
namespace {

namespace fs = std::filesystem;

Eigen::Isometry2d iso2(double x, double y, double yaw) {
  Eigen::Isometry2d t = Eigen::Isometry2d::Identity();
  t.linear() = Eigen::Rotation2Dd(yaw).toRotationMatrix();
  t.translation() = Eigen::Vector2d(x, y);
  return t;
}

struct LoopRun {
  slam::MappingTaskStatus status;
  std::size_t keyframes = 0;
  double end_error_m = 0.0, rms_error_m = 0.0;  // the keyframes against the truth (the first keyframe on it)
  std::uint64_t heap = 0;
  bool watched = false;
};

// The recording through the mapping task; `loops`: with loop closures.
LoopRun run_mapping(const std::string& recording, bool loops) {
  LoopRun out;
  // The pose thread's odometry over the whole recording.
  std::vector<perception::Pose> poses;
  eval::PoseEvalOptions po;
  po.on_odometry = [&](const pose::LocalPose& p) {
    poses.push_back({p.time_ns, p.x, p.y, p.z, p.roll, p.pitch, p.yaw, p.translation_valid});
  };
  const eval::PoseEvalResult pr = eval::evaluate_pose(recording, po);
  EXPECT_EQ(pr.error, "");
  auto opened = eval::RevolutionSource::open({recording}, "");
  EXPECT_TRUE(opened.source) << opened.error;
  if (!opened.source || poses.empty()) return out;
  eval::RevolutionSource& source = *opened.source;
  perception::PoseTrack truth(source.truth()->trajectory.size() + 1);
  eval::fill_pose_track(*source.truth(), truth);

  slam::MappingOptions mo;
  mo.use_gps = false;
  mo.keyframes.max_keyframes = 500;
  mo.optimize_period = 2.0;
  if (loops) {
    // trailnavd's defaults (mapping.loops: {}).
    perception::registration::LoopClosureConfig lc = perception::registration::spinning_lidar_loop_config();
    lc.max_input_points = static_cast<std::size_t>(source.shape().rings) * static_cast<std::size_t>(source.shape().max_columns);
    mo.loops = lc;
  }
  perception::PoseQueue queue;
  Mailbox<slam::MappingSnapshot> snapshots(mo.keyframes.max_keyframes);
  Broadcast<velodyne::RangeImage> revolutions(1, source.shape());
  slam::MappingTask task(mo, queue, nullptr, snapshots);
  const auto m = source.mount_translation();
  Eigen::Isometry3f mount = Eigen::Isometry3f::Identity();
  mount.translation() = Eigen::Vector3f(static_cast<float>(m[0]), static_cast<float>(m[1]), static_cast<float>(m[2]));
  task.set_revolutions(&revolutions.reader(0), mount, 2.0f, 60.0f);

  // The recording decoded revolution by revolution (decoding allocates: the
  // guard is armed around the task's runs only, on this thread marked as
  // the mapping thread is).
  out.watched = heap_redirect::supported() && alloc_guard::hook_installed();
  alloc_guard::reset_counters();
  alloc_guard::mark_realtime_thread("mapping");
  auto run_task = [&](const TaskTick& tick) {
    alloc_guard::arm();
    task.run(tick);
    alloc_guard::disarm();
  };
  std::size_t next = 0;
  std::uint64_t cycle = 0;
  const std::string e = source.run([&](const velodyne::RangeImage& image) {
    const std::int64_t end = image.reference_end_ns();
    while (next < poses.size() && poses[next].t_ns <= end) queue.try_push(poses[next++]);
    velodyne::RangeImage& slot = revolutions.write_slot();
    slot = image;
    revolutions.publish();
    // Every fifth revolution a run: the task's 2 Hz against the lidar's 10 Hz.
    if (++cycle % 5 == 0) run_task({cycle, end, end});
    return true;
  });
  EXPECT_EQ(e, "");
  while (next < poses.size()) {
    while (next < poses.size() && queue.try_push(poses[next])) ++next;
    run_task({++cycle, poses.back().t_ns, poses.back().t_ns + 10'000'000'000LL});
  }
  run_task({++cycle, poses.back().t_ns, poses.back().t_ns + 20'000'000'000LL});
  alloc_guard::unmark_current_thread();
  out.heap = alloc_guard::total_allocations();
  out.status = task.status();
  const slam::MappingSnapshot* s = snapshots.try_read();
  EXPECT_NE(s, nullptr);
  if (s == nullptr || s->path_count < 2) return out;
  out.keyframes = s->path_count;
  // The map frame is the odometry frame: laid onto the world by the first keyframe's truth.
  perception::Pose t0;
  truth.at(s->path[0].time_ns, t0);
  const Eigen::Isometry2d align =
      iso2(t0.x, t0.y, t0.yaw) * iso2(s->path[0].x, s->path[0].y, s->path[0].yaw).inverse();
  double sum = 0.0;
  for (std::size_t k = 0; k < s->path_count; ++k) {
    perception::Pose t;
    truth.at(s->path[k].time_ns, t);
    const Eigen::Vector2d d = align * Eigen::Vector2d(s->path[k].x, s->path[k].y) - Eigen::Vector2d(t.x, t.y);
    sum += d.squaredNorm();
    if (k + 1 == s->path_count) out.end_error_m = d.norm();
  }
  out.rms_error_m = std::sqrt(sum / static_cast<double>(s->path_count));
  return out;
}

TEST(MappingLoops, ALapRoundTheBlockClosesAndTheMapEndsNearerTheTruth) {
  const fs::path dir = fs::temp_directory_path() / ("trailnav-loops-" + std::to_string(::getpid()));
  sim::SimOptions so;
  so.scenario = "block-loop";
  so.seed = 3;
  so.out = dir.string();
  const sim::SimReport sr = sim::run_simulation(so);
  ASSERT_EQ(sr.error, "");
  const LoopRun without = run_mapping(dir.string(), false);
  const LoopRun with = run_mapping(dir.string(), true);
  const perception::registration::LoopCounters& l = with.status.loops;
  std::printf("%zu keyframes; odometry alone: end %.2f m, RMS %.2f m off the truth; with loops (%llu candidates, %llu "
              "accepted, %llu keyframes without a cloud): end %.2f m, RMS %.2f m; the longest search and verification "
              "%.1f ms, arena %zu of %zu kB\n",
              with.keyframes, without.end_error_m, without.rms_error_m, static_cast<unsigned long long>(l.candidates),
              static_cast<unsigned long long>(l.accepted), static_cast<unsigned long long>(with.status.loop_no_cloud),
              with.end_error_m, with.rms_error_m, with.status.loop_ms_max, with.status.loop_arena_high_water / 1024,
              with.status.loop_arena_capacity / 1024);
  EXPECT_EQ(without.status.optimisations, 0u);  // without GPS or a closure nothing to solve
  EXPECT_GE(l.accepted, 1u);
  EXPECT_GE(with.status.optimisations, 1u);
  EXPECT_EQ(with.status.failures, 0u);
  EXPECT_EQ(with.status.loop_arena_failures, 0u);
  EXPECT_LE(with.status.loop_no_cloud, 2u);
  EXPECT_GT(without.end_error_m, 0.3);  // the wheels' drift round the lap
  EXPECT_LT(with.end_error_m, 0.5 * without.end_error_m);
  EXPECT_LT(with.rms_error_m, without.rms_error_m);
  if (with.watched) {
    EXPECT_EQ(with.heap, 0u);
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace trailnav
