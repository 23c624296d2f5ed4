// The pose estimator's hot paths: one IMU step of gyro-aided odometry, and one
// GPS fix through the UTM alignment filter (projection, lookup by time,
// six-state update).
#include <benchmark/benchmark.h>

#include <cmath>

#include "trailnav/navigation/pose/pose_estimator.hpp"

namespace trailnav {
namespace {

constexpr std::int64_t kStart = 1'782'045'000'000'000'000LL;

void BM_GyroOdometryImuStep(benchmark::State& state) {
  pose::GyroOdometry odo;
  can::OdometryState w;
  w.speed = 1.5;
  w.yaw_rate = 0.05;
  imu::Attitude a;
  a.yaw_rate = 0.05;
  std::int64_t t = kStart;
  for (auto _ : state) {
    t += 10'000'000;
    w.time_ns = a.time_ns = t;
    odo.add_wheels(w);
    odo.add_imu(a);
    benchmark::DoNotOptimize(odo.pose());
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_GyroOdometryImuStep);

void BM_UtmAlignmentFix(benchmark::State& state) {
  pose::UtmAlignmentOptions o;
  o.zone = 32;
  pose::GyroOdometry odo;
  pose::UtmAlignment align(o);
  double e0 = 0, n0 = 0, g = 0;
  align.forward(48.0133, 7.8353, e0, n0, g);
  can::OdometryState w;
  w.speed = 1.5;
  imu::Attitude a;
  std::int64_t t = kStart;
  gps::GpsFix f;
  f.mode = 3;
  f.sigma_lat = f.sigma_lon = 1.0;
  f.has_date = true;
  double x = 0.0;
  auto step = [&] {
    for (int k = 0; k < 10; ++k) {
      t += 10'000'000;
      w.time_ns = a.time_ns = t;
      odo.add_wheels(w);
      odo.add_imu(a);
      x += 0.015;
    }
    align.reverse(e0 + x, n0, f.lat, f.lon);
    f.utc_ns = t;
  };
  for (int k = 0; k < 100; ++k) {  // past the initial fit
    step();
    align.add_fix(f, t, odo);
  }
  for (auto _ : state) {
    state.PauseTiming();
    step();
    state.ResumeTiming();
    align.add_fix(f, t, odo);
  }
  if (!align.heading_valid()) state.SkipWithError("never aligned");
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_UtmAlignmentFix);

}  // namespace
}  // namespace trailnav

BENCHMARK_MAIN();
