// The pose estimate on a simulated drive (mixed-route: 330 m of street, dirt
// road and grass track; GPS with a 3 m wandering error, a gyro with a bias,
// wheels with scale errors and slip), scored against the truth as
// `trailnav pose-eval` does.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdio>
#include <filesystem>

#include "pose_eval.hpp"
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
