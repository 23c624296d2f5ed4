#include <gtest/gtest.h>

#include <ctime>
#include <random>
#include <string>
#include <vector>

#include "test_data.hpp"
#include "trailnav/drivers/capture/capture_reader.hpp"
#include "trailnav/drivers/velodyne/sensor_clock.hpp"

namespace trailnav::velodyne {
namespace {

std::int64_t utc_ns(int year, int month, int day, int hour, int minute, int second) {
  std::tm tm{};
  tm.tm_year = year - 1900;
  tm.tm_mon = month - 1;
  tm.tm_mday = day;
  tm.tm_hour = hour;
  tm.tm_min = minute;
  tm.tm_sec = second;
  return static_cast<std::int64_t>(timegm(&tm)) * 1'000'000'000;
}

std::string with_checksum(const std::string& body) {
  unsigned sum = 0;
  for (char c : body) sum ^= static_cast<unsigned char>(c);
  char tail[8];
  std::snprintf(tail, sizeof tail, "*%02X", sum);
  return "$" + body + tail;
}

TEST(SensorClock, RmcTimeIsReadWithItsDate) {
  const auto t = rmc_utc_ns("$GPRMC,081802.00,A,3649.7478558,N,00224.4542928,W,0.034,212.5,210116,0.0,E,A*2E");
  ASSERT_TRUE(t);
  EXPECT_EQ(*t, utc_ns(2016, 1, 21, 8, 18, 2));
  const auto fraction = rmc_utc_ns(with_checksum("GNRMC,235959.750,A,4807.038,N,01131.000,E,022.4,084.4,311299,,,A"));
  ASSERT_TRUE(fraction);
  EXPECT_EQ(*fraction, utc_ns(1999, 12, 31, 23, 59, 59) + 750'000'000);
  // Checksum, date and time are all checked.
  EXPECT_FALSE(rmc_utc_ns("$GPRMC,081802.00,A,3649.7478558,N,00224.4542928,W,0.034,212.5,210116,0.0,E,A*2F"));
  EXPECT_FALSE(rmc_utc_ns(with_checksum("GPRMC,081802.00,A,,,,,,,,,")));
  EXPECT_FALSE(rmc_utc_ns(with_checksum("GPRMC,251802.00,A,,,,,,,210116,,")));
  EXPECT_FALSE(rmc_utc_ns(with_checksum("GPRMC,081802.00,A,,,,,,,211316,,")));
  EXPECT_FALSE(rmc_utc_ns(with_checksum("GPGGA,081802.00,3649.7,N,00224.4,W,1,08,0.9,545.4,M,46.9,M,,")));
  EXPECT_FALSE(rmc_utc_ns(""));
}

TEST(SensorClock, GpsTimeContinuesAcrossTheTopOfTheHour) {
  SensorClock clock;
  // The sensor's counter is UTC's position in the hour; the receiver's last
  // sentence says 10:59:59.
  const std::string sentence = with_checksum("GPRMC,105959.00,A,4807.038,N,01131.000,E,0.0,0.0,210126,,,A");
  PositionPacket position;
  position.timestamp_us = 3'599'400'000;  // 10:59:59.4
  position.pps = PpsStatus::locked;
  position.nmea = sentence;
  clock.on_position_packet(position);
  ASSERT_EQ(clock.source(), TimeSource::gps);

  const std::int64_t hour = utc_ns(2026, 1, 21, 10, 0, 0);
  std::int64_t previous = 0;
  // Packets every 1327 us from 10:59:59.5 to 11:00:00.5; the host clock is
  // a minute off and must not matter.
  for (std::int64_t us = 3'599'500'000; us < 3'600'500'000; us += 1327) {
    const auto counter = static_cast<std::uint32_t>(us % 3'600'000'000);
    const std::int64_t t = clock.resolve(counter, hour + us * 1000 + 60'000'000'000);
    EXPECT_EQ(t, hour + us * 1000);
    EXPECT_GT(t, previous);
    previous = t;
  }
  EXPECT_EQ(clock.hour_rollovers(), 1u);
  EXPECT_EQ(clock.clamped(), 0u);
}

TEST(SensorClock, GpsTimeNeedsPpsLock) {
  SensorClock clock;
  const std::string sentence = with_checksum("GPRMC,105959.00,A,4807.038,N,01131.000,E,0.0,0.0,210126,,,A");
  PositionPacket position;
  position.timestamp_us = 3'599'400'000;
  position.pps = PpsStatus::synchronizing;
  position.nmea = sentence;
  clock.on_position_packet(position);
  EXPECT_EQ(clock.source(), TimeSource::none);
  clock.resolve(3'599'500'000, 1'000'000'000'000);
  EXPECT_EQ(clock.source(), TimeSource::host);
}

TEST(SensorClock, HostTimeFollowsTheSmallestDelayAcrossTheTopOfTheHour) {
  SensorClockOptions options;
  options.offset_window_ns = 1'000'000'000;
  SensorClock clock(options);
  std::mt19937 rng(7);
  std::uniform_int_distribution<std::int64_t> delay_us(40, 400);
  // A free-running sensor counter 20 s before its hour wraps; the host
  // clock is 1234.5 s ahead of it, and each packet arrives 40..400 us late.
  const std::int64_t host_offset_ns = 1'234'500'000'000 + 1'700'000'000'000'000'000;
  std::int64_t previous = 0;
  int checked = 0;
  for (std::int64_t us = 3'580'000'000; us < 3'640'000'000; us += 1327) {
    const auto counter = static_cast<std::uint32_t>(us % 3'600'000'000);
    const std::int64_t truth = us * 1000 + host_offset_ns;
    const std::int64_t t = clock.resolve(counter, truth + delay_us(rng) * 1000);
    ASSERT_GE(t, previous);
    previous = t;
    if (us > 3'581'000'000) {  // after the first window
      EXPECT_GE(t - truth, 40'000);
      EXPECT_LE(t - truth, 60'000) << "the window minimum is close to the smallest delay";
      ++checked;
    }
  }
  EXPECT_GT(checked, 40000);
  EXPECT_EQ(clock.hour_rollovers(), 1u);
  EXPECT_EQ(clock.source(), TimeSource::host);
}

// A packet a few milliseconds late keeps its place (held, times stay
// monotonic); a counter set back by seconds is a step of the sensor's clock
// (a re-lock), and times follow it down instead of standing still for as
// long as the step (found by trailnav replay --fault lidar:clock-step=-2.5).
TEST(SensorClock, LatePacketsAreHeldButAClockSetBackIsFollowed) {
  SensorClock clock;
  const std::int64_t host = 1'700'000'000'000'000'000;
  std::int64_t t = 0;
  for (std::int64_t us = 1'000'000; us < 2'000'000; us += 1327) {
    t = clock.resolve(static_cast<std::uint32_t>(us), host + us * 1000);
  }
  const std::int64_t before = t;
  // 3 ms late: held at the newest time.
  EXPECT_EQ(clock.resolve(1'997'000, host + 2'000'000'000), before);
  EXPECT_EQ(clock.clamped(), 1u);
  EXPECT_EQ(clock.steps_back(), 0u);
  // Set back by 2.5 s: followed.
  const std::int64_t after = clock.resolve(static_cast<std::uint32_t>(2'000'000 - 2'500'000 + 3'600'000'000LL), host + 2'001'000'000);
  EXPECT_EQ(clock.steps_back(), 1u);
  EXPECT_NEAR(static_cast<double>(after - before), -2.5e9, 5e6);
  // And runs on from there.
  const std::int64_t next = clock.resolve(static_cast<std::uint32_t>(2'001'327 - 2'500'000 + 3'600'000'000LL), host + 2'002'000'000);
  EXPECT_EQ(next - after, 1'327'000);
}

TEST(SensorClock, HostTimeFollowsClockDrift) {
  SensorClockOptions options;
  options.offset_window_ns = 1'000'000'000;
  SensorClock clock(options);
  // The sensor's crystal runs 50 ppm fast; delays are a constant 100 us.
  std::int64_t worst = 0;
  for (std::int64_t us = 0; us < 60'000'000; us += 1327) {
    const std::int64_t host = static_cast<std::int64_t>(static_cast<double>(us) * 1000.0 / 1.00005) + 100'000;
    const std::int64_t t = clock.resolve(static_cast<std::uint32_t>(us), host);
    if (us > 2'000'000) worst = std::max(worst, std::abs(t - host));
  }
  // One window of drift (50 us) plus the delay.
  EXPECT_LE(worst, 160'000);
}

TEST(SensorClock, RealVlp16CaptureTakesItsTimeFromGprmc) {
  auto opened = capture::open_capture(test::shared_data("velodyne/mrpt_sample_velodyne_vlp16_gps.pcap"));
  ASSERT_TRUE(opened.reader) << opened.error;
  SensorClock clock;
  std::int64_t first = 0, last = 0, previous = 0;
  std::int64_t rmc = 0;
  int data = 0;
  while (auto d = opened.reader->next()) {
    if (d->payload.size() == kPositionPacketSize) {
      PositionPacket p;
      ASSERT_EQ(decode_position_packet(d->payload, p), PositionError::none);
      if (auto t = rmc_utc_ns(p.nmea)) rmc = *t;
      clock.on_position_packet(p);
      continue;
    }
    if (d->payload.size() != kDataPacketSize) continue;
    const std::int64_t t = clock.resolve(read_u32(d->payload.data() + kTimestampOffset), d->time_ns);
    if (clock.source() != TimeSource::gps) continue;
    ++data;
    if (first == 0) first = t;
    last = t;
    EXPECT_GE(t, previous);
    previous = t;
  }
  ASSERT_GT(data, 100);
  ASSERT_NE(rmc, 0);
  EXPECT_EQ(clock.source(), TimeSource::gps);
  // The capture is 2016-01-21 08:18:02 UTC (its $GPRMC); the data follow it within seconds.
  EXPECT_EQ(rmc, utc_ns(2016, 1, 21, 8, 18, 2));
  EXPECT_LT(std::abs(first - rmc), 3'000'000'000);
  EXPECT_LT(std::abs(last - rmc), 3'000'000'000);
  EXPECT_GT(last - first, 300'000'000);
  // The first data packet came before any position packet: host time, then one step to GPS time.
  EXPECT_EQ(clock.steps(), 1u);
  EXPECT_EQ(clock.clamped(), 0u);
}

}  // namespace
}  // namespace trailnav::velodyne
