// The IMU and CAN drivers' hot paths: Xsens bytes through the framer, the
// MTData2 decoder and the attitude filter; $TNIMU lines through the parser;
// CAN frames through the DBC decoder and the wheel odometry. Run from the
// repository root: build/release/bin/trailnav_imu_can_bench
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstring>
#include <stdexcept>
#include <vector>

#include "trailnav/drivers/can/wheel_odometry.hpp"
#include "trailnav/drivers/imu/attitude.hpp"
#include "trailnav/drivers/imu/line_format.hpp"
#include "trailnav/drivers/imu/xsens.hpp"

namespace trailnav {
namespace {

// 1000 MTData2 messages like an MTi's: counter, fine time, quaternion,
// acceleration, rate of turn, status (73 bytes each).
std::vector<std::uint8_t> xsens_stream() {
  std::vector<std::uint8_t> out;
  for (int k = 0; k < 1000; ++k) {
    std::vector<std::uint8_t> p;
    auto item = [&](std::uint16_t id, std::initializer_list<float> values) {
      p.push_back(static_cast<std::uint8_t>(id >> 8));
      p.push_back(static_cast<std::uint8_t>(id));
      p.push_back(static_cast<std::uint8_t>(values.size() * 4));
      for (float v : values) {
        std::uint32_t u = 0;
        std::memcpy(&u, &v, 4);
        for (int s = 24; s >= 0; s -= 8) p.push_back(static_cast<std::uint8_t>(u >> s));
      }
    };
    p.insert(p.end(), {0x10, 0x20, 2, static_cast<std::uint8_t>(k >> 8), static_cast<std::uint8_t>(k)});
    const auto fine = static_cast<std::uint32_t>(k * 100);
    p.insert(p.end(), {0x10, 0x60, 4, static_cast<std::uint8_t>(fine >> 24), static_cast<std::uint8_t>(fine >> 16),
                       static_cast<std::uint8_t>(fine >> 8), static_cast<std::uint8_t>(fine)});
    const float a = 0.001f * static_cast<float>(k);
    item(imu::xdi::kQuaternion, {std::cos(a), 0.0f, 0.0f, std::sin(a)});
    item(imu::xdi::kAcceleration, {0.1f, -0.2f, 9.8f});
    item(imu::xdi::kRateOfTurn, {0.001f, -0.002f, 0.2f});
    p.insert(p.end(), {0xE0, 0x20, 4, 0, 0, 0, 3});
    std::vector<std::uint8_t> m(p.size() + 8);
    m.resize(imu::encode_xbus(imu::mid::kMtData2, p, m));
    out.insert(out.end(), m.begin(), m.end());
  }
  return out;
}

// Items are samples.
void BM_XsensToAttitude(benchmark::State& state) {
  const std::vector<std::uint8_t> bytes = xsens_stream();
  imu::AttitudeOptions o;
  o.use_device_orientation = state.range(0) == 1;
  std::uint64_t samples = 0;
  for (auto _ : state) {
    imu::XbusFramer framer;
    imu::AttitudeFilter filter(o);
    framer.feed(bytes, [&](const imu::XbusMessage& m) {
      imu::ImuSample s;
      if (imu::decode_mtdata2(m.payload, s) == imu::XsensError::none) {
        benchmark::DoNotOptimize(filter.update(s));
        ++samples;
      }
    });
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(samples));
  state.SetLabel(o.use_device_orientation ? "device orientation" : "complementary filter");
}
BENCHMARK(BM_XsensToAttitude)->Arg(0)->Arg(1);

void BM_ImuLineParse(benchmark::State& state) {
  imu::ImuSample in;
  in.sample_time = 12.345678;
  in.rate_of_turn = {0.0012, -0.0021, 0.2003};
  in.acceleration = {0.101, -0.198, 9.807};
  in.orientation = {0.99, 0.01, -0.02, 0.1};
  in.fields = imu::kSampleTime | imu::kRateOfTurn | imu::kAcceleration | imu::kOrientation;
  char buffer[200];
  const std::string_view line(buffer, imu::format_imu_line(in, buffer, sizeof buffer));
  for (auto _ : state) {
    imu::ImuSample s;
    if (imu::parse_imu_line(line, s) != imu::LineError::none) throw std::runtime_error("bad benchmark line");
    benchmark::DoNotOptimize(s);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_ImuLineParse);

// Items are frames: decode both wheel signals and integrate.
void BM_CanWheelOdometry(benchmark::State& state) {
  auto loaded = can::load_dbc("board/sim/trailnav-robot.dbc");
  if (!loaded.dbc) throw std::runtime_error(loaded.error);
  can::WheelOdometryOptions o;
  o.left = {"WHEEL_SPEEDS", "SpeedLeft"};
  o.right = {"WHEEL_SPEEDS", "SpeedRight"};
  auto made = can::WheelOdometry::create(*loaded.dbc, o);
  if (!made.odometry) throw std::runtime_error(made.error);
  const can::DbcMessage& m = *loaded.dbc->message("WHEEL_SPEEDS");
  can::Frame f;
  f.id = m.id;
  f.length = 8;
  can::encode_signal(*m.signal("SpeedLeft"), 1.2, std::span(f.data.data(), 8));
  can::encode_signal(*m.signal("SpeedRight"), 1.3, std::span(f.data.data(), 8));
  for (auto _ : state) {
    f.time_ns += 20'000'000;
    benchmark::DoNotOptimize(made.odometry->on_frame(f));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_CanWheelOdometry);

}  // namespace
}  // namespace trailnav

BENCHMARK_MAIN();
