// Pose estimation: gyro-aided odometry on hand-made motions (a circle at
// known speed and turn rate, a standstill that must not turn, the wheels
// alone when the IMU falls silent, lookups by time), the UTM alignment on a
// synthetic drive with a known odometry->UTM transform, white GPS noise,
// outliers and a permanent jump, and the pose task on the scheduler without
// heap use once armed.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <random>
#include <thread>

#include "trailnav/navigation/pose/pose_estimator.hpp"
#include "trailnav/runtime/alloc_guard.hpp"
#include "../support/no_allocations.hpp"

using namespace trailnav;
using namespace trailnav::pose;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr std::int64_t kStart = 1'782'045'000'000'000'000LL;
constexpr std::int64_t ms(double v) { return static_cast<std::int64_t>(v * 1e6); }

imu::Attitude attitude(std::int64_t t, double yaw_rate, double roll = 0.0, double pitch = 0.0) {
  imu::Attitude a;
  a.time_ns = t;
  a.yaw_rate = yaw_rate;
  a.roll = roll;
  a.pitch = pitch;
  return a;
}

can::OdometryState wheels(std::int64_t t, double speed, double yaw_rate) {
  can::OdometryState w;
  w.time_ns = t;
  w.speed = speed;
  w.yaw_rate = yaw_rate;
  return w;
}

// The true planar motion of a drive's simulated robot: one step of dt at
// speed v and turn rate w (the midpoint heading).
struct PlanarTruth {
  double heading = 0.0, x = 0.0, y = 0.0;
  void step(double v, double w, double dt) noexcept {
    const double mid = heading + 0.5 * w * dt;
    x += v * dt * std::cos(mid);
    y += v * dt * std::sin(mid);
    heading += w * dt;
  }
};

gps::GpsFix fix_at(const UtmAlignment& ref, double e, double n, std::int64_t t, double sigma) {
  double lat = 0, lon = 0;
  EXPECT_TRUE(ref.reverse(e, n, lat, lon));
  gps::GpsFix f;
  f.mode = 3;
  f.status = gps::FixStatus::gps;
  f.lat = lat;
  f.lon = lon;
  f.alt_msl = 270.0;
  f.geoid_sep = 48.0;
  f.sigma_lat = f.sigma_lon = sigma;
  f.has_date = true;
  f.utc_ns = t;
  return f;
}

}  // namespace

TEST(GyroOdometry, DrivesACircleOfTheRightRadius) {
  GyroOdometryOptions o;
  o.history = 8192;
  GyroOdometry odo(o);
  const double v = 1.5, w = 0.15;  // radius 10 m
  for (int k = 0; k <= 4189; ++k) {  // 41.89 s: one full turn
    const std::int64_t t = kStart + ms(10.0 * k);
    if (k % 2 == 0) odo.add_wheels(wheels(t, v, w));
    odo.add_imu(attitude(t, w));
  }
  const LocalPose& p = odo.pose();
  EXPECT_NEAR(p.distance, v * 41.89, 0.02);
  EXPECT_NEAR(std::hypot(p.x, p.y), 0.0, 0.05);  // back where it started
  EXPECT_NEAR(std::abs(p.yaw), 2 * kPi - 0.15 * 41.89 + 0.0, 0.01);
  // Half way the robot is a diameter to the left.
  LocalPose half;
  ASSERT_TRUE(odo.pose_at(kStart + ms(41890.0 / 2), half));
  EXPECT_NEAR(half.x, 0.0, 0.05);
  EXPECT_NEAR(half.y, 20.0, 0.05);
  EXPECT_EQ(odo.counters().gaps, 0u);
  EXPECT_EQ(p.source, PoseSource::gyro_odometry);
}

TEST(GyroOdometry, StandstillHoldsTheHeadingAgainstGyroDrift) {
  GyroOdometry odo;
  for (int k = 0; k <= 1000; ++k) {
    const std::int64_t t = kStart + ms(10.0 * k);
    if (k % 2 == 0) odo.add_wheels(wheels(t, 0.0, 0.0));
    odo.add_imu(attitude(t, 0.01));  // a biased gyro
  }
  EXPECT_EQ(odo.pose().yaw, 0.0);
  EXPECT_EQ(odo.pose().x, 0.0);
  EXPECT_TRUE(odo.pose().standstill);
  EXPECT_GT(odo.counters().standstill_steps, 900u);
  // The bias handed back from GPS is taken off from then on.
  odo.set_yaw_rate_bias(0.01);
  for (int k = 1001; k <= 2000; ++k) {
    const std::int64_t t = kStart + ms(10.0 * k);
    if (k % 2 == 0) odo.add_wheels(wheels(t, 1.0, 0.0));
    odo.add_imu(attitude(t, 0.01));
  }
  EXPECT_NEAR(odo.pose().yaw, 0.0, 1e-9);
  EXPECT_NEAR(odo.pose().x, 10.0, 0.02);
}

TEST(GyroOdometry, WheelsCarryThePoseWhenTheImuFallsSilentAndPitchClimbs) {
  GyroOdometry odo;
  for (int k = 0; k <= 100; ++k) {
    const std::int64_t t = kStart + ms(10.0 * k);
    odo.add_wheels(wheels(t, 1.0, 0.0));
    odo.add_imu(attitude(t, 0.0, 0.0, -0.1));  // nose up 0.1 rad
  }
  EXPECT_NEAR(odo.pose().z, std::sin(0.1) * 1.0, 0.01);
  EXPECT_NEAR(odo.pose().x, std::cos(0.1) * 1.0, 0.01);
  for (int k = 101; k <= 300; ++k) odo.add_wheels(wheels(kStart + ms(10.0 * k), 1.0, 0.1));
  EXPECT_EQ(odo.pose().source, PoseSource::wheels_only);
  EXPECT_NEAR(odo.pose().yaw, 0.1 * 1.9, 0.02);  // the IMU timed out after 0.1 s
  EXPECT_GT(odo.counters().wheel_steps, 180u);
  // The IMU was heard, so the wheels' yaw rate is a stand-in: the pose says
  // its rotation is unmeasured (not mapped with), its translation is fine.
  EXPECT_FALSE(odo.pose().rotation_valid);
  EXPECT_TRUE(odo.pose().translation_valid);
  LocalPose p;
  EXPECT_FALSE(odo.pose_at(kStart + ms(5000.0), p));  // beyond the newest
  ASSERT_TRUE(odo.pose_at(kStart + ms(1000.0), p));
  EXPECT_TRUE(p.rotation_valid);  // kept poses keep what they were
  // The IMU back: measured again.
  odo.add_imu(attitude(kStart + ms(3010.0), 0.1, 0.0, -0.1));
  EXPECT_TRUE(odo.pose().rotation_valid);
  EXPECT_EQ(odo.pose().source, PoseSource::gyro_odometry);
}

// A robot without an IMU: the wheels carry the pose by design, and it is valid.
TEST(GyroOdometry, WithoutAnImuTheWheelsPoseIsAMeasuredOne) {
  GyroOdometry odo;
  for (int k = 0; k <= 200; ++k) odo.add_wheels(wheels(kStart + ms(10.0 * k), 1.0, 0.1));
  EXPECT_EQ(odo.pose().source, PoseSource::wheels_only);
  EXPECT_NEAR(odo.pose().yaw, 0.2, 0.01);
  EXPECT_TRUE(odo.pose().rotation_valid);
  EXPECT_TRUE(odo.pose().translation_valid);
}

// A robot with an IMU whose first reading has not come yet (the device still
// starting): the wheels' pose is a stand-in, not a measured rotation.
TEST(GyroOdometry, WithAnImuConfiguredTheWheelsAloneAreNotAMeasuredRotationBeforeItSpeaks) {
  GyroOdometryOptions o;
  o.imu_expected = true;
  GyroOdometry odo(o);
  for (int k = 0; k <= 50; ++k) odo.add_wheels(wheels(kStart + ms(10.0 * k), 1.0, 0.1));
  EXPECT_EQ(odo.pose().source, PoseSource::wheels_only);
  EXPECT_FALSE(odo.pose().rotation_valid);
  EXPECT_TRUE(odo.pose().translation_valid);
  odo.add_imu(attitude(kStart + ms(510.0), 0.1));
  EXPECT_TRUE(odo.pose().rotation_valid);
  EXPECT_EQ(odo.pose().source, PoseSource::gyro_odometry);
}

TEST(UtmAlignment, FindsTheTransformDespiteOutliersAndFollowsAJump) {
  UtmAlignmentOptions o;
  o.zone = 32;
  o.antenna = {0.2, 0.0, 1.2};
  UtmAlignment ref(o);
  // A known reference point to project from (zone 32, Freiburg).
  double e0 = 0, n0 = 0, g = 0;
  UtmAlignment tmp(o);
  ASSERT_TRUE(tmp.forward(48.0133, 7.8353, e0, n0, g));
  const double theta = 0.7;  // odometry frame -> grid rotation
  GyroOdometry odo;
  UtmAlignment align(o);
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 0.3);
  PlanarTruth truth;  // in the odometry frame
  for (int k = 0; k <= 12000; ++k) {  // 120 s at 100 Hz: straight, a quarter turn, straight
    const double ts = 0.01 * k;
    const std::int64_t t = kStart + ms(10.0 * k);
    const double w = ts > 40 && ts < 50 ? kPi / 20 : 0.0;
    if (k > 0) truth.step(1.2, w, 0.01);
    const double heading = truth.heading, x = truth.x, y = truth.y;
    odo.add_wheels(wheels(t, 1.2, w));
    odo.add_imu(attitude(t, w + 0.002));  // a gyro bias the GPS must find
    if (k % 10 == 0 && k > 0) {
      const double ax = x + std::cos(heading) * 0.2, ay = y + std::sin(heading) * 0.2;
      double e = e0 + std::cos(theta) * ax - std::sin(theta) * ay + noise(rng);
      double n = n0 + std::sin(theta) * ax + std::cos(theta) * ay + noise(rng);
      if (k % 170 == 0) e += 25.0;  // multipath outliers
      if (ts > 80) n += 8.0;        // the correction source changed: a lasting jump
      align.add_fix(fix_at(ref, e, n, t, 0.35), t, odo);
    }
  }
  ASSERT_TRUE(align.heading_valid());
  const UtmAlignmentCounters& c = align.counters();
  EXPECT_GE(c.outliers, 6u);
  EXPECT_EQ(c.jumps, 1u);
  EXPECT_NEAR(align.gyro_bias(), 0.002, 0.0005);
  // The robot's UTM position now: the truth plus the jump the GPS made.
  const UtmPose u = align.utm(odo.pose());
  const double te = e0 + std::cos(theta) * truth.x - std::sin(theta) * truth.y;
  const double tn = n0 + std::sin(theta) * truth.x + std::cos(theta) * truth.y + 8.0;
  EXPECT_NEAR(u.easting, te, 0.5);
  EXPECT_NEAR(u.northing, tn, 0.5);
  EXPECT_NEAR(std::remainder(u.yaw - (truth.heading + theta), 2 * kPi), 0.0, 0.02);
  EXPECT_GT(u.sigma_position(), 0.05);
  EXPECT_LT(u.sigma_position(), 2.0);
  EXPECT_NEAR(u.latitude, 48.0133, 0.01);
  EXPECT_EQ(u.zone, 32);
}

TEST(UtmAlignment, NoHeadingBeforeTheRobotMovesAndBadFixesAreCounted) {
  GyroOdometry odo;
  UtmAlignment align;
  gps::GpsFix none;
  align.add_fix(none, kStart, odo);
  EXPECT_EQ(align.counters().no_position, 1u);
  odo.add_imu(attitude(kStart, 0.0));
  UtmAlignmentOptions zo;
  zo.zone = 32;
  UtmAlignment ref(zo);
  double e = 0, n = 0, g = 0;
  ASSERT_TRUE(ref.forward(48.0133, 7.8353, e, n, g));
  align.add_fix(fix_at(ref, e, n, kStart, 100.0), kStart, odo);
  EXPECT_EQ(align.counters().too_uncertain, 1u);
  align.add_fix(fix_at(ref, e, n, kStart, 1.0), kStart, odo);
  EXPECT_EQ(align.zone(), 32);
  EXPECT_FALSE(align.heading_valid());
  const UtmPose u = align.utm(odo.pose());
  EXPECT_TRUE(u.position_valid);
  EXPECT_FALSE(u.heading_valid);
  EXPECT_NEAR(u.easting, e, 1e-6);
  align.add_fix(fix_at(ref, e, n, kStart + ms(10000), 1.0), kStart + ms(10000), odo);
  EXPECT_EQ(align.counters().no_odometry, 1u);
}

// Place fixes (the camera's place recognition): where GPS is lost and the
// gyro's bias changes, they hold the position that odometry alone lets
// drift; one far off is gated out; and without any GPS they align the
// odometry frame by themselves.
TEST(UtmAlignment, PlaceFixesHoldThePositionWhereGpsIsLostAndAlignWithoutIt) {
  UtmAlignmentOptions o;
  o.zone = 32;
  UtmAlignment ref(o);
  double e0 = 0, n0 = 0, g = 0;
  ASSERT_TRUE(ref.forward(48.0133, 7.8353, e0, n0, g));
  const double theta = 0.4;
  const auto to_utm = [&](double x, double y, double& e, double& n) {
    e = e0 + std::cos(theta) * x - std::sin(theta) * y;
    n = n0 + std::sin(theta) * x + std::cos(theta) * y;
  };
  // 300 s at 1.5 m/s with slow turns; GPS for the first 60 s (if at all),
  // then the gyro's bias grows by 0.003 rad/s; place fixes every 2 s after
  // 60 s (if at all), 2 m of noise, sigma 3 m, and one 400 m off at 200 s.
  struct Result {
    double error = 0.0;
    bool aligned = false;
    UtmAlignmentCounters counters;
  };
  const auto drive = [&](bool gps, bool places) -> Result {
    GyroOdometry odo;
    UtmAlignment align(o);
    std::mt19937 rng(3);
    std::normal_distribution<double> gps_noise(0.0, 0.3), place_noise(0.0, 2.0);
    PlanarTruth truth;
    for (int k = 0; k <= 30000; ++k) {
      const double ts = 0.01 * k;
      const std::int64_t t = kStart + ms(10.0 * k);
      const double w = 0.05 * std::sin(ts / 20.0);
      if (k > 0) truth.step(1.5, w, 0.01);
      const double x = truth.x, y = truth.y;
      odo.add_wheels(wheels(t, 1.5, w));
      odo.add_imu(attitude(t, w + (ts > 60.0 ? 0.003 : 0.0)));
      double e = 0, n = 0;
      to_utm(x, y, e, n);
      if (gps && ts <= 60.0 && k % 10 == 0 && k > 0)
        align.add_fix(fix_at(ref, e + gps_noise(rng), n + gps_noise(rng), t, 0.35), t, odo);
      if (places && (ts > 60.0 || !gps) && k % 200 == 100) {
        // Answered a second late, as the place task's lag makes them.
        double pe = e + place_noise(rng), pn = n + place_noise(rng);
        if (k == 20100) pe += 400.0;
        double lat = 0, lon = 0;
        EXPECT_TRUE(ref.reverse(pe, pn, lat, lon));
        align.add_place(lat, lon, 3.0, t - ms(1000), odo);
      }
    }
    const UtmPose u = align.utm(odo.pose());
    double e = 0, n = 0;
    to_utm(truth.x, truth.y, e, n);
    return Result{std::hypot(u.easting - e, u.northing - n), align.heading_valid(), align.counters()};
  };
  const Result lost = drive(true, false), held = drive(true, true), alone = drive(false, true);
  std::printf("[ pose ] 240 s without GPS: %.1f m off by odometry alone, %.1f m with place fixes; place fixes alone: %.1f m\n",
              lost.error, held.error, alone.error);
  EXPECT_GT(lost.error, 20.0);
  EXPECT_LT(held.error, 4.0);
  EXPECT_EQ(held.counters.place_outliers, 1u);  // the one 400 m off
  EXPECT_GE(held.counters.place_used, 115u);
  EXPECT_TRUE(alone.aligned);
  EXPECT_LT(alone.error, 5.0);
  EXPECT_EQ(alone.counters.used, 0u);
  // Refused: no position, no sigma, a time the odometry never had.
  GyroOdometry odo;
  odo.add_imu(attitude(kStart, 0.0));
  UtmAlignment a(o);
  EXPECT_FALSE(a.add_place(std::nan(""), 7.8, 3.0, kStart, odo));
  EXPECT_FALSE(a.add_place(48.0, 7.8, 0.0, kStart, odo));
  EXPECT_FALSE(a.add_place(48.0, 7.8, 3.0, kStart - ms(60000), odo));
  EXPECT_EQ(a.counters().place_refused, 3u);
  EXPECT_EQ(a.counters().place_offered, 3u);
}

// The pose task's policy for place answers: with `gps_poor`, passed over
// while GPS is good, taken once fixes stop; weak ones (probability, not in
// a sequence) never; `off` takes none.
TEST(PoseTask, PlaceAnswersAreTakenWhenGpsIsPoorAndTheyAreStrong) {
  for (const PlaceUse use : {PlaceUse::gps_poor, PlaceUse::off}) {
    SpscQueue<imu::ImuReading, imu::kImuQueueCapacity> imu_queue;
    SpscQueue<can::OdometryState, can::kOdometryQueueCapacity> wheel_queue;
    Mailbox<gps::GpsReading> gps_box;
    Mailbox<perception::place::PlaceSnapshot> place_box;
    PoseEstimatorOptions o;
    o.utm.zone = 32;
    PoseTask task(o, &imu_queue, &wheel_queue, &gps_box);
    PlaceUseOptions po;
    po.use = use;
    task.set_place_input(&place_box, po);
    UtmAlignment ref(o.utm);
    double e0 = 0, n0 = 0, g = 0;
    ASSERT_TRUE(ref.forward(48.0133, 7.8353, e0, n0, g));
    const auto place = [&](std::int64_t t, double e, double probability, bool in_sequence) {
      perception::place::PlaceSnapshot& p = place_box.write_slot();
      p = {};
      p.stamp_ns = t;
      EXPECT_TRUE(ref.reverse(e, n0, p.lat, p.lon));
      p.probability = probability;
      p.in_sequence = in_sequence;
      p.cov_xx = p.cov_yy = 9.0;
      place_box.publish();
    };
    // Grid east at 2 m/s; GPS for 10 s, none after; answers at 5 s (GPS
    // good), 12 s (weak, then not in a sequence) and 14 s (strong).
    for (int k = 0; k < 1600; ++k) {
      const std::int64_t t = kStart + ms(10.0 * k);
      imu::ImuReading r;
      r.attitude = attitude(t, 0.0);
      ASSERT_TRUE(imu_queue.try_push(r));
      ASSERT_TRUE(wheel_queue.try_push(wheels(t, 2.0, 0.0)));
      if (k % 10 == 5 && k < 1000) {
        gps::GpsReading& slot = gps_box.write_slot();
        slot.fix = fix_at(ref, e0 + 0.02 * (k - 5), n0, t - ms(50), 0.5);
        slot.receive_ns = t;
        gps_box.publish();
      }
      if (k == 500) place(t - ms(500), e0 + 0.02 * (k - 50), 0.9, true);
      if (k == 1200) place(t - ms(500), e0 + 0.02 * (k - 50), 0.1, true);
      if (k == 1250) place(t - ms(500), e0 + 0.02 * (k - 50), 0.9, false);
      if (k == 1400) place(t - ms(500), e0 + 0.02 * (k - 50), 0.9, true);
      task.run(TaskTick{static_cast<std::uint64_t>(k), t, t});
    }
    const PoseTaskStatus s = task.status();
    EXPECT_EQ(s.place_answers, 4u);
    if (use == PlaceUse::off) {
      EXPECT_EQ(s.utm_counters.place_offered + s.place_gps_good + s.place_weak, 0u);
      continue;
    }
    EXPECT_EQ(s.place_gps_good, 1u);
    EXPECT_EQ(s.place_weak, 2u);
    EXPECT_EQ(s.utm_counters.place_offered, 1u);
    EXPECT_EQ(s.utm_counters.place_used, 1u);
  }
}

TEST(PoseTask, ArmedTaskNeverTouchesTheHeap) {
  ASSERT_TRUE(alloc_guard::hook_installed());
  alloc_guard::set_fatal(false);
  alloc_guard::reset_counters();
  SpscQueue<imu::ImuReading, imu::kImuQueueCapacity> imu_queue;
  SpscQueue<can::OdometryState, can::kOdometryQueueCapacity> wheel_queue;
  Mailbox<gps::GpsReading> gps_box;
  PoseEstimatorOptions o;
  o.utm.zone = 32;
  PoseTask task(o, &imu_queue, &wheel_queue, &gps_box);
  Mailbox<perception::place::PlaceSnapshot> place_box;
  task.set_place_input(&place_box, {PlaceUse::always, 0.3, true, 2.0, 5.0});
  UtmAlignment ref(o.utm);
  double e0 = 0, n0 = 0, g = 0;
  ASSERT_TRUE(ref.forward(48.0133, 7.8353, e0, n0, g));
  MonotonicClock clock;
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  ASSERT_TRUE(scheduler.add({"pose", TaskKind::periodic, 200.0, 2 * kNanosPerMilli, 0, -1}, task));
  ASSERT_TRUE(scheduler.start());
  ASSERT_TRUE(alloc_guard::arm());
  for (int k = 0; k < 1500; ++k) {
    const std::int64_t t = kStart + ms(10.0 * k);
    imu::ImuReading r;
    r.attitude = attitude(t, 0.0);
    while (!imu_queue.try_push(r)) std::this_thread::sleep_for(std::chrono::microseconds(100));
    while (!wheel_queue.try_push(wheels(t, 2.0, 0.0))) std::this_thread::sleep_for(std::chrono::microseconds(100));
    if (k % 10 == 5) {
      gps::GpsReading& slot = gps_box.write_slot();
      slot.fix = fix_at(ref, e0 + 0.02 * (k - 5), n0, t - ms(50), 0.5);
      slot.receive_ns = t;
      gps_box.publish();
      std::this_thread::sleep_for(std::chrono::milliseconds(8));  // the task takes each fix (10 Hz GPS, 200 Hz task)
    }
    if (k % 100 == 55) {  // a place answer a second, for 0.5 s before
      perception::place::PlaceSnapshot& p = place_box.write_slot();
      p.stamp_ns = t - ms(500);
      EXPECT_TRUE(ref.reverse(e0 + 0.02 * (k - 50), n0, p.lat, p.lon));
      p.probability = 0.6;
      p.in_sequence = true;
      p.cov_xx = p.cov_yy = 4.0;
      place_box.publish();
    }
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(30));
  scheduler.stop();
  alloc_guard::disarm();
  const PoseTaskStatus s = task.status();
  EXPECT_EQ(s.imu_readings, 1500u);
  EXPECT_EQ(s.wheel_readings, 1500u);
  EXPECT_GT(s.gps_fixes, 100u);
  EXPECT_TRUE(s.utm.heading_valid);
  EXPECT_NEAR(s.local.x, 2.0 * 14.99, 0.05);
  EXPECT_NEAR(s.utm.yaw, 0.0, 0.05);  // driving grid east
  EXPECT_GT(s.utm_counters.place_offered, 5u);
  EXPECT_GT(s.utm_counters.place_used, 5u);
  test::expect_no_realtime_allocations();
}

namespace {

// Pushes the IMU readings (yaw rate `imu_rate`) and wheel readings (no yaw
// rate of their own) of [from, to) ms, 10 ms apart.
void push_imu(SpscQueue<imu::ImuReading, imu::kImuQueueCapacity>& q, int from, int to, double imu_rate) {
  for (int k = from; k < to; k += 10) {
    imu::ImuReading r;
    r.attitude = attitude(kStart + ms(k), imu_rate);
    ASSERT_TRUE(q.try_push(r));
  }
}
void push_wheels(SpscQueue<can::OdometryState, can::kOdometryQueueCapacity>& q, int from, int to) {
  for (int k = from; k < to; k += 10) ASSERT_TRUE(q.try_push(wheels(kStart + ms(k), 1.0, 0.0)));
}

}  // namespace

// The IMU's readings come through their own thread and can be late next to
// the wheels' (its thread lost its core). The wheel readings wait for them:
// every IMU reading is integrated, none is lost as a step into the past, and
// the heading is the IMU's (the wheels here say "straight on", the IMU turns).
TEST(PoseTask, WheelReadingsWaitForTheIMUReadingsOfTheirTime) {
  SpscQueue<imu::ImuReading, imu::kImuQueueCapacity> imu_queue;
  SpscQueue<can::OdometryState, can::kOdometryQueueCapacity> wheel_queue;
  PoseEstimatorOptions o;
  PoseTask task(o, &imu_queue, &wheel_queue, nullptr);
  const double rate = 0.5;  // rad/s
  push_imu(imu_queue, 0, 50, rate);
  push_wheels(wheel_queue, 0, 400);  // the wheels 350 ms ahead of the IMU
  task.run(TaskTick{0, 0, ms(100)});
  EXPECT_EQ(task.status().wheels_held, 35u);
  push_imu(imu_queue, 50, 400, rate);
  task.run(TaskTick{1, 0, ms(130)});  // the IMU spoke 30 ms ago (host time): live
  const PoseTaskStatus s = task.status();
  EXPECT_EQ(s.imu_readings, 40u);
  EXPECT_EQ(s.wheel_readings, 40u);
  EXPECT_EQ(s.odometry_counters.imu_steps, 40u);
  EXPECT_EQ(s.odometry_counters.wheel_steps, 1u);  // the very first reading, before any IMU one: it starts the odometry
  EXPECT_EQ(s.odometry_counters.gaps, 0u);
  EXPECT_EQ(s.wheels_released_early, 0u);
  EXPECT_NEAR(s.local.yaw, rate * 0.39, 1e-9);  // 39 steps of 10 ms at the IMU's rate
  EXPECT_NEAR(s.local.distance, 0.39, 1e-9);
}

// A silent IMU does not hold the wheels back: after imu_timeout of host time
// the held readings go, and the wheels alone carry the pose.
TEST(PoseTask, ASilentIMULetsTheHeldWheelReadingsGo) {
  SpscQueue<imu::ImuReading, imu::kImuQueueCapacity> imu_queue;
  SpscQueue<can::OdometryState, can::kOdometryQueueCapacity> wheel_queue;
  PoseEstimatorOptions o;
  PoseTask task(o, &imu_queue, &wheel_queue, nullptr);
  push_imu(imu_queue, 0, 50, 0.0);
  push_wheels(wheel_queue, 0, 50);
  task.run(TaskTick{0, 0, ms(50)});
  push_wheels(wheel_queue, 50, 500);
  task.run(TaskTick{1, 0, ms(100)});  // IMU 50 ms silent: still waited for (imu_wait 3 s)
  EXPECT_EQ(task.status().odometry_counters.wheel_steps, 1u);  // the first reading only (it started the odometry)
  task.run(TaskTick{2, 0, ms(3100)});  // 3050 ms silent: the IMU is down
  const PoseTaskStatus s = task.status();
  EXPECT_EQ(s.wheels_released_early, 45u);
  EXPECT_GT(s.odometry_counters.wheel_steps, 30u);
  EXPECT_EQ(s.local.source, PoseSource::wheels_only);
  EXPECT_NEAR(s.local.distance, 0.49, 1e-9);
}

// At start-up the CAN bus can speak before the IMU (the device starting, its
// thread late on a busy core). The wheel readings wait for the IMU's first
// readings as they wait for late ones: the odometry starts on the IMU's
// heading, and no pose is turned by the wheels' yaw rate alone.
TEST(PoseTask, WheelReadingsBeforeTheIMUsFirstOneWaitForIt) {
  SpscQueue<imu::ImuReading, imu::kImuQueueCapacity> imu_queue;
  SpscQueue<can::OdometryState, can::kOdometryQueueCapacity> wheel_queue;
  PoseEstimatorOptions o;
  PoseTask task(o, &imu_queue, &wheel_queue, nullptr);
  const double rate = 0.5;  // rad/s
  push_wheels(wheel_queue, 0, 300);
  task.run(TaskTick{0, 0, ms(100)});
  task.run(TaskTick{1, 0, ms(900)});  // 0.8 s without the IMU: still waited for (imu_wait 3 s)
  EXPECT_EQ(task.status().wheels_held, 30u);
  EXPECT_EQ(task.status().odometry_counters.wheel_steps, 0u);
  push_imu(imu_queue, 0, 300, rate);
  task.run(TaskTick{2, 0, ms(1000)});
  const PoseTaskStatus s = task.status();
  EXPECT_EQ(s.odometry_counters.imu_steps, 30u);
  EXPECT_EQ(s.odometry_counters.wheel_steps, 1u);  // the first reading (t = 0, before the IMU's) starts the odometry
  EXPECT_EQ(s.odometry_counters.gaps, 0u);
  EXPECT_EQ(s.wheels_released_early, 0u);
  EXPECT_NEAR(s.local.yaw, rate * 0.29, 1e-9);
  EXPECT_TRUE(s.local.rotation_valid);
}

// An IMU configured that never speaks: after imu_wait the wheels carry the
// pose, and it says its rotation is not measured (the map waits; health
// names the silent IMU).
TEST(PoseTask, AnIMUThatNeverSpeaksLetsTheWheelsGoUnmeasured) {
  SpscQueue<imu::ImuReading, imu::kImuQueueCapacity> imu_queue;
  SpscQueue<can::OdometryState, can::kOdometryQueueCapacity> wheel_queue;
  PoseEstimatorOptions o;
  PoseTask task(o, &imu_queue, &wheel_queue, nullptr);
  push_wheels(wheel_queue, 0, 300);
  task.run(TaskTick{0, 0, ms(100)});
  EXPECT_EQ(task.status().odometry_counters.wheel_steps, 0u);
  task.run(TaskTick{1, 0, ms(3200)});  // 3.1 s after the first wheel reading
  const PoseTaskStatus s = task.status();
  EXPECT_EQ(s.wheels_released_early, 30u);
  EXPECT_EQ(s.odometry_counters.wheel_steps, 30u);
  EXPECT_EQ(s.local.source, PoseSource::wheels_only);
  EXPECT_FALSE(s.local.rotation_valid);
  EXPECT_NEAR(s.local.distance, 0.29, 1e-9);
}

// The online map's correction (MapCorrection, from trailnavd's mapping task)
// is applied to every UTM pose the task hands out, and gradually: a new one
// never makes the UTM pose jump; it moves at most 0.5 m/s at the robot and
// 0.005 rad/s until it is the correction itself.
TEST(PoseTask, TheMapsCorrectionIsAppliedGraduallyToEveryUtmPose) {
  SpscQueue<imu::ImuReading, imu::kImuQueueCapacity> imu_queue;
  SpscQueue<can::OdometryState, can::kOdometryQueueCapacity> wheel_queue;
  Mailbox<gps::GpsReading> gps_box;
  Mailbox<MapCorrection> corrections;
  PoseEstimatorOptions o;
  o.utm.zone = 32;
  PoseTask task(o, &imu_queue, &wheel_queue, &gps_box);
  task.set_map_correction(&corrections);
  UtmAlignment ref(o.utm);
  double e0 = 0, n0 = 0, g = 0;
  ASSERT_TRUE(ref.forward(48.0133, 7.8353, e0, n0, g));
  // Driving grid east at 2 m/s, a fix every 100 ms; the task run every 10 ms.
  auto step = [&](int k) {
    const std::int64_t t = kStart + ms(10.0 * k);
    imu::ImuReading r;
    r.attitude = attitude(t, 0.0);
    ASSERT_TRUE(imu_queue.try_push(r));
    ASSERT_TRUE(wheel_queue.try_push(wheels(t, 2.0, 0.0)));
    if (k % 10 == 5) {
      gps::GpsReading& slot = gps_box.write_slot();
      slot.fix = fix_at(ref, e0 + 0.02 * (k - 5), n0, t - ms(50), 0.5);
      slot.receive_ns = t;
      gps_box.publish();
    }
    task.run(TaskTick{static_cast<std::uint64_t>(k), t, t});
  };
  int k = 0;
  for (; k < 1000; ++k) step(k);
  ASSERT_TRUE(task.status().utm.heading_valid);
  // A correction: 10 m north, turned by 0.02 rad about the zone's origin
  // (at the robot, 500 km east, that is another 10 km or so: the shift
  // limit carries it).
  const double yaw = 0.02;
  MapCorrection& c = corrections.write_slot();
  c = MapCorrection{true, 1, 0.0, 10.0, yaw};
  // Keep the robot where the correction puts it: the rotation about the
  // origin moved by the rotation's shift back.
  const pose::PoseSnapshot* before = task.poses().try_read();
  ASSERT_NE(before, nullptr);
  const double e = before->utm.easting, n = before->utm.northing;
  c.x = e - (std::cos(yaw) * e - std::sin(yaw) * n);
  c.y = n - (std::sin(yaw) * e + std::cos(yaw) * n) + 10.0;
  corrections.publish();
  double last_gap = -1.0, worst_speed = 0.0, worst_turn = 0.0;
  PoseSnapshot raw;
  const PoseSnapshot* previous = nullptr;
  double pe = e, pn = n, pyaw = before->utm.yaw, re = e, rn = n;
  for (int j = 0; j < 3000; ++j, ++k) {
    step(k);
    const PoseSnapshot* p = task.poses().try_read();
    ASSERT_NE(p, nullptr);
    task.estimator().snapshot(raw);  // the alignment's own, uncorrected
    // The change beyond the robot's own motion (the alignment's), per 10 ms.
    const double moved = std::hypot((p->utm.easting - pe) - (raw.utm.easting - re), (p->utm.northing - pn) - (raw.utm.northing - rn));
    worst_speed = std::max(worst_speed, moved / 0.01);
    worst_turn = std::max(worst_turn, std::fabs(std::remainder(p->utm.yaw - pyaw, 2.0 * kPi)) / 0.01);
    pe = p->utm.easting;
    pn = p->utm.northing;
    pyaw = p->utm.yaw;
    re = raw.utm.easting;
    rn = raw.utm.northing;
    // Where the correction itself puts the robot now.
    const double te = c.x + std::cos(yaw) * raw.utm.easting - std::sin(yaw) * raw.utm.northing;
    const double tn = c.y + std::sin(yaw) * raw.utm.easting + std::cos(yaw) * raw.utm.northing;
    last_gap = std::hypot(p->utm.easting - te, p->utm.northing - tn);
    previous = p;
  }
  ASSERT_NE(previous, nullptr);
  std::printf("[ pose ] a 10 m, 0.02 rad correction applied at most %.3f m/s and %.4f rad/s; after 30 s %.3f m from it\n",
              worst_speed, worst_turn, last_gap);
  EXPECT_LE(worst_speed, 0.5 + 0.1);    // the limit, and the alignment's own updates
  EXPECT_LE(worst_turn, 0.005 + 0.002);
  EXPECT_LT(last_gap, 0.05);            // 10 m at 0.5 m/s: there after 20 s, 30 s given
  EXPECT_NEAR(std::remainder(previous->utm.yaw - raw.utm.yaw, 2.0 * kPi), yaw, 1e-3);
  EXPECT_GE(task.status().map_corrections, 1u);
}
