// Bench recordings: everything the robot's sensors sent, with timestamps, in
// one directory (format in docs/recording.md):
//
//   manifest.yaml       what the streams are
//   udp.pcap            UDP traffic: lidar data and position packets, NMEA over UDP, ...
//   can.log             CAN frames, can-utils candump log format
//   serial/<name>.log   serial byte streams: "(seconds.micros) HEXBYTES" per read
//   gpio/<name>.log     GPIO line levels: "(seconds.micros) LINE 0|1" per change
//   images/<name>.log   camera frames: "(seconds.micros) SEQUENCE FILE" per frame,
//   images/<name>/      the frames, grey PNG files
//
// A bare pcap, pcapng or raw Velodyne file is read as a recording of its UDP
// streams alone. Offline tooling: allocates freely.
#pragma once

#include <array>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "trailnav/drivers/can/frame.hpp"
#include "trailnav/runtime/status.hpp"

namespace trailnav::recording {

enum class StreamKind : std::uint8_t { udp, can, serial, gpio, image };
const char* stream_kind_name(StreamKind kind) noexcept;

struct StreamInfo {
  std::string name;
  StreamKind kind = StreamKind::udp;
  std::string file;        // relative to the recording directory
  std::uint16_t port = 0;  // udp: destination port of the stream's datagrams
  std::string interface;   // can: bus name in the log (can0, ...)
  int baud = 0;            // serial: the port's baud rate (informational)
  std::string description;
};

struct Manifest {
  int version = 1;
  std::string description;
  std::vector<StreamInfo> streams;
};

inline constexpr const char* kManifestName = "manifest.yaml";

// Errors name the file, line and key.
struct ManifestResult {
  std::optional<Manifest> manifest;
  std::string error;
};
ManifestResult load_manifest(const std::string& path);
Status write_manifest(const std::string& path, const Manifest& manifest);

// CAN frames as SocketCAN encodes them (see trailnav/drivers/can/frame.hpp).
using CanFrame = can::Frame;
inline constexpr std::uint32_t kCanEffFlag = can::kEffFlag;
inline constexpr std::uint32_t kCanRtrFlag = can::kRtrFlag;
inline constexpr std::uint32_t kCanErrFlag = can::kErrFlag;

// One line of a candump log, "(1436509052.249713) can0 123#11223344". False
// with `error` set when malformed.
bool parse_candump_line(std::string_view line, CanFrame& frame, std::string& interface, std::string& error);
std::string format_candump_line(const CanFrame& frame, std::string_view interface);

// One line of a serial log, "(1436509052.249713) 2447504747412C...".
bool parse_serial_line(std::string_view line, std::int64_t& time_ns, std::vector<std::uint8_t>& bytes, std::string& error);
std::string format_serial_line(std::int64_t time_ns, std::span<const std::uint8_t> bytes);

// One line of a GPIO log, "(1436509052.249713) ESTOP 1": the line's logical
// level (1: active) from that time on. Names as in trailnav/drivers/gpio/line_tunnel.hpp.
bool parse_gpio_line(std::string_view line, std::int64_t& time_ns, std::string& name, bool& value, std::string& error);
std::string format_gpio_line(std::int64_t time_ns, std::string_view name, bool value);

// One line of an image log, "(1436509052.249713) 42 000042.png": the frame's
// time (its camera timestamp), the camera's sequence number and the PNG file
// in the stream's directory (images/<name>/; a plain name, no directories).
bool parse_image_line(std::string_view line, std::int64_t& time_ns, std::uint32_t& sequence, std::string& file,
                      std::string& error);
std::string format_image_line(std::int64_t time_ns, std::uint32_t sequence, std::string_view file);

// One record of a recording, in time order over all streams.
struct Event {
  std::int64_t time_ns = 0;
  int stream = 0;  // index into streams()
  StreamKind kind = StreamKind::udp;
  std::span<const std::uint8_t> payload;  // udp and serial: the bytes; gpio: the line name; image: the grey pixels;
                                          // valid until the next call
  std::uint32_t source_ip = 0;            // udp
  std::uint16_t source_port = 0;          // udp
  const CanFrame* can = nullptr;          // can
  bool gpio_value = false;                // gpio: the line's level
  int image_width = 0, image_height = 0;  // image
  std::uint32_t image_sequence = 0;       // image: the camera's frame number
};

struct ReaderCounters {
  std::uint64_t events = 0;
  std::uint64_t unassigned_udp = 0;  // datagrams to a port no stream claims: skipped
  std::uint64_t bad_lines = 0;       // unparsable CAN, serial, GPIO or image log lines, unreadable frames: skipped
};

class RecordingReader {
 public:
  struct Opened;
  // A recording directory, or a pcap/pcapng/raw file (streams from its ports:
  // 2368 "lidar", 8308 "lidar-position", others "udp-<port>").
  static Opened open(const std::string& path);
  ~RecordingReader();

  const std::vector<StreamInfo>& streams() const noexcept { return streams_; }
  // The index of the stream of this name and kind; -1 when there is none.
  int stream_index(std::string_view name, StreamKind kind) const noexcept;
  // The next event in time order; nullopt at the end.
  std::optional<Event> next();
  const ReaderCounters& counters() const noexcept { return counters_; }
  // The first bad line's description (file:line: what), if any.
  const std::string& first_problem() const noexcept { return first_problem_; }
  std::uint64_t position() const noexcept;  // bytes read, for progress bars
  std::uint64_t size() const noexcept;
  const std::string& path() const noexcept { return path_; }

 private:
  RecordingReader() = default;
  struct Source;
  struct UdpSource;
  struct LineSource;
  struct CanSource;
  struct SerialSource;
  struct GpioSource;
  struct ImageSource;

  void note_problem(const std::string& problem);

  std::string path_;
  std::vector<StreamInfo> streams_;
  std::vector<std::unique_ptr<Source>> sources_;
  Event current_;
  std::vector<std::uint8_t> current_bytes_;
  CanFrame current_can_;
  ReaderCounters counters_;
  std::string first_problem_;
};

struct RecordingReader::Opened {
  std::unique_ptr<RecordingReader> reader;
  std::string error;
};

// Writes a recording directory; the manifest is written by close().
class RecordingWriter {
 public:
  struct Created;
  static Created create(const std::string& directory, const std::string& description);
  ~RecordingWriter();

  // Streams; returns the stream index for the write calls.
  int add_udp_stream(const std::string& name, std::uint16_t port, const std::string& description = "");
  int add_can_stream(const std::string& name, const std::string& interface, const std::string& description = "");
  int add_serial_stream(const std::string& name, int baud, const std::string& description = "");
  int add_gpio_stream(const std::string& name, const std::string& description = "");
  // Camera frames: images/<name>.log and the PNG files in images/<name>/.
  int add_image_stream(const std::string& name, const std::string& description = "");

  // A UDP datagram from source to 127.0.0.1:<the stream's port>.
  Status write_udp(int stream, std::int64_t time_ns, std::span<const std::uint8_t> payload,
                   std::uint32_t source_ip = 0xC0A801C9u, std::uint16_t source_port = 2368);
  Status write_can(int stream, const CanFrame& frame);
  Status write_serial(int stream, std::int64_t time_ns, std::span<const std::uint8_t> bytes);
  Status write_gpio(int stream, std::int64_t time_ns, std::string_view line, bool value);
  // A grey frame (width x height), stamped with the camera's time.
  Status write_image(int stream, std::int64_t time_ns, std::uint32_t sequence, std::span<const std::uint8_t> grey,
                     int width, int height);
  Status close();

 private:
  RecordingWriter() = default;
  int add_stream(StreamInfo info);
  struct Pcap;
  std::string directory_;
  Manifest manifest_;
  std::unique_ptr<Pcap> pcap_;
  std::FILE* can_ = nullptr;
  std::vector<std::FILE*> serial_;  // per stream: serial and GPIO logs (nullptr for the others)
  bool closed_ = false;
};

struct RecordingWriter::Created {
  std::unique_ptr<RecordingWriter> writer;
  std::string error;
};

}  // namespace trailnav::recording
