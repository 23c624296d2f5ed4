// The CAN driver task on real sockets: frames through trailnav's UDP tunnel
// on loopback (the real NMEA 2000 candump log among them), odometry out,
// error frames reported, SocketCAN's failure explained, and no heap use
// once armed.
#include <gtest/gtest.h>

#include <linux/can.h>
#include <linux/can/error.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <thread>

#include "test_data.hpp"
#include "trailnav/drivers/can/can_driver.hpp"
#include "trailnav/drivers/recording/recording.hpp"
#include "trailnav/drivers/udp/udp_sender.hpp"
#include "trailnav/runtime/alloc_guard.hpp"
#include "../support/no_allocations.hpp"

using namespace trailnav;
using namespace trailnav::can;

namespace {

Dbc robot_dbc() {
  auto r = load_dbc("board/sim/trailnav-robot.dbc");
  EXPECT_TRUE(r.dbc) << r.error;
  return *r.dbc;
}

CanDriverOptions robot_options() {
  CanDriverOptions o;
  o.tunnel = {0x7F000001u, 0};  // a port of the kernel's choosing
  o.odometry.left = {"WHEEL_SPEEDS", "SpeedLeft"};
  o.odometry.right = {"WHEEL_SPEEDS", "SpeedRight"};
  o.odometry.track = 0.55;
  return o;
}

Frame speeds(const Dbc& dbc, double left, double right) {
  const DbcMessage& m = *dbc.message("WHEEL_SPEEDS");
  Frame f;
  f.id = m.id;
  f.length = 8;
  const std::span<std::uint8_t> d(f.data.data(), 8);
  EXPECT_EQ(encode_signal(*m.signal("SpeedLeft"), left, d), SignalError::none);
  EXPECT_EQ(encode_signal(*m.signal("SpeedRight"), right, d), SignalError::none);
  return f;
}

void tick(CanDriver& d, Nanos now) {
  TaskTick t;
  t.scheduled = t.started = now;
  d.run(t);
}

}  // namespace

TEST(CanDriver, TunnelFramesBecomeOdometryAndErrorFramesAreReported) {
  const Dbc dbc = robot_dbc();
  auto made = CanDriver::create(dbc, robot_options());
  ASSERT_TRUE(made.driver) << made.error;
  CanDriver& d = *made.driver;
  auto sender = udp::UdpSender::open(d.tunnel_endpoint());
  ASSERT_TRUE(sender.sender) << sender.error;
  Nanos now = kNanosPerSecond;
  tick(d, now);
  EXPECT_EQ(d.status().health, CanHealth::no_data);
  // 1 m/s straight on, 50 frames 20 ms apart (the driver times them on arrival).
  for (int k = 0; k < 50; ++k) {
    ASSERT_TRUE(sender.sender->send(encode_tunnel(speeds(dbc, 1.0, 1.0)).view()));
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    tick(d, now += 20 * kNanosPerMilli);
  }
  CanDriverStatus s = d.status();
  EXPECT_EQ(s.frames, 50u);
  EXPECT_EQ(s.odometry_counters.updates, 50u);
  EXPECT_EQ(s.health, CanHealth::ok);
  // 49 intervals of about 20 ms (longer on a loaded machine).
  EXPECT_GT(s.odometry.x, 0.95);
  EXPECT_LT(s.odometry.x, 1.5);
  EXPECT_NEAR(s.odometry.speed, 1.0, 1e-9);
  int queued = 0;
  OdometryState o;
  while (d.readings().try_pop(o)) ++queued;
  EXPECT_EQ(queued, 50);
  // Garbage and a bus-off error frame.
  const std::uint8_t junk[] = {1, 2, 3};
  sender.sender->send(junk);
  Frame err;
  err.id = kErrFlag | CAN_ERR_BUSOFF;
  err.length = 8;
  sender.sender->send(encode_tunnel(err).view());
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  tick(d, now += 10 * kNanosPerMilli);
  s = d.status();
  EXPECT_EQ(s.malformed, 1u);
  EXPECT_EQ(s.error_frames, 1u);
  EXPECT_EQ(s.bus_off, 1u);
  EXPECT_EQ(s.health, CanHealth::bus_error);
  tick(d, now += 3 * kNanosPerSecond);
  EXPECT_EQ(d.status().health, CanHealth::no_data);
}

TEST(CanDriver, RealCandumpLogPassesThroughTheTunnelWithoutALoss) {
  std::ifstream in(test::shared_data("can/gpsd_nmea2000_garmin_boat_candump.log"));
  ASSERT_TRUE(in);
  std::vector<Frame> frames;
  std::string line, interface, error;
  std::uint64_t parse_errors = 0;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    Frame f;
    if (recording::parse_candump_line(line, f, interface, error)) {
      frames.push_back(f);
    } else {
      ++parse_errors;
    }
  }
  EXPECT_EQ(parse_errors, 0u);
  ASSERT_EQ(frames.size(), 10495u);
  const Dbc dbc = robot_dbc();
  auto made = CanDriver::create(dbc, robot_options());
  ASSERT_TRUE(made.driver) << made.error;
  auto sender = udp::UdpSender::open(made.driver->tunnel_endpoint());
  ASSERT_TRUE(sender.sender);
  Nanos now = kNanosPerSecond;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    ASSERT_TRUE(sender.sender->send(encode_tunnel(frames[i]).view()));
    if (i % 100 == 99) {
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
      tick(*made.driver, now += kNanosPerMilli);
    }
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  for (int k = 0; k < 5; ++k) tick(*made.driver, now += kNanosPerMilli);
  const CanDriverStatus s = made.driver->status();
  EXPECT_EQ(s.frames, 10495u);
  EXPECT_EQ(s.malformed, 0u);
  EXPECT_EQ(s.kernel_drops, 0u);
  EXPECT_EQ(s.error_frames, 0u);
  EXPECT_EQ(s.odometry_counters.frames, 0u);  // a boat's NMEA 2000 bus carries no wheel speeds
}

TEST(CanDriver, SocketCanFailureIsExplained) {
  const Dbc dbc = robot_dbc();
  CanDriverOptions o = robot_options();
  o.transport = CanTransport::socketcan;
  o.interface = "tnnocan0";
  auto made = CanDriver::create(dbc, o);
  ASSERT_TRUE(made.driver) << made.error;
  tick(*made.driver, kNanosPerSecond);
  const CanDriverStatus s = made.driver->status();
  EXPECT_EQ(s.health, CanHealth::no_link);
  EXPECT_EQ(s.open_failures, 1u);
  const std::string e = s.last_error.data();
  const int probe = socket(PF_CAN, SOCK_RAW, CAN_RAW);
  if (probe < 0) {
    EXPECT_NE(e.find("SocketCAN is not available"), std::string::npos) << e;
    EXPECT_NE(e.find("tunnel"), std::string::npos) << e;
  } else {
    ::close(probe);
    EXPECT_NE(e.find("no CAN interface tnnocan0"), std::string::npos) << e;
  }
  o.interface = "";
  EXPECT_NE(CanDriver::create(dbc, o).error.find("interface name"), std::string::npos);
  o = robot_options();
  o.odometry.left = {"WHEEL_SPEEDS", "Nope"};
  EXPECT_NE(CanDriver::create(dbc, o).error.find("no signal 'Nope'"), std::string::npos);
}

TEST(CanDriver, ArmedDriverNeverTouchesTheHeap) {
  ASSERT_TRUE(alloc_guard::hook_installed());
  alloc_guard::set_fatal(false);
  alloc_guard::reset_counters();
  const Dbc dbc = robot_dbc();
  auto made = CanDriver::create(dbc, robot_options());
  ASSERT_TRUE(made.driver);
  auto sender = udp::UdpSender::open(made.driver->tunnel_endpoint());
  ASSERT_TRUE(sender.sender);
  std::vector<TunnelDatagram> prepared;
  for (int k = 0; k < 200; ++k) prepared.push_back(encode_tunnel(speeds(dbc, 0.5 + k * 0.001, 0.6)));
  Frame err;
  err.id = kErrFlag | CAN_ERR_CRTL;
  err.length = 8;
  err.data[1] = CAN_ERR_CRTL_RX_PASSIVE;
  prepared.push_back(encode_tunnel(err));
  MonotonicClock clock;
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  ASSERT_TRUE(scheduler.add({"can", TaskKind::periodic, 500.0, 2 * kNanosPerMilli, 0, -1}, *made.driver));
  ASSERT_TRUE(scheduler.start());
  ASSERT_TRUE(alloc_guard::arm());
  for (const TunnelDatagram& d : prepared) {
    sender.sender->send(d.view());
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  scheduler.stop();
  alloc_guard::disarm();
  const CanDriverStatus s = made.driver->status();
  EXPECT_EQ(s.frames, 201u);
  EXPECT_EQ(s.error_passive, 1u);
  EXPECT_EQ(s.odometry_counters.updates, 200u);
  test::expect_no_realtime_allocations();
}
