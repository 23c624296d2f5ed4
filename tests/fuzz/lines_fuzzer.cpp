// Fuzzes the text and datagram formats of bench recordings and sensors:
// candump log lines, serial and GPIO log lines, NMEA sentences and RMC times, CAN
// and GPIO tunnel datagrams, DBC databases, the recording manifest and the
// obstacle and terrain sections of a robot config, and CARMEN laser lines
// (FLASER). Round trips are checked
// where a format has one.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "check.hpp"

#include "replayer.hpp"
#include "trailnav/drivers/can/dbc.hpp"
#include "trailnav/drivers/gps/fix.hpp"
#include "trailnav/drivers/gpio/line_tunnel.hpp"
#include "trailnav/drivers/gps/nmea.hpp"
#include "trailnav/drivers/recording/recording.hpp"
#include "trailnav/drivers/velodyne/sensor_clock.hpp"
#include "trailnav/perception/obstacle_config.hpp"
#include "trailnav/perception/registration/carmen.hpp"
#include "trailnav/perception/terrain_config.hpp"
#include "trailnav/runtime/config.hpp"

using namespace trailnav;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  std::size_t start = 0;
  std::string interface, error;
  std::vector<std::uint8_t> bytes;
  while (start <= text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    const std::string_view line = text.substr(start, end - start);
    {
      // A CARMEN laser line: a scan or a message, never a crash; its points
      // finite and within the range limit.
      perception::registration::LaserScan2 scan;
      const std::string why = perception::registration::parse_flaser(line, scan, 1081);
      if (why.empty()) {
        // Its first field is FLASER (blanks before it are allowed).
        const std::size_t first = line.find_first_not_of(" \t\r");
        check(first != std::string_view::npos && line.substr(first, 6) == "FLASER");
        check(scan.ranges.size() >= 2 && scan.ranges.size() <= 1081);
        std::vector<perception::registration::Point> points;
        points.reserve(scan.ranges.size());
        const std::size_t no_room = perception::registration::scan_points(scan, 81.0f, 0.0f, points);
        check(no_room == 0 && points.size() <= scan.ranges.size());
        for (const auto& p : points) check(p.allFinite() && p.norm() < 81.1f);
      }
    }
    recording::CanFrame frame;
    if (recording::parse_candump_line(line, frame, interface, error)) {
      check(frame.length <= (frame.fd ? 64 : 8));
      // What we write, we read back the same.
      const std::string written = recording::format_candump_line(frame, interface);
      recording::CanFrame again;
      std::string interface2;
      check(recording::parse_candump_line(written, again, interface2, error));
      check(again.id == frame.id && again.length == frame.length && again.fd == frame.fd);
      check(again.time_ns / 1000 == frame.time_ns / 1000 || frame.time_ns < 0);
      const auto tunnel = can::encode_tunnel(frame);
      recording::CanFrame back;
      check(can::decode_tunnel(tunnel.view(), back));
      check(back.id == frame.id && back.length == frame.length && back.time_ns == frame.time_ns);
    }
    std::int64_t t = 0;
    if (recording::parse_serial_line(line, t, bytes, error)) check(!bytes.empty());
    std::string gpio_name;
    bool gpio_value = false;
    if (recording::parse_gpio_line(line, t, gpio_name, gpio_value, error)) {
      const auto tunnel = gpio::encode_tunnel(gpio_name, gpio_value, t);
      gpio::LineLevel level;
      check(gpio::decode_tunnel(tunnel.view(), level));
      check(level.line() == gpio_name && level.value == gpio_value && level.time_ns == t);
    }
    (void)velodyne::rmc_utc_ns(line);
    gps::NmeaSentence sentence;
    if (gps::parse_nmea(line, sentence) == gps::NmeaError::none) {
      if (sentence.type == gps::SentenceType::gga) {
        check(!(std::abs(sentence.gga.lat) > 90.0) && !(std::abs(sentence.gga.lon) > 180.0));
      }
      if (sentence.type == gps::SentenceType::rmc && sentence.rmc.year != 0) {
        check(sentence.rmc.year >= 1980 && sentence.rmc.year <= 2079 && sentence.rmc.month >= 1 && sentence.rmc.month <= 12);
      }
    }
    start = end + 1;
  }
  // The whole input as a GPS byte stream: every fix is a sane one.
  {
    gps::LineFramer framer;
    gps::FixAssembler assembler;
    gps::GpsFix fix;
    char json[512];
    auto check_fix = [&](const gps::GpsFix& f) {
      check(f.mode >= 0 && f.mode <= 3);
      if (f.has_fix()) check(std::abs(f.lat) <= 90.0 && std::abs(f.lon) <= 180.0);
      check(gps::write_tpv_json(f, json) > 0);
    };
    framer.feed({data, size}, [&](std::string_view line) {
      if (assembler.add_line(line, fix)) check_fix(fix);
    });
    if (assembler.flush(fix)) check_fix(fix);
    const gps::GpsCounters& c = assembler.counters();
    check(c.accepted + c.unsupported + c.rejected_total() == c.lines);
  }
  recording::CanFrame frame;
  (void)can::decode_tunnel({data, size}, frame);
  gpio::LineLevel level;
  if (gpio::decode_tunnel({data, size}, level)) {
    const auto again = gpio::encode_tunnel(level.line(), level.value, level.time_ns);
    check(again.size == size && std::equal(again.bytes.begin(), again.bytes.begin() + static_cast<std::ptrdiff_t>(size), data));
  }
  const auto dbc = can::parse_dbc(text, "fuzz.dbc");
  if (dbc.dbc) {
    for (const can::DbcMessage& m : dbc.dbc->messages) {
      check(m.size >= 0 && m.size <= 64);
      for (const can::DbcSignal& sig : m.signals) {
        std::uint8_t buf[64] = {};
        double v = 0;
        const auto used = std::span<std::uint8_t>(buf, static_cast<std::size_t>(m.size));
        if (can::decode_signal(sig, used, v) != can::SignalError::none || sig.length > 52) continue;
        const double value = sig.factor + sig.offset;
        if (can::encode_signal(sig, value, used) == can::SignalError::none) {
          double back = 0;
          check(can::decode_signal(sig, used, back) == can::SignalError::none);
          check(std::abs(back - value) <= std::abs(sig.factor) * 1e-6 + std::abs(value) * 1e-12);
        }
      }
    }
  }
  std::optional<ConfigNode> node;
  try {
    node = ConfigNode::parse(std::string(text), "fuzz.yaml");
    (void)node->has("streams");
  } catch (const ConfigError&) {
  }
  if (!node) return 0;
  try {
    // What the obstacle parser accepts is what the pipeline can run with.
    if (auto o = node->optional_map("obstacles")) {
      const perception::ObstacleConfig c = perception::parse_obstacle_config(*o);
      check(c.features.min_distance > 0.0f && c.features.neighbour_reach > 0.0f);
      check(c.features.min_range < c.features.max_range);
      check(c.map.size > 0 && c.map.resolution > 0.0 && c.map.measurement_min < c.map.measurement_max);
      if (c.features.self_box) {
        const auto& b = *c.features.self_box;
        check(b[0] < b[1] && b[2] < b[3] && b[4] < b[5]);
      }
    }
  } catch (const ConfigError&) {
  }
  try {
    if (auto t = node->optional_map("terrain")) (void)perception::parse_terrain_config(*t);
  } catch (const ConfigError&) {
  }
  return 0;
}
