// The bench: a simulated recording replayed by `trailnav replay`'s engine —
// GPS and IMU bytes into pseudo-terminals, CAN frames and the e-stop line
// into their UDP tunnels — read by the GPS, IMU, CAN and GPIO driver tasks on
// the scheduler, as on the robot. Every sentence, sample, frame and line level
// the simulator wrote arrives, the wheel odometry measures the distance the
// truth says was driven, and the e-stop press with its bouncing release is
// seen as one press.
#include <gtest/gtest.h>

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <thread>

#include "../support/eventually.hpp"
#include "replayer.hpp"
#include "simulator.hpp"
#include "trailnav/drivers/can/can_driver.hpp"
#include "trailnav/drivers/gpio/gpio_driver.hpp"
#include "trailnav/drivers/gps/gps_driver.hpp"
#include "trailnav/drivers/imu/imu_driver.hpp"
#include "trailnav/runtime/scheduler.hpp"

using namespace trailnav;
namespace fs = std::filesystem;

TEST(DriversBench, SimulatedRecordingReplaysIntoTheGpsImuCanAndGpioDrivers) {
  const fs::path dir = fs::temp_directory_path() / ("trailnav-drivers-bench-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  sim::SimOptions so;
  so.scenario = "urban";
  so.seed = 2;
  so.duration = 6.0;
  so.out = dir.string();
  const sim::SimReport sr = sim::run_simulation(so);
  ASSERT_EQ(sr.error, "");

  auto dbc = can::load_dbc("board/sim/trailnav-robot.dbc");
  ASSERT_TRUE(dbc.dbc) << dbc.error;
  can::CanDriverOptions co;
  co.tunnel = {0x7F000001u, 0};
  co.tunnel_recorded_time = true;  // replayed at twice the speed
  co.odometry.left = {"WHEEL_SPEEDS", "SpeedLeft"};
  co.odometry.right = {"WHEEL_SPEEDS", "SpeedRight"};
  co.odometry.track = 0.55;
  auto can_driver = can::CanDriver::create(*dbc.dbc, co);
  ASSERT_TRUE(can_driver.driver) << can_driver.error;

  gpio::GpioDriverOptions po;
  po.transport = gpio::GpioTransport::tunnel;
  po.tunnel = {0x7F000001u, 0};
  po.estop_release_debounce = 0.02;
  auto gpio_driver = gpio::GpioDriver::create(po);
  ASSERT_TRUE(gpio_driver.driver) << gpio_driver.error;

  replay::ReplayOptions ro;
  ro.rate = 2.0;
  ro.can_tunnel = can_driver.driver->tunnel_endpoint();
  ro.gpio_tunnel = gpio_driver.driver->tunnel_endpoint();
  ro.serial_links["gps"] = (dir / "gps-link").string();
  ro.serial_links["imu"] = (dir / "imu-link").string();
  auto replayer = replay::Replayer::create(dir.string(), ro);
  ASSERT_TRUE(replayer.replayer) << replayer.error;

  gps::GpsDriverOptions go;
  go.link.device = ro.serial_links["gps"];
  go.link.baud = 9600;
  auto gps_driver = gps::GpsDriver::create(go);
  ASSERT_TRUE(gps_driver.driver) << gps_driver.error;
  imu::ImuDriverOptions io;
  io.link.device = ro.serial_links["imu"];
  auto imu_driver = imu::ImuDriver::create(io);
  ASSERT_TRUE(imu_driver.driver) << imu_driver.error;

  MonotonicClock clock;
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  ASSERT_TRUE(scheduler.add({"gps", TaskKind::periodic, 100.0, 2 * kNanosPerMilli, 0, -1}, *gps_driver.driver));
  ASSERT_TRUE(scheduler.add({"imu", TaskKind::periodic, 200.0, 2 * kNanosPerMilli, 0, -1}, *imu_driver.driver));
  ASSERT_TRUE(scheduler.add({"can", TaskKind::periodic, 200.0, 2 * kNanosPerMilli, 0, -1}, *can_driver.driver));
  ASSERT_TRUE(scheduler.add({"gpio", TaskKind::periodic, 200.0, 2 * kNanosPerMilli, 0, -1}, *gpio_driver.driver));
  ASSERT_TRUE(scheduler.start());
  // The serial drivers open their links on their first ticks; bytes the
  // replayer wrote before would be lost in the pseudo-terminal.
  ASSERT_TRUE(test::eventually([&] {
    return gps_driver.driver->status().link_state == link::LinkState::open &&
           imu_driver.driver->status().link_state == link::LinkState::open;
  }));
  const replay::ReplayReport report = replayer.replayer->run();
  // The drivers read what the replayer wrote at their own pace: wait until
  // every line, sample, frame and level has arrived and the last GPS epoch has
  // been closed by its gap, however long a loaded machine takes; the
  // assertions below then check the counts themselves.
  const std::uint64_t fixes_expected = sr.nmea_sentences / 4;  // GGA, RMC, GST, VTG per epoch
  // (Every line too: an epoch split by a pause is published, and counted, on
  // its first part, before its late sentences arrive.)
  const bool arrived = test::eventually([&] {
    return gps_driver.driver->status().published >= fixes_expected &&
           gps_driver.driver->status().gps.lines >= sr.nmea_sentences &&
           imu_driver.driver->status().stream.samples >= sr.imu_messages &&
           can_driver.driver->status().frames >= sr.can_frames &&
           gpio_driver.driver->status().tunnel_levels >= sr.gpio_levels;
  });
  // The e-stop's release is debounced: it completes 20 ms after the last level.
  test::eventually([&] { return gpio_driver.driver->status().estop == gpio::EstopState::released; });
  scheduler.stop();
  EXPECT_TRUE(arrived) << "not everything arrived within 30 s";

  const gps::GpsDriverStatus gs = gps_driver.driver->status();
  const imu::ImuDriverStatus is = imu_driver.driver->status();
  const can::CanDriverStatus cs = can_driver.driver->status();
  const gpio::GpioDriverStatus ps = gpio_driver.driver->status();
  std::printf("[ bench ] %.1f s at 2x: GPS %llu lines, %llu fixes; IMU %llu samples; CAN %llu frames, "
              "odometry %.2f m\n",
              report.recording_s, static_cast<unsigned long long>(gs.gps.lines),
              static_cast<unsigned long long>(gs.published), static_cast<unsigned long long>(is.stream.samples),
              static_cast<unsigned long long>(cs.frames), cs.odometry.distance);
  EXPECT_EQ(gs.gps.lines, sr.nmea_sentences);
  EXPECT_EQ(gs.gps.rejected_total(), 0u);
  // One fix per epoch, exactly, even when a pause split an epoch's burst
  // (its late sentences are dropped and counted, never a second fix).
  EXPECT_EQ(gs.published, fixes_expected);
  EXPECT_EQ(gs.gps.accepted, sr.nmea_sentences);
  std::printf("[ bench ] %llu late GPS sentences\n", static_cast<unsigned long long>(gs.gps.late));
  EXPECT_EQ(gs.health, gps::GpsHealth::fix);
  EXPECT_EQ(is.stream.samples, sr.imu_messages);
  EXPECT_EQ(is.stream.xbus.bad_checksum, 0u);
  // Nobody drains the IMU queue here: it fills to its capacity, then counts.
  EXPECT_EQ(is.queue_drops, sr.imu_messages - std::min<std::uint64_t>(sr.imu_messages, imu::kImuQueueCapacity));
  EXPECT_EQ(cs.frames, sr.can_frames);
  EXPECT_EQ(cs.malformed, 0u);
  EXPECT_EQ(cs.odometry_counters.updates, sr.can_frames / 2);  // speeds and ticks alternate
  // The distance the truth says the robot drove in those 6 s.
  std::ifstream truth(dir / "truth" / "trajectory.csv");
  std::string line, last;
  std::getline(truth, line);
  while (std::getline(truth, line)) last = line;
  double arc = 0.0;
  {
    // route_arc is the 13th column.
    std::size_t pos = 0;
    for (int c = 0; c < 12; ++c) pos = last.find(',', pos) + 1;
    arc = std::stod(last.substr(pos));
  }
  ASSERT_GT(arc, 3.0);
  EXPECT_NEAR(cs.odometry.distance, arc, 0.05 * arc);  // wheel scale errors and slip of a few per cent
  // The urban scenario's e-stop test at 3 s: the level at the start, one
  // press, a release with two bounces.
  EXPECT_EQ(sr.gpio_levels, 7u);
  EXPECT_EQ(ps.tunnel_levels, sr.gpio_levels);
  EXPECT_EQ(ps.malformed, 0u);
  EXPECT_EQ(ps.estop_counters.bounces, 2u);
  EXPECT_EQ(ps.estop_counters.engagements, 2u);  // unknown -> engaged at the first level, then the press
  EXPECT_EQ(ps.estop_counters.releases, 2u);
  EXPECT_EQ(ps.estop, gpio::EstopState::released);
  fs::remove_all(dir);
}
