// CAN frames encoded with real DBCs (Honda 0x1D0, Toyota 0xAA, and the
// simulated robot's) decode back exactly, and wheel odometry integrates them
// into the poses of known motions for differential and car-like platforms.
#include <gtest/gtest.h>

#include <cmath>

#include "test_data.hpp"
#include "trailnav/drivers/can/dbc.hpp"
#include "trailnav/drivers/can/frame.hpp"
#include "trailnav/drivers/can/wheel_odometry.hpp"

using namespace trailnav;
using namespace trailnav::can;

namespace {

Dbc load(const std::string& path) {
  auto r = load_dbc(path);
  EXPECT_TRUE(r.dbc) << r.error;
  return r.dbc ? *r.dbc : Dbc{};
}

Frame frame_of(const DbcMessage& m, std::int64_t t, std::initializer_list<std::pair<const char*, double>> values) {
  Frame f;
  f.time_ns = t;
  f.id = m.id | (m.extended ? kEffFlag : 0u);
  f.length = static_cast<std::uint8_t>(m.size);
  for (const auto& [name, v] : values) {
    const DbcSignal* s = m.signal(name);
    EXPECT_NE(s, nullptr) << name;
    if (s) {
      EXPECT_EQ(encode_signal(*s, v, std::span(f.data.data(), f.length)), SignalError::none) << name;
    }
  }
  return f;
}

double decoded(const DbcMessage& m, const Frame& f, const char* name) {
  double v = std::nan("");
  EXPECT_EQ(decode_signal(*m.signal(name), f.payload(), v), SignalError::none);
  return v;
}

}  // namespace

TEST(CanWheelSpeeds, HondaAndToyotaFramesDecodeBackExactly) {
  const Dbc honda = load(test::shared_data("can/dbc/opendbc__honda_common.dbc"));
  const DbcMessage* h = honda.message(0x1D0);
  ASSERT_NE(h, nullptr);
  const Frame hf = frame_of(*h, 0, {{"WHEEL_SPEED_FL", 12.34}, {"WHEEL_SPEED_FR", 12.35}, {"WHEEL_SPEED_RL", 0.0},
                                    {"WHEEL_SPEED_RR", 250.0}});
  EXPECT_DOUBLE_EQ(decoded(*h, hf, "WHEEL_SPEED_FL"), 12.34);
  EXPECT_DOUBLE_EQ(decoded(*h, hf, "WHEEL_SPEED_FR"), 12.35);
  EXPECT_DOUBLE_EQ(decoded(*h, hf, "WHEEL_SPEED_RL"), 0.0);
  EXPECT_DOUBLE_EQ(decoded(*h, hf, "WHEEL_SPEED_RR"), 250.0);
  // FL = 1234 raw in the 15 bits from bit 7 of byte 0 down: 0x09A4 << 1.
  EXPECT_EQ(hf.data[0], 0x09);
  EXPECT_EQ(hf.data[1] & 0xFE, 0xA4);

  const Dbc toyota = load(test::shared_data("can/dbc/opendbc__toyota_2017.dbc"));
  const DbcMessage* t = toyota.message(0xAA);
  ASSERT_NE(t, nullptr);
  EXPECT_EQ(t->name, "WHEEL_SPEEDS");
  // Offset -67.67 km/h: reversing is negative.
  const Frame tf = frame_of(*t, 0, {{"WHEEL_SPEED_FR", 36.0}, {"WHEEL_SPEED_FL", -5.5}, {"WHEEL_SPEED_RR", 0.0},
                                    {"WHEEL_SPEED_RL", 100.01}});
  EXPECT_DOUBLE_EQ(decoded(*t, tf, "WHEEL_SPEED_FR"), 36.0);
  EXPECT_DOUBLE_EQ(decoded(*t, tf, "WHEEL_SPEED_FL"), -5.5);
  EXPECT_DOUBLE_EQ(decoded(*t, tf, "WHEEL_SPEED_RR"), 0.0);
  EXPECT_DOUBLE_EQ(decoded(*t, tf, "WHEEL_SPEED_RL"), 100.01);
  // 0 km/h is raw 6767 = 0x1A6F in RR's 15 bits (bit 38 down): bytes 4..5.
  EXPECT_EQ((tf.data[4] & 0x7F) << 8 | tf.data[5], 6767);
  // A value outside the signal is refused, not wrapped.
  Frame bad = tf;
  EXPECT_EQ(encode_signal(*t->signal("WHEEL_SPEED_FR"), -100.0, std::span(bad.data.data(), 8)), SignalError::out_of_range);
}

TEST(CanWheelSpeeds, TunnelDatagramsCarryFramesUnchanged) {
  Frame f;
  f.time_ns = 1'700'000'000'123'456'789;
  f.id = 0x18FEF100u | kEffFlag;
  f.length = 8;
  for (std::uint8_t i = 0; i < 8; ++i) f.data[i] = static_cast<std::uint8_t>(0xA0 + i);
  const TunnelDatagram d = encode_tunnel(f);
  Frame back;
  ASSERT_TRUE(decode_tunnel(d.view(), back));
  EXPECT_EQ(back.time_ns, f.time_ns);
  EXPECT_EQ(back.id, f.id);
  EXPECT_EQ(back.identifier(), 0x18FEF100u);
  EXPECT_TRUE(back.extended());
  EXPECT_EQ(back.data, f.data);
  EXPECT_FALSE(decode_tunnel(d.view().subspan(0, 20), back));
}

TEST(WheelOdometry, ToyotaDrivesAQuarterCircleOnItsRearWheels) {
  const Dbc toyota = load(test::shared_data("can/dbc/opendbc__toyota_2017.dbc"));
  WheelOdometryOptions o;
  o.platform = Platform::ackermann;
  o.left = {"WHEEL_SPEEDS", "WHEEL_SPEED_RL"};
  o.right = {"WHEEL_SPEEDS", "WHEEL_SPEED_RR"};
  o.speed_scale = 1.0 / 3.6;
  o.track = 1.6;
  auto made = WheelOdometry::create(toyota, o);
  ASSERT_TRUE(made.odometry) << made.error;
  WheelOdometry& w = *made.odometry;
  // 10 m radius left turn at 5 m/s: the rear wheels at radii 9.2 and 10.8 m.
  const double v = 5.0, radius = 10.0, omega = v / radius;
  const double vl = omega * (radius - 0.8) * 3.6, vr = omega * (radius + 0.8) * 3.6;
  const DbcMessage& m = *toyota.message(0xAA);
  const double quarter = M_PI / 2 / omega;  // s
  const int frames = static_cast<int>(std::round(quarter * 80.0));
  for (int k = 0; k <= frames; ++k) {
    const auto t = static_cast<std::int64_t>(std::llround(k * 1e9 / 80.0));
    w.on_frame(frame_of(m, t, {{"WHEEL_SPEED_RL", std::round(vl * 100) / 100}, {"WHEEL_SPEED_RR", std::round(vr * 100) / 100},
                               {"WHEEL_SPEED_FL", 0.0}, {"WHEEL_SPEED_FR", 0.0}}));
  }
  const OdometryState& s = w.state();
  EXPECT_EQ(s.updates, static_cast<std::uint64_t>(frames + 1));
  // The end of a quarter circle from the origin heading east: (10, 10), heading north.
  EXPECT_NEAR(s.x, radius, 0.05);
  EXPECT_NEAR(s.y, radius, 0.05);
  EXPECT_NEAR(s.yaw, M_PI / 2, 0.005);
  EXPECT_NEAR(s.distance, radius * M_PI / 2, 0.05);
  EXPECT_NEAR(s.speed, v, 0.01);
  EXPECT_EQ(w.counters().decode_errors, 0u);
}

TEST(WheelOdometry, DifferentialRobotFromSpeedsAndFromWrappingTicks) {
  const Dbc robot = load("board/sim/trailnav-robot.dbc");
  const DbcMessage& speeds = *robot.message("WHEEL_SPEEDS");
  const DbcMessage& ticks = *robot.message("WHEEL_TICKS");
  WheelOdometryOptions o;
  o.left = {"WHEEL_SPEEDS", "SpeedLeft"};
  o.right = {"WHEEL_SPEEDS", "SpeedRight"};
  o.track = 0.55;
  auto from_speed = WheelOdometry::create(robot, o);
  ASSERT_TRUE(from_speed.odometry) << from_speed.error;
  o.input = WheelInput::ticks;
  o.left = {"WHEEL_TICKS", "TicksLeft"};
  o.right = {"WHEEL_TICKS", "TicksRight"};
  o.ticks_per_metre = 2000.0;
  auto from_ticks = WheelOdometry::create(robot, o);
  ASSERT_TRUE(from_ticks.odometry) << from_ticks.error;
  std::uint32_t ids[4];
  ASSERT_EQ(from_ticks.odometry->ids(ids, 4), 1u);
  EXPECT_EQ(ids[0], ticks.id);
  // Straight 1 m/s for 4 s, then turn on the spot at 0.5 rad/s for pi s.
  // The tick counters start near the top of their int32 range and wrap.
  double left = 2147483647.0 - 3000.0, right = left;
  for (int k = 0; k <= 50 * 8; ++k) {
    const double t = k / 50.0;
    const double vl = t < 4.0 ? 1.0 : -0.5 * 0.275, vr = t < 4.0 ? 1.0 : 0.5 * 0.275;
    const bool turning_done = t > 4.0 + M_PI;
    const double l = turning_done ? 0.0 : vl, r = turning_done ? 0.0 : vr;
    const auto ns = static_cast<std::int64_t>(std::llround(t * 1e9));
    from_speed.odometry->on_frame(frame_of(speeds, ns, {{"SpeedLeft", l}, {"SpeedRight", r}, {"Counter", k % 256}, {"Status", 0}}));
    auto wrap = [](double v) { return v > 2147483647.0 ? v - 4294967296.0 : v; };
    from_ticks.odometry->on_frame(frame_of(ticks, ns, {{"TicksLeft", std::round(wrap(left))}, {"TicksRight", std::round(wrap(right))}}));
    left += l / 50.0 * 2000.0;
    right += r / 50.0 * 2000.0;
  }
  for (const WheelOdometry* w : {from_speed.odometry.get(), from_ticks.odometry.get()}) {
    EXPECT_NEAR(w->state().x, 4.0, 0.03);
    EXPECT_NEAR(w->state().y, 0.0, 0.03);
    EXPECT_NEAR(std::abs(w->state().yaw), M_PI / 2 * 1.0, 0.05);  // 0.5 rad/s for pi s
    EXPECT_EQ(w->counters().implausible, 0u);
  }
  EXPECT_EQ(from_ticks.odometry->counters().gaps, 0u);
}

TEST(WheelOdometry, ConfigurationErrorsNameTheFileAndTheSignal) {
  const Dbc honda = load(test::shared_data("can/dbc/opendbc__honda_common.dbc"));
  WheelOdometryOptions o;
  o.left = {"WHEEL_SPEEDS", "WHEEL_SPEED_RL"};
  o.right = {"WHEEL_SPEEDZ", "WHEEL_SPEED_RR"};
  std::string e = WheelOdometry::create(honda, o).error;
  EXPECT_NE(e.find("opendbc__honda_common.dbc"), std::string::npos) << e;
  EXPECT_NE(e.find("'WHEEL_SPEEDZ'"), std::string::npos) << e;
  o.right = {"WHEEL_SPEEDS", "WHEEL_SPEED_XX"};
  e = WheelOdometry::create(honda, o).error;
  EXPECT_NE(e.find("no signal 'WHEEL_SPEED_XX'"), std::string::npos) << e;
  o.right = {"WHEEL_SPEEDS", "WHEEL_SPEED_RR"};
  o.steering = {"STEERING_SENSORS", "STEER_ANGLE"};
  e = WheelOdometry::create(honda, o).error;
  EXPECT_NE(e.find("ackermann"), std::string::npos) << e;
}
