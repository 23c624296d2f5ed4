// The obstacle map (Eq. 7.10 with clamping, unknown vs free, the PW hold,
// PW/PS/PC with a terrain-class map), pose interpolation, gravity alignment
// with motion compensation, configuration errors, and zero heap operations
// per revolution after arm.
#include <gtest/gtest.h>

#include <cmath>
#include <chrono>
#include <numbers>
#include <thread>
#include <vector>

#include "test_data.hpp"
#include "trailnav/perception/kitti.hpp"
#include "trailnav/perception/obstacle_pipeline.hpp"
#include "trailnav/perception/obstacle_task.hpp"
#include "trailnav/runtime/alloc_guard.hpp"

namespace trailnav::perception {
namespace {

// One ring of flat ground at 2 m and a 0.5 m wall segment across rings.
RevolutionCloud ground_and_wall() {
  RevolutionCloud c(CloudShape{4, 720});
  c.reset(720);
  c.full_turn = true;
  for (int i = 0; i < 4; ++i) {
    const double r = 4.05 + 0.2 * i;
    for (int j = 0; j < 720; ++j) {
      const double a = 2.0 * std::numbers::pi * j / 720;
      const std::size_t k = c.index(i, j);
      const bool wall = j < 20;  // azimuth 0..10 degrees: a wall at r = 4.05 m rising with the rings
      c.x[k] = static_cast<float>((wall ? 4.05 : r) * std::cos(a));
      c.y[k] = static_cast<float>((wall ? 4.05 : r) * std::sin(a));
      c.z[k] = wall ? 0.15f * static_cast<float>(i) : 0.0f;
      c.range[k] = static_cast<float>(r);
      c.state[k] = PointState::valid;
    }
  }
  return c;
}

// One measured point at (x, y) with the given features, in a small cloud.
RevolutionCloud one_point(float x, float y, float step, float sin_incline) {
  RevolutionCloud c(CloudShape{2, 16});
  c.reset(16);
  const std::size_t k = c.index(0, 0);
  c.x[k] = x;
  c.y[k] = y;
  c.step_height[k] = step;
  c.sin_incline[k] = sin_incline;
  c.state[k] = PointState::measured;
  return c;
}

TEST(ObstacleMap, UnknownFreeAndOccupiedAreDistinct) {
  RevolutionCloud c = ground_and_wall();
  FeatureCounters fc;
  FeatureParams fp;
  fp.smoothing_half_window = 0;
  compute_features(c, fp, fc);
  MapParams mp;
  ObstacleModels models(default_class_params(), mp);
  TerrainSource street;
  street.fixed = true;
  street.fixed_class = TerrainClass::street;
  for (FusionModel m : {FusionModel::pw, FusionModel::ps, FusionModel::pc}) {
    ObstacleMap map(mp, m);
    for (int rev = 0; rev < 5; ++rev) {
      c.start_ns = rev * 100'000'000LL;
      map.integrate(c, models, street);
    }
    const auto& g = map.grid();
    // Never observed: unknown, NaN probability.
    EXPECT_EQ(map.state(*g.find(10.0, 10.0)), CellState::unknown) << fusion_model_name(m);
    EXPECT_TRUE(std::isnan(map.probability(*g.find(10.0, 10.0))));
    // Ground of ring 2 (4.45 m) at azimuth 150 degrees: free.
    const std::size_t ground = c.index(2, 300);
    const ObstacleCell& free_cell = *g.find(static_cast<double>(c.x[ground]), static_cast<double>(c.y[ground]));
    EXPECT_EQ(map.state(free_cell), CellState::free) << fusion_model_name(m);
    // The wall, ring 2 at azimuth 5 degrees: occupied.
    const std::size_t wall = c.index(2, 10);
    const ObstacleCell& wall_cell = *g.find(static_cast<double>(c.x[wall]), static_cast<double>(c.y[wall]));
    EXPECT_EQ(map.state(wall_cell), CellState::occupied) << fusion_model_name(m);
    // Clamped log-odds.
    EXPECT_LE(wall_cell.logit, mp.logit_max);
    EXPECT_GE(free_cell.logit, mp.logit_min);
    // The exported percentages: -1 unknown, else within 1 of 100 P(o).
    std::vector<std::int8_t> occupancy(g.cell_count());
    map.export_occupancy(occupancy);
    std::size_t unknown = 0;
    for (std::int32_t y = 0; y < g.size_y(); ++y) {
      for (std::int32_t x = 0; x < g.size_x(); ++x) {
        const ObstacleCell& cell = g.at({g.origin().x + x, g.origin().y + y});
        const std::int8_t v = occupancy[static_cast<std::size_t>(y * g.size_x() + x)];
        if (!cell.known()) {
          ASSERT_EQ(v, -1);
          ++unknown;
        } else {
          ASSERT_NEAR(v, 100.0f * map.probability(cell), 1.0f);
        }
      }
    }
    EXPECT_GT(unknown, g.cell_count() / 2);
  }
}

TEST(ObstacleMap, LogOddsFollowEquation710) {
  // One point per revolution in one cell, p = P(o | g) from the smooth model.
  RevolutionCloud c = one_point(1.05f, 1.05f, 0.06f, 0.5f);
  MapParams mp;
  mp.logit_max = 20.0f;
  ObstacleModels models(default_class_params(), mp);
  TerrainSource street;
  street.fixed = true;
  ObstacleMap map(mp, FusionModel::ps);
  const float p = std::clamp(models.smooth(0, 0.06f, 0.5f), mp.measurement_min, mp.measurement_max);
  for (int n = 1; n <= 3; ++n) {
    map.integrate(c, models, street);
    EXPECT_NEAR(map.grid().find(1.05, 1.05)->logit, static_cast<float>(n) * std::log(p / (1.0f - p)), 2e-3f);
  }
}

// Revolution n (10 Hz) of a cloud made by one_point(2.05, 0.05, ...): its
// point at height z, a vertical step of `step` (0: flat). The PW cell's state after.
CellState dirac_revolution(ObstacleMap& map, RevolutionCloud& c, const ObstacleModels& models,
                           const TerrainSource& terrain, int n, float step, float z) {
  const std::size_t k = c.index(0, 0);
  c.start_ns = n * 100'000'000LL;  // the map measures the rate from the revolutions' starts
  c.time_ns = c.start_ns + 99'000'000LL;
  c.step_height[k] = step;
  c.sin_incline[k] = step > 0 ? 1.0f : 0.0f;
  c.z[k] = z;
  map.integrate(c, models, terrain);
  return map.state(*map.grid().find(2.05, 0.05));
}

TEST(ObstacleMap, DiracHoldKeepsObstaclesForTheConfiguredTime) {
  RevolutionCloud c = one_point(2.05f, 0.05f, 0.0f, 0.0f);
  MapParams mp;
  mp.dirac_hold_s = 0.5f;      // 5 revolutions at 10 Hz
  mp.dirac_top_hold_s = 1.5f;  // 15
  ObstacleModels models(default_class_params(), mp);
  TerrainSource street;
  street.fixed = true;
  ObstacleMap map(mp, FusionModel::pw);
  auto rev = [&](int n, float step, float z) { return dirac_revolution(map, c, models, street, n, step, z); };
  EXPECT_EQ(rev(0, 0.0f, 0.0f), CellState::free);
  // A box's face seen at 0.3 and 0.4 m, then only its flat top at 0.42 m.
  EXPECT_EQ(rev(1, 0.2f, 0.3f), CellState::occupied);
  EXPECT_EQ(rev(2, 0.2f, 0.4f), CellState::occupied);
  for (int n = 3; n <= 7; ++n) EXPECT_EQ(rev(n, 0.0f, 0.0f), CellState::occupied) << n;  // held
  // After the hold: the top (not 0.1 m below the highest face point) keeps
  // it, until the top hold is over.
  for (int n = 8; n <= 17; ++n) EXPECT_EQ(rev(n, 0.0f, 0.42f), CellState::occupied) << n;
  EXPECT_EQ(rev(18, 0.0f, 0.42f), CellState::free);
  // A new obstacle: the ground where it stood clears it right after the hold.
  EXPECT_EQ(rev(19, 0.2f, 0.5f), CellState::occupied);
  for (int n = 20; n <= 24; ++n) EXPECT_EQ(rev(n, 0.0f, 0.0f), CellState::occupied) << n;
  EXPECT_EQ(rev(25, 0.0f, 0.0f), CellState::free);
}

TEST(ObstacleMap, TopHoldFollowsTheCellsTerrainClass) {
  // A box's face, then only its flat top: a cell the terrain map calls
  // `other` (a solid object) stays occupied; one it calls grass is cleared
  // once the map's top hold is over; ground where the box stood clears both.
  RevolutionCloud c = one_point(2.05f, 0.05f, 0.0f, 0.0f);
  MapParams mp;
  mp.dirac_hold_s = 0.5f;      // 5 revolutions at 10 Hz
  mp.dirac_top_hold_s = 1.0f;  // 10
  auto classes = default_class_params();
  classes[static_cast<int>(TerrainClass::grass)].max_step_height = 0.1f;  // so the face counts on grass too
  ObstacleModels models(classes, mp);
  EXPECT_FLOAT_EQ(models.top_hold_s(static_cast<int>(TerrainClass::other)), kTopHoldForever);
  EXPECT_FLOAT_EQ(models.top_hold_s(static_cast<int>(TerrainClass::grass)), 1.0f);
  for (const TerrainClass cls : {TerrainClass::other, TerrainClass::grass}) {
    TerrainClassMap terrain;
    std::array<float, kTerrainClasses> dist{};
    dist[static_cast<std::size_t>(cls)] = 1.0f;
    terrain.grid().find(2.05, 0.05)->set(dist);
    TerrainSource adaptive;
    adaptive.map = &terrain;
    ObstacleMap map(mp, FusionModel::pw);
    auto rev = [&](int n, float step, float z) { return dirac_revolution(map, c, models, adaptive, n, step, z); };
    EXPECT_EQ(rev(0, 0.3f, 0.3f), CellState::occupied);
    for (int n = 1; n <= 10; ++n) EXPECT_EQ(rev(n, 0.0f, 0.32f), CellState::occupied) << n;
    const bool held = cls == TerrainClass::other;
    for (int n = 11; n <= 400; ++n) {
      ASSERT_EQ(rev(n, 0.0f, 0.32f), held ? CellState::occupied : CellState::free)
          << terrain_class_name(cls) << " " << n;
    }
    EXPECT_EQ(rev(401, 0.0f, 0.0f), CellState::free) << terrain_class_name(cls);
  }
}

TEST(ObstacleMap, TerrainClassesChangeTheVerdict) {
  // A 0.3 m vertical step: an obstacle on street, not on grass (PW, PS);
  // PC weighs the classes.
  const RevolutionCloud c = one_point(1.05f, 1.05f, 0.3f, 1.0f);
  MapParams mp;
  ObstacleModels models(default_class_params(), mp);
  TerrainClassMap terrain;
  TerrainCell* cell = terrain.grid().find(1.05, 1.05);
  ASSERT_NE(cell, nullptr);
  TerrainSource adaptive;
  adaptive.map = &terrain;
  // One revolution, so no map saturates at the clamp.
  auto verdict = [&](FusionModel m, std::array<float, kTerrainClasses> dist) {
    cell->set(dist);
    ObstacleMap map(mp, m);
    map.integrate(c, models, adaptive);
    return map.probability(*map.grid().find(1.05, 1.05));
  };
  EXPECT_GT(verdict(FusionModel::pw, {1, 0, 0, 0, 0}), 0.9f);
  EXPECT_LT(verdict(FusionModel::pw, {0, 0, 1, 0, 0}), 0.1f);
  const float street_ps = verdict(FusionModel::ps, {0.9f, 0, 0.1f, 0, 0});
  const float grass_ps = verdict(FusionModel::ps, {0.1f, 0, 0.9f, 0, 0});
  const float mixed_pc = verdict(FusionModel::pc, {0.5f, 0.5f, 0, 0, 0});
  EXPECT_GT(street_ps, grass_ps);
  // PC of an even street/dirt mix lies between the two pure classes' PS.
  const float street_only = verdict(FusionModel::ps, {1, 0, 0, 0, 0});
  const float dirt_only = verdict(FusionModel::ps, {0, 1, 0, 0, 0});
  EXPECT_LT(mixed_pc, street_only);
  EXPECT_GT(mixed_pc, dirt_only);
  // An unknown terrain cell uses the configured class for unknown terrain.
  cell->known = false;
  ObstacleMap map(mp, FusionModel::pw);
  adaptive.unknown_class = TerrainClass::grass;
  map.integrate(c, models, adaptive);
  EXPECT_EQ(map.state(*map.grid().find(1.05, 1.05)), CellState::free);
  EXPECT_EQ(map.counters().unknown_terrain, 1u);
}

TEST(PoseTrack, InterpolatesAndWrapsYaw) {
  PoseTrack t(4);
  EXPECT_TRUE(t.push({0, 0.0, 0.0, 0.0, 0.0, 0.0, 3.1}));
  EXPECT_TRUE(t.push({100, 1.0, 2.0, 0.0, 0.1, 0.0, -3.1}));
  EXPECT_FALSE(t.push({100, 0, 0, 0, 0, 0, 0}));
  EXPECT_EQ(t.rejected(), 1u);
  Pose p;
  EXPECT_EQ(t.at(50, p), PoseLookup::interpolated);
  EXPECT_NEAR(p.x, 0.5, 1e-12);
  EXPECT_NEAR(p.y, 1.0, 1e-12);
  EXPECT_NEAR(p.roll, 0.05, 1e-12);
  EXPECT_NEAR(std::abs(p.yaw), std::numbers::pi, 1e-9);  // across +-pi, not through 0
  EXPECT_EQ(t.at(-5, p), PoseLookup::before_first);
  EXPECT_EQ(t.at(500, p), PoseLookup::after_last);
  EXPECT_NEAR(p.x, 1.0, 1e-12);
  for (int i = 2; i < 10; ++i) t.push({i * 100, 1.0 * i, 0, 0, 0, 0, 0});
  EXPECT_EQ(t.size(), 4u);
  EXPECT_EQ(t.oldest().t_ns, 600);
}

// A revolution's span is mapped only when the odometry measured the motion
// all through it: one sample without wheel speeds inside the span (not only
// at its ends), or the samples around it, is enough to say no.
TEST(PoseTrack, TranslationIsKnownOnlyWhenEverySampleOfTheSpanHadIt) {
  PoseTrack t(16);
  EXPECT_TRUE(t.motion_known(0, 100));  // nothing better known
  for (int i = 0; i < 10; ++i) t.push({i * 10, 0.1 * i, 0, 0, 0, 0, 0, i != 5});  // 50: wheels stale
  EXPECT_TRUE(t.motion_known(0, 40));
  EXPECT_TRUE(t.motion_known(61, 90));
  EXPECT_FALSE(t.motion_known(42, 48));   // between 40 and 50: 50 is the sample after
  EXPECT_FALSE(t.motion_known(30, 70));   // 50 inside, both ends fine
  EXPECT_FALSE(t.motion_known(52, 58));   // 50 is the sample before
  EXPECT_TRUE(t.motion_known(60, 200));   // past the newest: the newest says
  EXPECT_TRUE(t.motion_known(-50, -10));  // before the oldest: the oldest says
}

// The obstacle and terrain threads wait for a pose thread that is behind
// the revolution, asleep and for a bounded time.
TEST(PoseTrack, WaitsForALatePoseThreadAndGivesUpAfterTheLimit) {
  PoseTrack t(16);
  PoseQueue q;
  PoseWait w;
  w.max_lag_ns = 30;
  w.max_wait_ns = 20'000'000;
  EXPECT_EQ(t.lag(1000), 0);  // empty: nothing to wait for
  q.try_push(Pose{1000, 0, 0, 0, 0, 0, 0});
  PoseWaitResult r = wait_for_pose(t, q, 1020, w, true);  // drained; 20 ns behind: within the lag
  EXPECT_TRUE(r.ready);
  EXPECT_EQ(r.poses, 1u);
  EXPECT_EQ(r.waited_ns, 0);
  EXPECT_EQ(t.lag(1100), 100);
  // Only checking: no wait.
  r = wait_for_pose(t, q, 1100, w, false);
  EXPECT_FALSE(r.ready);
  EXPECT_EQ(r.waited_ns, 0);
  // Nothing comes: back after the limit, not ready.
  r = wait_for_pose(t, q, 1100, w, true);
  EXPECT_FALSE(r.ready);
  EXPECT_GE(r.waited_ns, w.max_wait_ns);
  // The pose thread catches up while it waits (the limit is long here, so a
  // busy machine cannot make this fail).
  w.max_wait_ns = 20'000'000'000;
  std::thread late([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    q.try_push(Pose{1050, 0, 0, 0, 0, 0, 0});
    q.try_push(Pose{1090, 0, 0, 0, 0, 0, 0});
  });
  r = wait_for_pose(t, q, 1100, w, true);
  late.join();
  EXPECT_TRUE(r.ready);
  EXPECT_GT(r.waited_ns, 0);
  EXPECT_GE(r.poses, 1u);
  EXPECT_LE(t.lag(1100), 30);
}

// A revolution the pose thread has not reached is not mapped with the newest
// (stale) pose: the task waits, then leaves it out, counts it and says so;
// it maps again once the pose catches up.
TEST(ObstacleTask, LeavesOutARevolutionThePoseHasNotReached) {
  ObstacleConfig config;
  auto made = ObstaclePipeline::create(config, kitti_shape());
  ASSERT_TRUE(made.pipeline) << made.error;
  std::vector<float> buffer;
  velodyne::RangeImage image(kitti_shape());
  ASSERT_TRUE(load_kitti_scan(test::shared_data("kitti/000000.bin"), buffer, image));
  Broadcast<velodyne::RangeImage> revolutions(1, kitti_shape());
  Mailbox<ObstacleSnapshot> out(config.map.size, config.map.size);
  PoseQueue pose_queue;
  PoseWait wait;
  wait.max_lag_ns = 30'000'000;
  wait.max_wait_ns = 5'000'000;
  ObstacleTask task(*made.pipeline, revolutions.reader(0), &pose_queue, nullptr, out, 64, wait);
  auto send = [&](std::uint64_t n) {
    revolutions.write_slot() = image;
    revolutions.write_slot().start_ns = static_cast<std::int64_t>(n) * 100'000'000LL;
    revolutions.write_slot().end_ns = static_cast<std::int64_t>(n + 1) * 100'000'000LL;
    revolutions.write_slot().sequence = n;
    revolutions.publish();
    task.run(TaskTick{});
  };
  for (int i = 0; i <= 10; ++i) pose_queue.try_push(Pose{i * 10'000'000LL, 0.01 * i, 0, 0, 0, 0, 0});
  send(1);  // 100..200 ms: the poses end at 100 ms
  EXPECT_EQ(task.counters().revolutions, 0u);
  EXPECT_EQ(task.counters().pose_waits, 1u);
  EXPECT_EQ(task.counters().pose_late, 1u);
  EXPECT_TRUE(task.counters().pose_behind);
  EXPECT_GE(task.counters().pose_wait_max_ns, wait.max_wait_ns);
  EXPECT_EQ(out.try_read(), nullptr);
  send(2);  // still behind: checked, not waited for again
  EXPECT_EQ(task.counters().pose_waits, 1u);
  EXPECT_EQ(task.counters().pose_late, 2u);
  for (int i = 11; i <= 40; ++i) pose_queue.try_push(Pose{i * 10'000'000LL, 0.01 * i, 0, 0, 0, 0, 0});
  send(3);  // 300..400 ms, poses to 400 ms
  EXPECT_EQ(task.counters().revolutions, 1u);
  EXPECT_FALSE(task.counters().pose_behind);
  const ObstacleSnapshot* snap = out.try_read();
  ASSERT_NE(snap, nullptr);
  EXPECT_EQ(snap->revolution, 3u);
  EXPECT_NEAR(snap->robot_x, 0.4, 1e-9);  // the pose at the revolution's end
}

TEST(CloudAligner, LevelsThePitchAndCompensatesMotion) {
  velodyne::RangeImage image({2, 100, 1});
  image.reset(100);
  image.mark_received(0, 100);
  image.start_ns = 0;
  image.end_ns = 100'000'000;
  // The same world point (5, 0, 0) seen at the first and the last column
  // while the robot drives 1 m along x in the revolution: from the sensor
  // it is 5 m ahead, then 4 m ahead.
  auto put = [&](int column, float x) {
    velodyne::RangeCell& c = image.at(0, 0, column);
    c.x = x;
    c.distance = x;
    c.azimuth = static_cast<float>(image.column_azimuth(column));
  };
  put(0, 5.0f);
  put(99, 4.0f);
  image.finish();
  MountParams mount;
  FeatureParams fp;
  fp.min_range = 0.5f;
  CloudAligner aligner(mount, fp);
  PoseTrack poses(8);
  poses.push({-1'000'000, -0.01, 0, 0, 0, 0, 0});
  poses.push({101'000'000, 1.01, 0, 0, 0, 0, 0});
  RevolutionCloud cloud(CloudShape{2, 100});
  aligner.align(image, &poses, cloud);
  const std::size_t a = cloud.index(0, 0), b = cloud.index(0, 99);
  ASSERT_EQ(cloud.state[a], PointState::valid);
  EXPECT_NEAR(cloud.ref_x + static_cast<double>(cloud.aligned_x[a]), 5.005, 1e-3);
  EXPECT_NEAR(cloud.ref_x + static_cast<double>(cloud.aligned_x[b]), 4.0 + 0.995, 1e-3);

  // No pose stream: the fixed pitch levels the sensor. Nose down by 10
  // degrees, a point 5 m along the sensor's x lies 5 sin(10 deg) below it.
  mount.fixed_pitch_deg = 10.0;
  CloudAligner fixed(mount, fp);
  fixed.align(image, nullptr, cloud);
  EXPECT_NEAR(static_cast<double>(cloud.aligned_z[a]), -5.0 * std::sin(10.0 * std::numbers::pi / 180.0), 1e-5);
  EXPECT_EQ(fixed.counters().no_pose, 1u);
}

// `yaml` must be refused with an error naming `line` and containing `fragment`.
void expect_config_error(const char* yaml, int line, const char* fragment) {
  const ConfigNode node = ConfigNode::parse(yaml, "robot.yaml");
  try {
    parse_obstacle_config(node.map("obstacles"));
    ADD_FAILURE() << "accepted: " << yaml;
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.line(), line) << yaml;
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST(ObstacleConfig, DefaultsAreTheThesisAndErrorsNameTheLine) {
  const ObstacleConfig d;
  EXPECT_EQ(d.features.ring_neighbours, 5);
  EXPECT_EQ(d.features.cross_neighbours, 2);
  EXPECT_FLOAT_EQ(d.features.min_distance, 0.05f);
  EXPECT_EQ(d.map.size, 600);
  EXPECT_DOUBLE_EQ(d.map.resolution, 0.1);
  EXPECT_FLOAT_EQ(d.classes[static_cast<int>(TerrainClass::grass)].max_step_height, 0.5f);
  EXPECT_FLOAT_EQ(d.classes[static_cast<int>(TerrainClass::dirt)].alpha, 3.0f);

  const ConfigNode ok = ConfigNode::parse(
      "obstacles:\n  model: PW\n  terrain: grass\n  classes:\n    grass: {max_step_height: 0.4}\n", "robot.yaml");
  const ObstacleConfig c = parse_obstacle_config(ok.map("obstacles"));
  EXPECT_EQ(c.model, FusionModel::pw);
  ASSERT_TRUE(c.fixed_class.has_value());
  EXPECT_EQ(*c.fixed_class, TerrainClass::grass);
  EXPECT_FLOAT_EQ(c.classes[static_cast<int>(TerrainClass::grass)].max_step_height, 0.4f);

  expect_config_error("obstacles:\n  map:\n    size: 600\n    resolutoin: 0.1\n", 4, "resolutoin");  // misspelt
  EXPECT_FLOAT_EQ(d.map.dirac_top_hold_s, d.map.dirac_hold_s);  // the thesis' hold unless asked
  const ConfigNode holds =
      ConfigNode::parse("obstacles:\n  map: {dirac_top_hold: 10, dirac_clear_depth: 0.15}\n", "robot.yaml");
  const ObstacleConfig h = parse_obstacle_config(holds.map("obstacles"));
  EXPECT_FLOAT_EQ(h.map.dirac_top_hold_s, 10.0f);
  EXPECT_FLOAT_EQ(h.map.dirac_clear_depth, 0.15f);
  EXPECT_FALSE(d.classes[static_cast<int>(TerrainClass::grass)].top_hold_s.has_value());
  EXPECT_FLOAT_EQ(d.classes[static_cast<int>(TerrainClass::other)].top_hold_s.value_or(0.0f), kTopHoldForever);
  const ConfigNode class_hold =
      ConfigNode::parse("obstacles:\n  classes:\n    other: {top_hold: 30}\n    dirt: {top_hold: 4}\n", "robot.yaml");
  const ObstacleConfig ch = parse_obstacle_config(class_hold.map("obstacles"));
  EXPECT_FLOAT_EQ(ch.classes[static_cast<int>(TerrainClass::other)].top_hold_s.value_or(0.0f), 30.0f);
  EXPECT_FLOAT_EQ(ch.classes[static_cast<int>(TerrainClass::dirt)].top_hold_s.value_or(0.0f), 4.0f);
  expect_config_error("obstacles:\n  classes:\n    other:\n      top_hold: -1\n", 4, "top_hold");
  const ConfigNode range = ConfigNode::parse("obstacles:\n  features: {max_range: 80}\n", "robot.yaml");
  EXPECT_THROW(parse_obstacle_config(range.map("obstacles")), ConfigError);
  expect_config_error("obstacles:\n  mount:\n    translation: [0.2, 1.1]\n", 3, "three numbers");
  expect_config_error("obstacles:\n  features:\n    self_box: [-1, 1, 0.5, -0.5, -1, 0]\n", 3, "lower to a higher");
  const ConfigNode box5 = ConfigNode::parse("obstacles:\n  features: {self_box: [-1, 1, -0.5, 0.5, -1]}\n", "robot.yaml");
  EXPECT_THROW(parse_obstacle_config(box5.map("obstacles")), ConfigError);
  EXPECT_FALSE(d.features.self_box.has_value());
  const ConfigNode box_ok =
      ConfigNode::parse("obstacles:\n  features: {self_box: [-0.4, 0.6, -0.3, 0.3, -0.9, 0.1]}\n", "robot.yaml");
  const ObstacleConfig b = parse_obstacle_config(box_ok.map("obstacles"));
  ASSERT_TRUE(b.features.self_box.has_value());
  EXPECT_FLOAT_EQ((*b.features.self_box)[1], 0.6f);
  EXPECT_FLOAT_EQ((*b.features.self_box)[4], -0.9f);
  const ConfigNode mount_ok =
      ConfigNode::parse("obstacles:\n  mount: {translation: [0.2, 0, 1.1], rotation: [0, 2, 0]}\n", "robot.yaml");
  const ObstacleConfig m = parse_obstacle_config(mount_ok.map("obstacles"));
  EXPECT_DOUBLE_EQ(m.mount.translation[2], 1.1);
  EXPECT_DOUBLE_EQ(m.mount.rotation_deg[1], 2.0);
}

TEST(ObstaclePipeline, NoHeapOperationsPerRevolutionAfterArm) {
  ObstacleConfig config;
  config.compare_models = true;
  auto made = ObstaclePipeline::create(config, kitti_shape());
  ASSERT_TRUE(made.pipeline) << made.error;
  ObstaclePipeline& pipeline = *made.pipeline;
  // Two real scans, a moving pose and a terrain map, loaded before arm.
  std::vector<float> buffer;
  std::array<velodyne::RangeImage, 2> images{velodyne::RangeImage(kitti_shape()), velodyne::RangeImage(kitti_shape())};
  ASSERT_TRUE(load_kitti_scan(test::shared_data("kitti/000000.bin"), buffer, images[0]));
  ASSERT_TRUE(load_kitti_scan(test::shared_data("kitti/000001.bin"), buffer, images[1]));
  PoseTrack poses(256);
  TerrainClassMap terrain;
  for (std::int32_t y = 0; y < terrain.grid().size_y(); ++y) {
    for (std::int32_t x = 0; x < terrain.grid().size_x(); ++x) {
      terrain.grid().at({terrain.grid().origin().x + x, terrain.grid().origin().y + y}).set({0.6f, 0.2f, 0.1f, 0.05f, 0.05f});
    }
  }
  Broadcast<velodyne::RangeImage> revolutions(1, kitti_shape());
  Mailbox<ObstacleSnapshot> out(config.map.size, config.map.size);
  PoseQueue pose_queue;
  ObstacleTask task(pipeline, revolutions.reader(0), &pose_queue, nullptr, out);

  alloc_guard::set_fatal(false);
  alloc_guard::mark_realtime_thread("obstacles");
  ASSERT_TRUE(alloc_guard::arm());
  for (int n = 0; n < 20; ++n) {
    velodyne::RangeImage& image = images[static_cast<std::size_t>(n % 2)];
    image.start_ns = n * 100'000'000LL;
    image.end_ns = image.start_ns + 100'000'000LL;
    poses.push({image.end_ns, 0.3 * n, 0.05 * n, 0.0, 0.01, -0.02, 0.01 * n});
    pipeline.process(image, &poses, &terrain);
    // And through the task: pose queue, mailbox in, snapshot out.
    pose_queue.try_push(Pose{image.end_ns, 0.3 * n, 0.0, 0.0, 0.0, 0.0, 0.0});
    revolutions.write_slot() = image;
    revolutions.write_slot().sequence = static_cast<std::uint64_t>(n + 1);
    revolutions.publish();
    task.run(TaskTick{});
  }
  alloc_guard::disarm();
  alloc_guard::unmark_current_thread();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
  EXPECT_EQ(task.counters().revolutions, 20u);
  EXPECT_EQ(pipeline.counters().revolutions, 40u);  // 20 direct, 20 through the task
  const ObstacleSnapshot* snap = out.try_read();
  ASSERT_NE(snap, nullptr);
  EXPECT_EQ(snap->revolution, 20u);
  std::size_t known = 0;
  for (std::int8_t v : snap->occupancy) known += v >= 0;
  EXPECT_GT(known, 10000u);
}

}  // namespace
}  // namespace trailnav::perception
