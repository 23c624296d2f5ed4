// The pose estimate on a simulated drive (mixed-route: 330 m of street, dirt
// road and grass track; GPS with a 3 m wandering error, a gyro with a bias,
// wheels with scale errors and slip), scored against the truth as
// `trailnav pose-eval` does.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>

#include "pose_eval.hpp"
#include "roads.hpp"
#include "sim_truth.hpp"
#include "simulator.hpp"

using namespace trailnav;
namespace fs = std::filesystem;

TEST(PoseEval, MixedRouteUtmErrorStaysAtTheGpsLevelAndTheCovarianceIsHonest) {
  const fs::path dir = fs::temp_directory_path() / ("trailnav-pose-eval-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  sim::SimOptions so;
  so.scenario = "mixed-route";
  so.seed = 1;
  so.lidar_packets = false;
  so.out = dir.string();
  const sim::SimReport sr = sim::run_simulation(so);
  ASSERT_EQ(sr.error, "");
  const eval::PoseEvalResult r = eval::evaluate_pose(dir.string(), {});
  ASSERT_EQ(r.error, "");
  std::printf("[ pose ] %.0f m: local drift %.2f m / 100 m (heading %.2f deg); UTM mean %.2f m, p95 %.2f m, "
              "heading %.2f deg, within 2 sigma %.0f %%; raw GPS mean %.2f m\n",
              r.distance, r.drift_mean, r.yaw_drift_mean_deg, r.utm_mean, r.utm_p95, r.heading_mean_deg,
              100 * r.within_2sigma, r.gps_mean);
  EXPECT_GT(r.distance, 300.0);
  EXPECT_NEAR(r.odometry_distance, r.distance, 0.03 * r.distance);
  EXPECT_GE(r.drift_segments, 20u);
  EXPECT_LT(r.drift_mean, 10.0);  // m per 100 m, the gyro bias learned from GPS as the drive goes on
  EXPECT_LT(r.aligned_after_m, 10.0);
  EXPECT_LT(r.utm_mean, 1.1 * r.gps_mean);  // no worse than the fixes, and smooth
  EXPECT_LT(r.heading_mean_deg, 6.0);
  EXPECT_GT(r.within_2sigma, 0.8);          // the covariance covers the real error
  EXPECT_EQ(r.utm_counters.outliers, 0u);   // the simulated receiver has none
  EXPECT_GT(r.utm_counters.used, 2500u);
  EXPECT_EQ(r.rows.size(), 4u);
  fs::remove_all(dir);
}

// The check of points against the simulated trail: through the odometry pose
// at a stamp and the true pose then; a stamp past the trajectory's end only
// within the tolerance given (the robot at its end), never before its start.
TEST(TrailCheck, MapsThroughOdometryAndTruthAndTakesLateStampsOnlyWithinTheTolerance) {
  eval::SimTruth truth;
  // True: along x at 1 m/s from (100, 50) for 10 s, facing +x.
  for (int i = 0; i <= 10; ++i) {
    eval::TruthPose p;
    p.utc_ns = 1'000'000'000'000LL + i * 1'000'000'000LL;
    p.x = 100.0 + i;
    p.y = 50.0;
    truth.trajectory.push_back(p);
  }
  const sim::Polyline trail({{0.0, 50.0}, {300.0, 50.0}});  // the centre line y = 50
  const std::int64_t offset = 5'000'000'000LL;              // daemon clock = recording + 5 s
  eval::TrailCheck check(truth, trail, offset);
  // Odometry: the robot at the origin of its frame facing +y at each second.
  for (int i = 0; i <= 20; ++i) check.add_odometry_pose(truth.trajectory.front().utc_ns + offset + i * 1'000'000'000LL, 0.0, 0.0, std::numbers::pi / 2);
  const std::int64_t t3 = truth.trajectory[3].utc_ns + offset;
  // 2 m ahead of the robot in odometry (0, 2) is (105, 50) in the world: on the centre.
  double wx = 0, wy = 0;
  ASSERT_TRUE(check.to_world(t3, 0.0, 2.0, wx, wy));
  EXPECT_NEAR(wx, 105.0, 1e-9);
  EXPECT_NEAR(wy, 50.0, 1e-9);
  EXPECT_NEAR(check.distance(t3, 0.0, 2.0), 0.0, 1e-9);
  // 1.5 m to its left (-1.5, 0) is 1.5 m off the centre.
  EXPECT_NEAR(check.distance(t3, -1.5, 0.0), 1.5, 1e-9);
  // No odometry pose within 0.2 s: NaN.
  EXPECT_TRUE(std::isnan(check.distance(truth.trajectory.front().utc_ns + offset - 1'000'000'000LL, 0.0, 0.0)));
  // Past the end: NaN without a tolerance, the end pose within it.
  const std::int64_t late = truth.trajectory.back().utc_ns + offset + 3'000'000'000LL;
  EXPECT_TRUE(std::isnan(check.distance(late, 0.0, 0.0)));
  check.set_past_end_tolerance(2'000'000'000LL);
  EXPECT_TRUE(std::isnan(check.distance(late, 0.0, 0.0)));
  check.set_past_end_tolerance(3'000'000'000LL);
  ASSERT_TRUE(check.to_world(late, 0.0, 1.0, wx, wy));
  EXPECT_NEAR(wx, 111.0, 1e-9);
  EXPECT_NEAR(wy, 50.0, 1e-9);
}
