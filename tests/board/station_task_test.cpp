// trailnavd's station task (perception/registration/station_task.hpp) on the
// thesis' simulated floor (board/sim/station_world.hpp): scans in through its
// mailbox, a fix per body out. Simulated truth throughout.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <thread>

#include "random.hpp"
#include "sim_station.hpp"
#include "station_world.hpp"
#include "trailnav/perception/registration/station_task.hpp"
#include "trailnav/runtime/alloc_guard.hpp"
#include "trailnav/runtime/heap_redirect.hpp"

namespace trailnav {
namespace {

namespace reg = perception::registration;
namespace st = sim::station;

// The box of the thesis' floor taught from 16 scans on the arc before it
// (noisy odometry refined by the teach-in), marked by its polygon.
struct TaughtBox {
  st::World world = st::thesis_world();
  reg::StationConfig config;
  reg::Station station;
  std::vector<st::Pose2> taught;
  TaughtBox() {
    for (const st::ObjectShape& o : world.objects) taught.push_back(o.pose);
    reg::BuiltStation built = test::teach_simulated_box(world, world.objects[0].name, 11, 12, config);
    EXPECT_EQ(built.error, "");
    station = std::move(built.station);
  }
};

// A visit to the box after it moved by `move`: `scans` scans 0.1 s apart,
// the last `still` of them standing at the visit's end.
struct Visit {
  st::Drive drive;
  std::vector<std::vector<Eigen::Vector3f>> scans;
};
Visit visit_of(const TaughtBox& t, const st::Pose2& move, int driving, int still, std::uint64_t key) {
  std::vector<st::Pose2> now = t.taught;
  now[0] = st::compose(move, t.world.objects[0].pose);
  std::vector<st::Segment> seen = t.world.walls;
  const auto os = st::object_segments(t.world, now);
  seen.insert(seen.end(), os.begin(), os.end());
  Visit v;
  v.drive = st::visit_drive(t.world.objects[0], driving, key);
  for (int i = 0; i < still; ++i) {
    v.drive.truth.push_back(v.drive.truth.back());
    v.drive.odometry.push_back({});
  }
  for (std::size_t i = 0; i < v.drive.truth.size(); ++i) {
    v.scans.push_back(st::cast(seen, v.drive.truth[i], {}, sim::hash(key, 9, i)));
  }
  return v;
}

// Where the box's centre went by the estimated motion against where it is.
double centre_error_mm(const reg::StationBodyFix& b, const st::Pose2& move, const st::Pose2& centre) {
  const Eigen::Vector2d c(centre.x, centre.y);
  const Eigen::Rotation2Dd re(b.turned), rt(move.theta);
  const Eigen::Vector2d est = re * c + Eigen::Vector2d(b.moved_x, b.moved_y);
  const Eigen::Vector2d truth = rt * c + Eigen::Vector2d(move.x, move.y);
  return 1000.0 * (est - truth).norm();
}

struct Rig {
  Mailbox<reg::PlanarScan> in{std::size_t{2048}};
  Mailbox<reg::StationSnapshot> out;
  perception::PoseQueue poses;
  reg::StationTask task;
  Rig(const TaughtBox& t, const reg::StationTaskOptions& o, bool with_poses)
      : out(t.station.bodies.size()), task(t.station, t.config, o, &in, with_poses ? &poses : nullptr, out) {}
  // One scan at `stamp_ns`, then one run of the task; the snapshot it published, if any.
  const reg::StationSnapshot* feed(const std::vector<Eigen::Vector3f>& points, std::int64_t stamp_ns, std::uint64_t seq) {
    reg::PlanarScan& s = in.write_slot();
    s.points.clear();
    for (const auto& p : points) s.points.push_back(p);
    s.stamp_ns = stamp_ns;
    s.sequence = seq;
    s.dropped = 0;
    in.publish();
    task.run({});
    return out.try_read();
  }
};

// The thesis' combined set (10 cm and 10°): the task's fixes find the box's
// motion to within millimetres, with the pose thread's odometry or without it
// (the last step again), and a robot that then stands at the box for 50 more
// scans keeps finding it (the local model re-anchored by each fix), every
// run on a watched thread without one heap operation.
TEST(StationTask, FindsTheMovedBoxWithOrWithoutOdometryAndWithoutTheHeap) {
  const TaughtBox t;
  const st::ObjectShape& box = t.world.objects[0];
  const st::Pose2 move = st::move_of(box, st::kThesisSets[5], 77);
  const Visit v = visit_of(t, move, 10, 50, 78);
  for (const bool with_poses : {true, false}) {
    SCOPED_TRACE(with_poses ? "with odometry" : "without odometry");
    reg::StationTaskOptions o;
    // The regular localisation's pose at the visit's start, 3 cm and 1° off.
    o.start = st::to_isometry({v.drive.truth.front().x + 0.03, v.drive.truth.front().y - 0.02,
                               v.drive.truth.front().theta + 0.017});
    Rig rig(t, o, with_poses);
    // Room for every fix before the thread is watched: copying one into a
    // slot of the same size touches no heap.
    std::vector<reg::StationSnapshot> fixes(v.scans.size(), reg::StationSnapshot(t.station.bodies.size()));
    std::size_t n_fixes = 0;
    const bool watched = heap_redirect::supported() && alloc_guard::hook_installed();
    alloc_guard::reset_counters();
    std::thread worker([&] {
      alloc_guard::mark_realtime_thread("station");
      alloc_guard::arm();
      st::Pose2 odo = v.drive.truth.front();
      for (std::size_t i = 0; i < v.scans.size(); ++i) {
        const std::int64_t stamp = 1'000'000'000 + static_cast<std::int64_t>(i) * 100'000'000;
        if (with_poses) {
          // The odometry's pose (its own frame: the noisy steps from the start).
          if (i > 0) odo = st::compose(odo, v.drive.odometry[i]);
          rig.poses.try_push(perception::Pose{stamp, odo.x, odo.y, 0.0, 0.0, 0.0, odo.theta, true});
        }
        if (const reg::StationSnapshot* s = rig.feed(v.scans[i], stamp, i + 1)) fixes[n_fixes++] = *s;
      }
      alloc_guard::disarm();
      alloc_guard::unmark_current_thread();
    });
    worker.join();
    fixes.resize(n_fixes, reg::StationSnapshot(0));
    if (watched) {
      EXPECT_EQ(alloc_guard::total_allocations(), 0u);
    }
    const reg::StationCounters c = rig.task.counters();
    EXPECT_EQ(c.scans, v.scans.size());
    EXPECT_EQ(c.visits, 1u);
    EXPECT_EQ(c.lost, 0u);
    EXPECT_EQ(c.arena_failures, 0u);
    EXPECT_EQ(c.without_odometry, with_poses ? 0u : v.scans.size() - 1);
    if (heap_redirect::supported()) {  // (a sanitizer's malloc serves the trees itself)
      EXPECT_GT(c.arena_high_water, 0u);
      EXPECT_LT(c.arena_high_water, c.arena_capacity);
    }
    // A fix from the 10th scan on, one a scan.
    ASSERT_EQ(fixes.size(), v.scans.size() - 9);
    double worst_mm = 0.0, worst_deg = 0.0, worst_robot_mm = 0.0, worst_sigma_mm = 0.0;
    for (const reg::StationSnapshot& s : fixes) {
      ASSERT_EQ(s.bodies.size(), 2u);
      EXPECT_TRUE(s.bodies[0].observed);
      EXPECT_TRUE(s.bodies[1].observed);
      worst_mm = std::max(worst_mm, centre_error_mm(s.bodies[1], move, box.pose));
      worst_deg = std::max(worst_deg, std::abs(std::remainder(s.bodies[1].turned - move.theta, 2 * std::numbers::pi)) *
                                          180.0 / std::numbers::pi);
      // The robot in the station frame (the surroundings' body) where it stands.
      const st::Pose2& truth = v.drive.truth[s.scan_sequence - 1];
      worst_robot_mm = std::max(worst_robot_mm, 1000.0 * std::hypot(s.bodies[0].x - truth.x, s.bodies[0].y - truth.y));
      // A covariance that says something: the robot's position known to
      // millimetres in each body's frame, its heading to a fraction of a degree.
      for (const reg::StationBodyFix& b : s.bodies) {
        EXPECT_GT(b.covariance[0], 0.0);
        EXPECT_LT(std::sqrt(b.covariance[0]), 0.02);
        EXPECT_LT(std::sqrt(b.covariance[4]), 0.02);
        EXPECT_LT(std::sqrt(b.covariance[8]) * 180.0 / std::numbers::pi, 0.5);
        worst_sigma_mm = std::max(worst_sigma_mm, 1000.0 * std::sqrt(b.covariance[0] + b.covariance[4]));
      }
    }
    EXPECT_LT(worst_mm, 15.0);
    EXPECT_LT(worst_deg, 1.5);
    EXPECT_LT(worst_robot_mm, 20.0);
    std::printf("worst: box centre %.1f mm, %.2f deg; robot %.1f mm; sigma %.1f mm\n", worst_mm, worst_deg, worst_robot_mm,
                worst_sigma_mm);
    // The fixes saw it move: its centre 10 cm away, turned by 10°.
    const reg::StationBodyFix& last = fixes.back().bodies[1];
    const Eigen::Vector2d centre(box.pose.x, box.pose.y);
    const Eigen::Vector2d went =
        Eigen::Rotation2Dd(last.turned) * centre + Eigen::Vector2d(last.moved_x, last.moved_y) - centre;
    EXPECT_NEAR(went.norm(), 0.10, 0.015);
    EXPECT_NEAR(std::abs(last.turned) * 180.0 / std::numbers::pi, 10.0, 1.5);
  }
}

// A gap in the scans ends a visit: the next scan begins another from the
// configured start, and the task counts it.
TEST(StationTask, SilenceEndsAVisitAndTheNextScanBeginsAnother) {
  const TaughtBox t;
  const st::Pose2 move = st::move_of(t.world.objects[0], st::kThesisSets[1], 5);
  const Visit v = visit_of(t, move, 10, 2, 6);
  reg::StationTaskOptions o;
  o.start = st::to_isometry(v.drive.truth.front());
  o.silence_s = 1.0;
  Rig rig(t, o, false);
  int fixes = 0;
  for (int pass = 0; pass < 2; ++pass) {
    for (std::size_t i = 0; i < v.scans.size(); ++i) {
      const std::int64_t stamp = pass * 10'000'000'000LL + static_cast<std::int64_t>(i) * 100'000'000;
      if (const reg::StationSnapshot* s = rig.feed(v.scans[i], stamp, i + 1)) {
        ++fixes;
        EXPECT_EQ(s->visit, static_cast<std::uint64_t>(pass + 1));
        EXPECT_LT(centre_error_mm(s->bodies[1], move, t.world.objects[0].pose), 15.0);
      }
    }
  }
  EXPECT_EQ(fixes, 2 * 3);
  EXPECT_EQ(rig.task.counters().visits, 2u);
}

// The Velodyne input: a band of rings flattened into the plane, in the
// robot frame by the mount, the range window kept, the rest counted.
TEST(StationTask, ARingBandIsFlattenedIntoTheRobotFrame) {
  velodyne::RangeImage image({16, 8, 1});
  image.reset(8);
  for (int r = 0; r < 16; ++r) {
    for (int col = 0; col < 8; ++col) {
      velodyne::RangeCell& c = image.at(0, r, col);
      c.x = 1.0f + static_cast<float>(col);
      c.y = 0.5f;
      c.z = 0.1f * static_cast<float>(r - 8);
      c.distance = std::sqrt(c.x * c.x + c.y * c.y + c.z * c.z);
    }
  }
  image.end_ns = 5'000;
  image.clock_offset_ns = 1'000;
  reg::RingBand band;
  band.first_ring = 7;
  band.last_ring = 8;
  band.max_range = 6.0f;
  band.mount.translation() = Eigen::Vector3f(0.2f, 0.0f, 0.5f);
  reg::PlanarScan out(6);
  reg::band_scan(image, band, out);
  // Rings 7 and 8, columns with x <= 5.9 (distance within 6 m): 5 each; 6 kept, 4 counted.
  EXPECT_EQ(out.points.size(), 6u);
  EXPECT_EQ(out.dropped, 4u);
  EXPECT_EQ(out.stamp_ns, 6'000);
  for (const auto& p : out.points) {
    EXPECT_EQ(p.z(), 0.0f);
    EXPECT_FLOAT_EQ(p.y(), 0.5f);
    EXPECT_GE(p.x(), 1.2f);
  }
  EXPECT_FLOAT_EQ(out.points.front().x(), 1.2f);
}

}  // namespace
}  // namespace trailnav
