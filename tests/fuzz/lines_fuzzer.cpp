// Fuzzes the text and datagram formats of bench recordings: candump log
// lines, serial log lines, NMEA RMC times, CAN tunnel datagrams and the
// recording manifest. Round trips are checked where a format has one.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <vector>

#include "check.hpp"

#include "replayer.hpp"
#include "trailnav/drivers/recording/recording.hpp"
#include "trailnav/drivers/velodyne/sensor_clock.hpp"
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
      const auto tunnel = replay::encode_can_tunnel(frame);
      recording::CanFrame back;
      check(replay::decode_can_tunnel(tunnel.view(), back));
      check(back.id == frame.id && back.length == frame.length && back.time_ns == frame.time_ns);
    }
    std::int64_t t = 0;
    if (recording::parse_serial_line(line, t, bytes, error)) check(!bytes.empty());
    (void)velodyne::rmc_utc_ns(line);
    start = end + 1;
  }
  recording::CanFrame frame;
  (void)replay::decode_can_tunnel({data, size}, frame);
  try {
    const ConfigNode node = ConfigNode::parse(std::string(text), "fuzz.yaml");
    (void)node.has("streams");
  } catch (const ConfigError&) {
  }
  return 0;
}
