// The GPIO driver: the e-stop debouncer on hand-made level sequences, the GPIO
// tunnel codec and the recording's GPIO log, the driver task on real loopback
// sockets (e-stop engages at once, a bouncing release is debounced, the
// heartbeat and status outputs follow), the missing-chip error, and no heap
// use once armed. This machine has no GPIO chip (no gpio-sim module), so the
// libgpiod path is exercised only for its failure.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include "trailnav/drivers/gpio/estop.hpp"
#include "trailnav/drivers/gpio/gpio_driver.hpp"
#include "trailnav/drivers/gpio/line_tunnel.hpp"
#include "trailnav/drivers/recording/recording.hpp"
#include "trailnav/drivers/udp/udp_sender.hpp"
#include "trailnav/runtime/alloc_guard.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "../support/no_allocations.hpp"

using namespace trailnav;
using namespace trailnav::gpio;

namespace {

constexpr Nanos ms(double v) { return static_cast<Nanos>(v * 1e6); }

void tick(GpioDriver& d, Nanos now) {
  TaskTick t;
  t.scheduled = t.started = now;
  d.run(t);
}

GpioDriverOptions tunnel_options() {
  GpioDriverOptions o;
  o.transport = GpioTransport::tunnel;
  o.tunnel = {0x7F000001u, 0};
  o.heartbeat_line = "HEARTBEAT";
  o.heartbeat_period = 0.1;
  o.status_line = "READY_LED";
  return o;
}

// Waits until the driver has taken in `n` e-stop levels (or a second passed).
void settle(GpioDriver& d, Nanos now, std::uint64_t n) {
  for (int k = 0; k < 200 && d.status().tunnel_levels < n; ++k) {
    tick(d, now);
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

}  // namespace

TEST(Estop, UnknownUntilALevelIsSeenAndThenReleasedOnlyAfterTheDebounce) {
  EstopDebouncer e(0.2);
  EXPECT_EQ(e.update(0), EstopState::unknown);
  EXPECT_TRUE(e.engaged());
  e.input(false, ms(10));
  EXPECT_EQ(e.update(ms(100)), EstopState::engaged);
  EXPECT_EQ(e.update(ms(209)), EstopState::engaged);
  EXPECT_EQ(e.update(ms(210)), EstopState::released);
  EXPECT_EQ(e.since(), ms(210));
  EXPECT_FALSE(e.engaged());
}

TEST(Estop, APressEngagesAtOnceAndABouncingReleaseWaitsForTheLastBounce) {
  EstopDebouncer e(0.05);
  e.input(false, 0);
  EXPECT_EQ(e.update(ms(60)), EstopState::released);
  e.input(true, ms(100));
  EXPECT_EQ(e.state(), EstopState::engaged);
  EXPECT_EQ(e.since(), ms(100));
  // Release with contact bounce.
  e.input(false, ms(500));
  e.input(true, ms(501));
  e.input(false, ms(502));
  e.input(true, ms(503));
  e.input(false, ms(504));
  EXPECT_EQ(e.update(ms(553)), EstopState::engaged);
  EXPECT_EQ(e.update(ms(554)), EstopState::released);
  EXPECT_EQ(e.counters().bounces, 2u);
  EXPECT_EQ(e.counters().engagements, 2u);
  EXPECT_EQ(e.counters().releases, 2u);
  // A press shorter than any poll period still engages.
  e.input(true, ms(700));
  e.input(false, ms(700));
  EXPECT_EQ(e.update(ms(701)), EstopState::engaged);
  EXPECT_EQ(e.update(ms(750)), EstopState::released);
}

TEST(Estop, ALostLineIsUnknownAndCountsAsEngaged) {
  EstopDebouncer e(0.0);
  e.input(false, 0);
  EXPECT_EQ(e.update(0), EstopState::released);
  e.lost();
  EXPECT_EQ(e.update(ms(1000)), EstopState::unknown);
  EXPECT_TRUE(e.engaged());
  EXPECT_EQ(e.counters().losses, 1u);
  e.input(false, ms(1001));
  EXPECT_EQ(e.update(ms(1001)), EstopState::released);
}

TEST(GpioTunnel, RoundTripsAndRejectsMalformedDatagrams) {
  const TunnelDatagram d = encode_tunnel("ESTOP", true, 1'782'036'000'123'456'789LL);
  ASSERT_EQ(d.size, kTunnelHeader + 5);
  LineLevel level;
  ASSERT_TRUE(decode_tunnel(d.view(), level));
  EXPECT_EQ(level.line(), "ESTOP");
  EXPECT_TRUE(level.value);
  EXPECT_EQ(level.time_ns, 1'782'036'000'123'456'789LL);
  EXPECT_EQ(encode_tunnel("E STOP", true, 0).size, 0u);
  EXPECT_EQ(encode_tunnel("", true, 0).size, 0u);
  EXPECT_EQ(encode_tunnel(std::string(32, 'A'), true, 0).size, 0u);
  auto bad = [&](std::size_t at, std::uint8_t value) {
    TunnelDatagram b = d;
    b.bytes[at] = value;
    return !decode_tunnel(b.view(), level);
  };
  EXPECT_TRUE(bad(0, 'X'));   // magic
  EXPECT_TRUE(bad(4, 2));     // version
  EXPECT_TRUE(bad(5, 2));     // value
  EXPECT_TRUE(bad(6, 6));     // name length does not match the size
  EXPECT_TRUE(bad(7, 1));     // reserved
  EXPECT_TRUE(bad(16, ' '));  // name character
  EXPECT_FALSE(decode_tunnel(std::span(d.bytes.data(), kTunnelHeader), level));
}

TEST(GpioRecording, LogLinesRoundTripAndBadLinesAreExplained) {
  std::int64_t t = 0;
  std::string name, error;
  bool value = false;
  ASSERT_TRUE(recording::parse_gpio_line("(1782036000.250000) ESTOP 1", t, name, value, error)) << error;
  EXPECT_EQ(t, 1'782'036'000'250'000'000LL);
  EXPECT_EQ(name, "ESTOP");
  EXPECT_TRUE(value);
  EXPECT_EQ(recording::format_gpio_line(t, name, false), "(1782036000.250000) ESTOP 0");
  EXPECT_FALSE(recording::parse_gpio_line("(1782036000.250000) ESTOP 2", t, name, value, error));
  EXPECT_NE(error.find("LINE 0"), std::string::npos);
  EXPECT_FALSE(recording::parse_gpio_line("(1782036000.250000) 1", t, name, value, error));
  EXPECT_FALSE(recording::parse_gpio_line("ESTOP 1", t, name, value, error));

  const std::string dir = ::testing::TempDir() + "gpio_recording_" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  {
    auto made = recording::RecordingWriter::create(dir, "gpio test");
    ASSERT_TRUE(made.writer) << made.error;
    const int s = made.writer->add_gpio_stream("gpio");
    ASSERT_TRUE(made.writer->write_gpio(s, 2'000'000'000, "ESTOP", false));
    ASSERT_TRUE(made.writer->write_gpio(s, 3'000'000'000, "ESTOP", true));
    EXPECT_FALSE(made.writer->write_gpio(s, 3'000'000'000, "E STOP", true));
    ASSERT_TRUE(made.writer->close());
  }
  std::ofstream(dir + "/gpio/gpio.log", std::ios::app) << "(4.000000) ESTOP maybe\n";
  auto opened = recording::RecordingReader::open(dir);
  ASSERT_TRUE(opened.reader) << opened.error;
  ASSERT_EQ(opened.reader->stream_index("gpio", recording::StreamKind::gpio), 0);
  auto a = opened.reader->next();
  ASSERT_TRUE(a);
  EXPECT_EQ(a->kind, recording::StreamKind::gpio);
  EXPECT_FALSE(a->gpio_value);
  auto b = opened.reader->next();
  ASSERT_TRUE(b);
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(b->payload.data()), b->payload.size()), "ESTOP");
  EXPECT_TRUE(b->gpio_value);
  EXPECT_EQ(b->time_ns, 3'000'000'000);
  EXPECT_FALSE(opened.reader->next());
  EXPECT_EQ(opened.reader->counters().bad_lines, 1u);
  EXPECT_NE(opened.reader->first_problem().find("gpio.log:3"), std::string::npos) << opened.reader->first_problem();
  std::filesystem::remove_all(dir);
}

TEST(GpioDriver, MissingChipIsExplainedWithTheChipsThereAre) {
  GpioDriverOptions o;
  o.chip = "gpiochip-robot-io";
  auto made = GpioDriver::create(o);
  ASSERT_FALSE(made.driver);
  EXPECT_NE(made.error.find("GPIO chip 'gpiochip-robot-io' not found"), std::string::npos) << made.error;
  EXPECT_NE(made.error.find("chips here:"), std::string::npos) << made.error;
}

TEST(GpioDriver, BadLineConfigurationIsRefusedBeforeAnythingOpens) {
  GpioDriverOptions o = tunnel_options();
  o.status_line = "HEARTBEAT";
  auto made = GpioDriver::create(o);
  EXPECT_NE(made.error.find("line 'HEARTBEAT' is configured for two functions"), std::string::npos) << made.error;
  o = tunnel_options();
  o.estop_line = "E STOP";
  EXPECT_NE(GpioDriver::create(o).error.find("'E STOP'"), std::string::npos);
  o = tunnel_options();
  o.heartbeat_period = 0.0;
  EXPECT_NE(GpioDriver::create(o).error.find("heartbeat_period"), std::string::npos);
}

TEST(GpioDriver, TunnelLevelsDriveTheEstopAndTheOutputsFollow) {
  auto outputs = udp::UdpReceiver::open([] {
    udp::ReceiverOptions u;
    u.bind = {0x7F000001u, 0};
    return u;
  }());
  ASSERT_TRUE(outputs.receiver) << outputs.error;
  GpioDriverOptions o = tunnel_options();
  o.estop_release_debounce = 0.05;
  o.tunnel_outputs = outputs.receiver->local();
  auto made = GpioDriver::create(o);
  ASSERT_TRUE(made.driver) << made.error;
  GpioDriver& d = *made.driver;
  auto sender = udp::UdpSender::open(d.tunnel_endpoint());
  ASSERT_TRUE(sender.sender);
  auto send = [&](const char* line, bool v) { sender.sender->send(encode_tunnel(line, v, 0).view()); };

  d.set_ready(true);
  tick(d, ms(0));
  EXPECT_EQ(d.status().estop, EstopState::unknown);
  EXPECT_FALSE(d.status().status_output);  // never ready while the e-stop is unknown
  const EstopReading* r = d.estop().try_read();
  ASSERT_NE(r, nullptr);
  EXPECT_EQ(r->state, EstopState::unknown);

  send("ESTOP", false);
  settle(d, ms(10), 1);
  EXPECT_EQ(d.status().estop, EstopState::engaged);
  tick(d, ms(70));
  EXPECT_EQ(d.status().estop, EstopState::released);
  EXPECT_TRUE(d.status().status_output);
  r = d.estop().try_read();
  ASSERT_NE(r, nullptr);
  EXPECT_EQ(r->state, EstopState::released);

  // Press: engaged on the first run that sees it; the status output drops.
  send("ESTOP", true);
  settle(d, ms(100), 2);
  EXPECT_EQ(d.status().estop, EstopState::engaged);
  EXPECT_FALSE(d.status().status_output);
  // Bouncing release, then quiet.
  send("ESTOP", false);
  send("ESTOP", true);
  send("ESTOP", false);
  settle(d, ms(200), 5);
  EXPECT_EQ(d.status().estop, EstopState::engaged);
  tick(d, ms(249));
  EXPECT_EQ(d.status().estop, EstopState::engaged);
  tick(d, ms(251));
  const GpioDriverStatus s = d.status();
  EXPECT_EQ(s.estop, EstopState::released);
  EXPECT_EQ(s.estop_counters.bounces, 1u);
  EXPECT_EQ(s.estop_counters.engagements, 2u);
  EXPECT_TRUE(s.status_output);

  // Levels for other lines and garbage are counted, not applied.
  send("DOOR", true);
  const std::uint8_t junk[3] = {1, 2, 3};
  sender.sender->send(junk);
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  tick(d, ms(260));
  EXPECT_EQ(d.status().unknown_lines, 1u);
  EXPECT_EQ(d.status().malformed, 1u);
  EXPECT_EQ(d.status().estop, EstopState::released);

  // Not ready: the status output goes off.
  d.set_ready(false);
  tick(d, ms(270));
  EXPECT_FALSE(d.status().status_output);

  // The mirrored outputs: heartbeat toggles every 100 ms of task time (ticks
  // at 0, 100, 200 ms), status on at 70 ms, off at 100, on at 251, off at 270.
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  int heartbeats = 0;
  std::vector<bool> status;
  for (const udp::Datagram& g : outputs.receiver->receive()) {
    LineLevel level;
    ASSERT_TRUE(decode_tunnel(g.payload, level));
    if (level.line() == "HEARTBEAT") ++heartbeats;
    if (level.line() == "READY_LED") status.push_back(level.value);
  }
  EXPECT_EQ(static_cast<std::uint64_t>(heartbeats), d.status().heartbeat_toggles);
  EXPECT_GE(heartbeats, 3);
  EXPECT_EQ(status, (std::vector<bool>{false, true, false, true, false}));
}

TEST(GpioDriver, RestsUntilTheHeartbeatOrTheReleaseIsDue) {
  GpioDriverOptions o = tunnel_options();  // heartbeat every 100 ms
  o.estop_release_debounce = 0.03;
  o.max_rest = 1.0;
  auto made = GpioDriver::create(o);
  ASSERT_TRUE(made.driver) << made.error;
  GpioDriver& d = *made.driver;
  EXPECT_GE(d.wake_fd(), 0);  // the tunnel's socket
  tick(d, ms(1000));
  EXPECT_EQ(d.rest(), ms(100));  // the next toggle
  auto sender = udp::UdpSender::open(d.tunnel_endpoint());
  ASSERT_TRUE(sender.sender);
  sender.sender->send(encode_tunnel("ESTOP", false, 0).view());
  settle(d, ms(1010), 1);
  EXPECT_EQ(d.status().estop, EstopState::engaged);
  EXPECT_EQ(d.rest(), ms(30));  // the release, 30 ms after the inactive level
  tick(d, ms(1040));
  EXPECT_EQ(d.status().estop, EstopState::released);
  EXPECT_EQ(d.rest(), ms(60));  // the toggle at 1.1 s again
  o.max_rest = 0.02;
  auto capped = GpioDriver::create(o);
  ASSERT_TRUE(capped.driver);
  tick(*capped.driver, ms(1000));
  EXPECT_EQ(capped.driver->rest(), ms(20));
  o.max_rest = 0.0;  // every period
  auto every = GpioDriver::create(o);
  ASSERT_TRUE(every.driver);
  tick(*every.driver, ms(1000));
  EXPECT_EQ(every.driver->rest(), 0);
}

// Under the scheduler on the real clock: between levels the task sleeps
// through its 200 Hz periods, and a level sent to the tunnel wakes it at
// once (its rests here are 5 s long).
TEST(GpioDriver, ALevelWakesTheRestingTaskAtOnce) {
  GpioDriverOptions o = tunnel_options();
  o.heartbeat_period = 5.0;
  o.max_rest = 5.0;
  o.estop_release_debounce = 0.02;
  auto made = GpioDriver::create(o);
  ASSERT_TRUE(made.driver) << made.error;
  GpioDriver& d = *made.driver;
  auto sender = udp::UdpSender::open(d.tunnel_endpoint());
  ASSERT_TRUE(sender.sender);
  MonotonicClock clock;
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  ASSERT_TRUE(scheduler.add({"gpio", TaskKind::periodic, 200.0, 2 * kNanosPerMilli, 0, -1}, d));
  ASSERT_TRUE(scheduler.start());
  const auto wait_for_state = [&](EstopState want) {
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(3);
    while (d.status().estop != want && std::chrono::steady_clock::now() < give_up) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return d.status().estop == want;
  };
  // Released 20 ms after the first inactive level (the debounce's wake-up).
  sender.sender->send(encode_tunnel("ESTOP", false, 0).view());
  ASSERT_TRUE(wait_for_state(EstopState::released));
  const std::uint64_t runs_before = scheduler.stats(0).runs;
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const std::uint64_t runs_quiet = scheduler.stats(0).runs - runs_before;
  EXPECT_LE(runs_quiet, 2u) << "60 periods of 5 ms passed: the task should have rested through them";
  // A press: engaged long before the 5 s rest would end.
  const auto pressed = std::chrono::steady_clock::now();
  sender.sender->send(encode_tunnel("ESTOP", true, 0).view());
  ASSERT_TRUE(wait_for_state(EstopState::engaged));
  EXPECT_LT(std::chrono::steady_clock::now() - pressed, std::chrono::seconds(3));
  const EstopReading* r = d.estop().try_read();
  ASSERT_NE(r, nullptr);
  EXPECT_EQ(r->state, EstopState::engaged);
  scheduler.stop();
  const TaskStats s = scheduler.stats(0);
  EXPECT_GT(s.rested_periods, 50u);
}

TEST(GpioDriver, ArmedDriverNeverTouchesTheHeap) {
  ASSERT_TRUE(alloc_guard::hook_installed());
  alloc_guard::set_fatal(false);
  alloc_guard::reset_counters();
  auto outputs = udp::UdpReceiver::open([] {
    udp::ReceiverOptions u;
    u.bind = {0x7F000001u, 0};
    return u;
  }());
  ASSERT_TRUE(outputs.receiver);
  GpioDriverOptions o = tunnel_options();
  o.estop_release_debounce = 0.01;
  o.heartbeat_period = 0.005;
  o.tunnel_outputs = outputs.receiver->local();
  auto made = GpioDriver::create(o);
  ASSERT_TRUE(made.driver);
  auto sender = udp::UdpSender::open(made.driver->tunnel_endpoint());
  ASSERT_TRUE(sender.sender);
  std::vector<TunnelDatagram> prepared;
  for (int k = 0; k < 40; ++k) prepared.push_back(encode_tunnel("ESTOP", k % 2 == 0, k));  // ends released
  MonotonicClock clock;
  Scheduler scheduler(clock, {RealtimePolicy::off, false});
  ASSERT_TRUE(scheduler.add({"gpio", TaskKind::periodic, 500.0, 2 * kNanosPerMilli, 0, -1}, *made.driver));
  made.driver->set_ready(true);
  ASSERT_TRUE(scheduler.start());
  ASSERT_TRUE(alloc_guard::arm());
  for (const TunnelDatagram& g : prepared) {
    sender.sender->send(g.view());
    std::this_thread::sleep_for(std::chrono::milliseconds(3));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  scheduler.stop();
  alloc_guard::disarm();
  const GpioDriverStatus s = made.driver->status();
  EXPECT_EQ(s.tunnel_levels, 40u);
  EXPECT_EQ(s.estop, EstopState::released);
  EXPECT_GT(s.heartbeat_toggles, 10u);
  test::expect_no_realtime_allocations();
}
