#include "trailnav/drivers/recording/recording.hpp"

#include <pcap/pcap.h>
#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>

#include "trailnav/drivers/capture/capture_reader.hpp"
#include "trailnav/drivers/camera/image_file.hpp"
#include "trailnav/drivers/gpio/line_tunnel.hpp"
#include "trailnav/drivers/velodyne/packet.hpp"
#include "trailnav/runtime/config.hpp"

namespace trailnav::recording {
namespace camera = trailnav::drivers::camera;
namespace {

namespace fs = std::filesystem;

int hex_value(char c) noexcept {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

// "(1436509052.249713)" at the start of a line; returns the rest.
bool parse_stamp(std::string_view& line, std::int64_t& time_ns, std::string& error) {
  if (line.empty() || line.front() != '(') {
    error = "expected '(seconds.microseconds)' at the start";
    return false;
  }
  const std::size_t close = line.find(')');
  const std::size_t dot = line.find('.');
  if (close == std::string_view::npos || dot == std::string_view::npos || dot > close) {
    error = "malformed timestamp";
    return false;
  }
  std::int64_t seconds = 0;
  auto r = std::from_chars(line.data() + 1, line.data() + dot, seconds);
  if (r.ec != std::errc{} || r.ptr != line.data() + dot) {
    error = "malformed timestamp seconds";
    return false;
  }
  if (seconds < 0 || seconds > 9'000'000'000) {  // nanoseconds must fit in 64 bits
    error = "timestamp seconds out of range";
    return false;
  }
  const std::string_view fraction = line.substr(dot + 1, close - dot - 1);
  if (fraction.empty() || fraction.size() > 9) {
    error = "timestamp fraction must have 1 to 9 digits";
    return false;
  }
  std::int64_t ns = 0;
  for (std::size_t i = 0; i < 9; ++i) {
    int digit = 0;
    if (i < fraction.size()) {
      if (fraction[i] < '0' || fraction[i] > '9') {
        error = "malformed timestamp fraction";
        return false;
      }
      digit = fraction[i] - '0';
    }
    ns = ns * 10 + digit;
  }
  time_ns = seconds * 1'000'000'000 + ns;
  line.remove_prefix(close + 1);
  while (!line.empty() && line.front() == ' ') line.remove_prefix(1);
  return true;
}

bool parse_hex_bytes(std::string_view text, std::uint8_t* out, std::size_t capacity, std::size_t& length,
                     std::string& error) {
  if (text.size() % 2 != 0) {
    error = "odd number of hex digits";
    return false;
  }
  if (text.size() / 2 > capacity) {
    error = "more than " + std::to_string(capacity) + " data bytes";
    return false;
  }
  for (std::size_t i = 0; i < text.size(); i += 2) {
    const int hi = hex_value(text[i]);
    const int lo = hex_value(text[i + 1]);
    if (hi < 0 || lo < 0) {
      error = "'" + std::string(text.substr(i, 2)) + "' is not a hex byte";
      return false;
    }
    out[i / 2] = static_cast<std::uint8_t>(hi * 16 + lo);
  }
  length = text.size() / 2;
  return true;
}

std::string format_stamp(std::int64_t time_ns) {
  char text[48];
  const std::int64_t seconds = time_ns / 1'000'000'000;
  const std::int64_t micros = (time_ns % 1'000'000'000) / 1000;
  std::snprintf(text, sizeof text, "(%lld.%06lld)", static_cast<long long>(seconds), static_cast<long long>(micros));
  return text;
}

constexpr const char* kHex = "0123456789ABCDEF";

}  // namespace

const char* stream_kind_name(StreamKind kind) noexcept {
  switch (kind) {
    case StreamKind::udp:
      return "udp";
    case StreamKind::can:
      return "can";
    case StreamKind::serial:
      return "serial";
    case StreamKind::gpio:
      return "gpio";
    case StreamKind::image:
      return "image";
  }
  return "?";
}

// ---------------------------------------------------------------- manifest

ManifestResult load_manifest(const std::string& path) {
  ManifestResult result;
  try {
    const ConfigNode root = ConfigNode::load_file(path);
    Manifest m;
    const std::string format = root.choice("format", {"trailnav-recording"});
    (void)format;
    m.version = static_cast<int>(root.integer("version", 1, 1));
    m.description = root.string("description", "");
    std::map<std::string, int> names;
    for (const ConfigNode& s : root.map_list("streams")) {
      StreamInfo info;
      info.name = s.string("name");
      if (info.name.empty() || names.count(info.name) != 0) {
        s.fail("name", info.name.empty() ? "must not be empty" : "'" + info.name + "' names two streams");
      }
      names[info.name] = 1;
      const std::string kind = s.choice("kind", {"udp", "can", "serial", "gpio", "image"});
      info.kind = kind == "udp"      ? StreamKind::udp
                  : kind == "can"    ? StreamKind::can
                  : kind == "serial" ? StreamKind::serial
                  : kind == "gpio"   ? StreamKind::gpio
                                     : StreamKind::image;
      info.file = s.string("file");
      if (info.file.empty() || info.file.front() == '/' || info.file.find("..") != std::string::npos) {
        s.fail("file", "must be a path inside the recording directory");
      }
      if (!fs::exists(fs::path(path).parent_path() / info.file)) {
        s.fail("file", "'" + info.file + "' does not exist next to the manifest");
      }
      if (info.kind == StreamKind::udp) info.port = static_cast<std::uint16_t>(s.integer("port", 1, 65535));
      if (info.kind == StreamKind::can) info.interface = s.string("interface", "can0");
      if (info.kind == StreamKind::serial) info.baud = static_cast<int>(s.integer("baud", 50, 16'000'000, 115200));
      info.description = s.string("description", "");
      s.reject_unknown_keys();
      m.streams.push_back(std::move(info));
    }
    root.reject_unknown_keys();
    result.manifest = std::move(m);
  } catch (const ConfigError& e) {
    result.error = e.what();
  }
  return result;
}

Status write_manifest(const std::string& path, const Manifest& manifest) {
  std::ofstream out(path);
  if (!out) return Status::error("cannot write " + path + ": " + std::strerror(errno));
  out << "# trailnav bench recording (docs/recording.md)\n"
      << "format: trailnav-recording\n"
      << "version: " << manifest.version << "\n";
  if (!manifest.description.empty()) out << "description: \"" << manifest.description << "\"\n";
  out << "streams:\n";
  for (const StreamInfo& s : manifest.streams) {
    out << "  - name: " << s.name << "\n"
        << "    kind: " << stream_kind_name(s.kind) << "\n"
        << "    file: " << s.file << "\n";
    if (s.kind == StreamKind::udp) out << "    port: " << s.port << "\n";
    if (s.kind == StreamKind::can) out << "    interface: " << s.interface << "\n";
    if (s.kind == StreamKind::serial) out << "    baud: " << s.baud << "\n";
    if (!s.description.empty()) out << "    description: \"" << s.description << "\"\n";
  }
  out.close();
  if (!out) return Status::error("cannot write " + path);
  return Status::ok();
}

// ---------------------------------------------------------------- line formats

bool parse_candump_line(std::string_view line, CanFrame& frame, std::string& interface, std::string& error) {
  frame = CanFrame{};
  while (!line.empty() && (line.back() == '\r' || line.back() == '\n' || line.back() == ' ')) line.remove_suffix(1);
  if (!parse_stamp(line, frame.time_ns, error)) return false;
  const std::size_t space = line.find(' ');
  if (space == std::string_view::npos || space == 0) {
    error = "expected an interface name after the timestamp";
    return false;
  }
  interface.assign(line.substr(0, space));
  std::string_view rest = line.substr(space + 1);
  // Anything after the frame (candump -L appends " R"/" T" direction flags on newer versions).
  if (const std::size_t tail = rest.find(' '); tail != std::string_view::npos) rest = rest.substr(0, tail);
  const std::size_t hash = rest.find('#');
  if (hash == std::string_view::npos) {
    error = "expected ID#DATA";
    return false;
  }
  const std::string_view id_text = rest.substr(0, hash);
  if (id_text.size() != 3 && id_text.size() != 8) {
    error = "a CAN id has 3 (standard) or 8 (extended) hex digits, not '" + std::string(id_text) + "'";
    return false;
  }
  std::uint32_t id = 0;
  for (char c : id_text) {
    const int v = hex_value(c);
    if (v < 0) {
      error = "'" + std::string(id_text) + "' is not a hex CAN id";
      return false;
    }
    id = id * 16 + static_cast<std::uint32_t>(v);
  }
  if (id_text.size() == 8) {
    // 29-bit extended ids; error frames carry CAN_ERR_FLAG (0x20000000) as candump prints it.
    if (id > 0x3FFFFFFFu) {
      error = "extended CAN id " + std::string(id_text) + " has more than 29 bits";
      return false;
    }
    if ((id & kCanErrFlag) == 0) id |= kCanEffFlag;
  } else if (id > 0x7FF) {
    error = "standard CAN id " + std::string(id_text) + " is over 0x7FF";
    return false;
  }
  frame.id = id;
  std::string_view data = rest.substr(hash + 1);
  std::size_t length = 0;
  if (!data.empty() && data.front() == '#') {  // CAN FD: ID##<flags><data>
    if (data.size() < 2 || hex_value(data[1]) < 0) {
      error = "CAN FD frame without its flags digit";
      return false;
    }
    frame.fd = true;
    frame.fd_flags = static_cast<std::uint8_t>(hex_value(data[1]));
    if (!parse_hex_bytes(data.substr(2), frame.data.data(), 64, length, error)) return false;
    static constexpr std::array<std::size_t, 16> kFdLengths = {0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64};
    if (std::find(kFdLengths.begin(), kFdLengths.end(), length) == kFdLengths.end()) {
      error = "CAN FD data of " + std::to_string(length) + " bytes is not a valid FD length";
      return false;
    }
  } else if (!data.empty() && data.front() == 'R') {
    // Remote request: "R", or "R<length>" with the requested length 0..8.
    if (data.size() > 2 || (data.size() == 2 && (data[1] < '0' || data[1] > '8'))) {
      error = "a remote frame is written R or R0..R8, not '" + std::string(data) + "'";
      return false;
    }
    frame.id |= kCanRtrFlag;
    length = data.size() == 2 ? static_cast<std::size_t>(data[1] - '0') : 0;
  } else {
    if (!parse_hex_bytes(data, frame.data.data(), 8, length, error)) return false;
  }
  frame.length = static_cast<std::uint8_t>(length);
  return true;
}

std::string format_candump_line(const CanFrame& frame, std::string_view interface) {
  std::string out = format_stamp(frame.time_ns);
  out += ' ';
  out += interface;
  out += ' ';
  char id[16];
  if ((frame.id & (kCanEffFlag | kCanErrFlag)) != 0) {
    std::snprintf(id, sizeof id, "%08X",
                  (frame.id & kCanErrFlag) != 0 ? (frame.id & 0x3FFFFFFFu) : (frame.id & 0x1FFFFFFFu));
  } else {
    std::snprintf(id, sizeof id, "%03X", frame.id & 0x7FFu);
  }
  out += id;
  out += '#';
  if (frame.fd) {
    out += '#';
    out += kHex[frame.fd_flags & 0xF];
  } else if ((frame.id & kCanRtrFlag) != 0) {
    out += 'R';
    if (frame.length > 0) out += static_cast<char>('0' + std::min<int>(frame.length, 8));
    return out;
  }
  for (std::size_t i = 0; i < frame.length; ++i) {
    out += kHex[frame.data[i] >> 4];
    out += kHex[frame.data[i] & 0xF];
  }
  return out;
}

bool parse_serial_line(std::string_view line, std::int64_t& time_ns, std::vector<std::uint8_t>& bytes,
                       std::string& error) {
  while (!line.empty() && (line.back() == '\r' || line.back() == '\n' || line.back() == ' ')) line.remove_suffix(1);
  if (!parse_stamp(line, time_ns, error)) return false;
  bytes.resize(line.size() / 2);
  std::size_t length = 0;
  if (!parse_hex_bytes(line, bytes.data(), bytes.size(), length, error)) return false;
  if (length == 0) {
    error = "no bytes";
    return false;
  }
  return true;
}

std::string format_serial_line(std::int64_t time_ns, std::span<const std::uint8_t> bytes) {
  std::string out = format_stamp(time_ns);
  out += ' ';
  for (std::uint8_t b : bytes) {
    out += kHex[b >> 4];
    out += kHex[b & 0xF];
  }
  return out;
}

bool parse_gpio_line(std::string_view line, std::int64_t& time_ns, std::string& name, bool& value, std::string& error) {
  while (!line.empty() && (line.back() == '\r' || line.back() == '\n' || line.back() == ' ')) line.remove_suffix(1);
  if (!parse_stamp(line, time_ns, error)) return false;
  const std::size_t space = line.rfind(' ');
  if (space == std::string_view::npos || space + 2 != line.size() || (line.back() != '0' && line.back() != '1')) {
    error = "expected 'LINE 0' or 'LINE 1' after the time";
    return false;
  }
  const std::string_view n = line.substr(0, space);
  if (!gpio::valid_line_name(n)) {
    error = "line name '" + std::string(n) + "' must be 1 to 31 printable characters without spaces";
    return false;
  }
  name.assign(n);
  value = line.back() == '1';
  return true;
}

bool parse_image_line(std::string_view line, std::int64_t& time_ns, std::uint32_t& sequence, std::string& file,
                      std::string& error) {
  while (!line.empty() && (line.back() == '\r' || line.back() == '\n' || line.back() == ' ')) line.remove_suffix(1);
  if (!parse_stamp(line, time_ns, error)) return false;
  const std::size_t space = line.find(' ');
  if (space == std::string_view::npos || space == 0) {
    error = "expected 'SEQUENCE FILE' after the time";
    return false;
  }
  std::uint64_t seq = 0;
  for (char c : line.substr(0, space)) {
    if (c < '0' || c > '9' || seq > 0xFFFFFFFFull / 10) {
      error = "the sequence '" + std::string(line.substr(0, space)) + "' is not a number of 0 to 4294967295";
      return false;
    }
    seq = seq * 10 + static_cast<std::uint64_t>(c - '0');
  }
  if (seq > 0xFFFFFFFFull) {
    error = "the sequence is larger than 4294967295";
    return false;
  }
  const std::string_view f = line.substr(space + 1);
  if (f.empty() || f.find('/') != std::string_view::npos || f.find(' ') != std::string_view::npos || f == "." || f == "..") {
    error = "the frame's file must be a plain name in the stream's directory";
    return false;
  }
  sequence = static_cast<std::uint32_t>(seq);
  file.assign(f);
  return true;
}

std::string format_image_line(std::int64_t time_ns, std::uint32_t sequence, std::string_view file) {
  std::string out = format_stamp(time_ns);
  out += ' ';
  out += std::to_string(sequence);
  out += ' ';
  out += file;
  return out;
}

std::string format_gpio_line(std::int64_t time_ns, std::string_view name, bool value) {
  std::string out = format_stamp(time_ns);
  out += ' ';
  out += name;
  out += value ? " 1" : " 0";
  return out;
}

// ---------------------------------------------------------------- reader

struct RecordingReader::Source {
  virtual ~Source() = default;
  // Loads the next record into the source's own buffer; false at the end.
  virtual bool advance(RecordingReader& reader) = 0;
  virtual std::uint64_t position() const noexcept = 0;
  virtual std::uint64_t size() const noexcept = 0;
  bool has = false;
  Event event;
};

struct RecordingReader::UdpSource final : Source {
  std::unique_ptr<capture::CaptureReader> capture;
  std::map<std::uint16_t, int> stream_of_port;
  std::vector<std::uint8_t> buffer;
  // Raw Velodyne files have no capture time: the packets' own clock, unwrapped.
  bool have_raw = false;
  std::uint32_t last_raw_stamp = 0;
  std::int64_t raw_us = 0;

  bool advance(RecordingReader& reader) override {
    while (auto d = capture->next()) {
      auto it = stream_of_port.find(d->destination_port);
      if (it == stream_of_port.end()) {
        ++reader.counters_.unassigned_udp;
        continue;
      }
      buffer.assign(d->payload.begin(), d->payload.end());
      event = Event{};
      event.time_ns = d->time_ns;
      if (d->time_ns == 0 && buffer.size() == velodyne::kDataPacketSize) {
        const std::uint32_t stamp = velodyne::read_u32(buffer.data() + velodyne::kTimestampOffset);
        if (have_raw)
          raw_us += velodyne::hour_clock_delta_us(stamp, last_raw_stamp);
        else
          raw_us = stamp;
        have_raw = true;
        last_raw_stamp = stamp;
        event.time_ns = raw_us * 1000;
      }
      event.stream = it->second;
      event.kind = StreamKind::udp;
      event.payload = buffer;
      event.source_ip = d->source_ip;
      event.source_port = d->source_port;
      return true;
    }
    return false;
  }
  std::uint64_t position() const noexcept override { return capture->position(); }
  std::uint64_t size() const noexcept override { return capture->size(); }
};

// A text log read line by line (candump and serial logs).
struct RecordingReader::LineSource : Source {
  std::ifstream in;
  std::string file;
  std::string line;
  int line_number = 0;
  std::uint64_t bytes_read = 0;
  std::uint64_t total = 0;

  bool open_file(const std::string& path, std::string& error) {
    in.open(path);
    if (!in) {
      error = "cannot read " + path;
      return false;
    }
    file = path;
    std::error_code ec;
    total = fs::file_size(path, ec);
    return true;
  }
  // The next line that is neither empty nor a comment.
  bool next_line() {
    while (std::getline(in, line)) {
      ++line_number;
      bytes_read += line.size() + 1;
      if (!line.empty() && line.front() != '#') return true;
    }
    return false;
  }
  void problem(RecordingReader& reader, const std::string& what) const {
    reader.note_problem(file + ":" + std::to_string(line_number) + ": " + what);
  }
  std::uint64_t position() const noexcept override { return bytes_read; }
  std::uint64_t size() const noexcept override { return total; }
};

struct RecordingReader::CanSource final : LineSource {
  std::map<std::string, int> stream_of_interface;
  int default_stream = -1;
  CanFrame frame;

  bool advance(RecordingReader& reader) override {
    std::string interface, error;
    while (next_line()) {
      if (!parse_candump_line(line, frame, interface, error)) {
        problem(reader, error);
        continue;
      }
      auto it = stream_of_interface.find(interface);
      event = Event{};
      event.time_ns = frame.time_ns;
      event.stream = it != stream_of_interface.end() ? it->second : default_stream;
      event.kind = StreamKind::can;
      event.can = &frame;
      return true;
    }
    return false;
  }
};

struct RecordingReader::SerialSource final : LineSource {
  int stream = 0;
  std::vector<std::uint8_t> bytes;

  bool advance(RecordingReader& reader) override {
    std::string error;
    while (next_line()) {
      std::int64_t t = 0;
      if (!parse_serial_line(line, t, bytes, error)) {
        problem(reader, error);
        continue;
      }
      event = Event{};
      event.time_ns = t;
      event.stream = stream;
      event.kind = StreamKind::serial;
      event.payload = bytes;
      return true;
    }
    return false;
  }
};

struct RecordingReader::GpioSource final : LineSource {
  int stream = 0;
  std::string name;

  bool advance(RecordingReader& reader) override {
    std::string error;
    while (next_line()) {
      std::int64_t t = 0;
      bool value = false;
      if (!parse_gpio_line(line, t, name, value, error)) {
        problem(reader, error);
        continue;
      }
      event = Event{};
      event.time_ns = t;
      event.stream = stream;
      event.kind = StreamKind::gpio;
      event.payload = {reinterpret_cast<const std::uint8_t*>(name.data()), name.size()};
      event.gpio_value = value;
      return true;
    }
    return false;
  }
};

struct RecordingReader::ImageSource final : LineSource {
  int stream = 0;
  std::string directory;  // images/<name>/ next to the log
  camera::GreyImage image;

  bool advance(RecordingReader& reader) override {
    std::string error, name;
    while (next_line()) {
      std::int64_t t = 0;
      std::uint32_t sequence = 0;
      if (!parse_image_line(line, t, sequence, name, error)) {
        problem(reader, error);
        continue;
      }
      camera::ImageRead read = camera::read_grey_image((fs::path(directory) / name).string());
      if (!read.ok()) {
        problem(reader, read.error);
        continue;
      }
      image = std::move(read.image);
      event = Event{};
      event.time_ns = t;
      event.stream = stream;
      event.kind = StreamKind::image;
      event.payload = image.pixels;
      event.image_width = image.width;
      event.image_height = image.height;
      event.image_sequence = sequence;
      return true;
    }
    return false;
  }
};

void RecordingReader::note_problem(const std::string& problem) {
  ++counters_.bad_lines;
  if (first_problem_.empty()) first_problem_ = problem;
}

RecordingReader::~RecordingReader() = default;

RecordingReader::Opened RecordingReader::open(const std::string& path) {
  Opened result;
  std::unique_ptr<RecordingReader> r(new RecordingReader());
  r->path_ = path;
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    const std::string manifest_path = (fs::path(path) / kManifestName).string();
    if (!fs::exists(manifest_path)) {
      result.error = path + " is a directory without a " + kManifestName + ": not a recording";
      return result;
    }
    ManifestResult loaded = load_manifest(manifest_path);
    if (!loaded.manifest) {
      result.error = loaded.error;
      return result;
    }
    r->streams_ = loaded.manifest->streams;
  } else {
    if (!fs::exists(path, ec)) {
      result.error = path + ": no such file or directory";
      return result;
    }
    // A bare capture: streams from the ports in it.
    auto opened = capture::open_capture(path);
    if (!opened.reader) {
      result.error = opened.error;
      return result;
    }
    std::map<std::uint16_t, bool> ports;
    while (auto d = opened.reader->next()) ports[d->destination_port] = true;
    for (const auto& [port, unused] : ports) {
      StreamInfo s;
      s.kind = StreamKind::udp;
      s.port = port;
      s.file = fs::path(path).filename().string();
      s.name = port == 2368 ? "lidar" : port == 8308 ? "lidar-position" : "udp-" + std::to_string(port);
      r->streams_.push_back(s);
    }
  }
  const fs::path base = fs::is_directory(path, ec) ? fs::path(path) : fs::path(path).parent_path();

  // One UDP source per capture file.
  std::map<std::string, UdpSource*> udp_by_file;
  std::map<std::string, CanSource*> can_by_file;
  for (std::size_t i = 0; i < r->streams_.size(); ++i) {
    const StreamInfo& s = r->streams_[i];
    const std::string file = (base / s.file).string();
    if (s.kind == StreamKind::udp) {
      UdpSource*& u = udp_by_file[file];
      if (u == nullptr) {
        auto source = std::make_unique<UdpSource>();
        auto opened = capture::open_capture(file);
        if (!opened.reader) {
          result.error = opened.error;
          return result;
        }
        source->capture = std::move(opened.reader);
        u = source.get();
        r->sources_.push_back(std::move(source));
      }
      if (u->stream_of_port.count(s.port) != 0) {
        result.error = path + ": streams '" + r->streams_[static_cast<std::size_t>(u->stream_of_port[s.port])].name +
                       "' and '" + s.name + "' both claim port " + std::to_string(s.port) + " of " + s.file;
        return result;
      }
      u->stream_of_port[s.port] = static_cast<int>(i);
    } else if (s.kind == StreamKind::can) {
      CanSource*& c = can_by_file[file];
      if (c == nullptr) {
        auto source = std::make_unique<CanSource>();
        if (!source->open_file(file, result.error)) return result;
        source->default_stream = static_cast<int>(i);
        c = source.get();
        r->sources_.push_back(std::move(source));
      }
      c->stream_of_interface[s.interface] = static_cast<int>(i);
    } else if (s.kind == StreamKind::serial) {
      auto source = std::make_unique<SerialSource>();
      if (!source->open_file(file, result.error)) return result;
      source->stream = static_cast<int>(i);
      r->sources_.push_back(std::move(source));
    } else if (s.kind == StreamKind::gpio) {
      auto source = std::make_unique<GpioSource>();
      if (!source->open_file(file, result.error)) return result;
      source->stream = static_cast<int>(i);
      r->sources_.push_back(std::move(source));
    } else {
      auto source = std::make_unique<ImageSource>();
      if (!source->open_file(file, result.error)) return result;
      source->stream = static_cast<int>(i);
      // images/<name>.log -> images/<name>/
      fs::path dir = fs::path(file);
      dir.replace_extension();
      source->directory = dir.string();
      r->sources_.push_back(std::move(source));
    }
  }
  for (auto& source : r->sources_) source->has = source->advance(*r);
  result.reader = std::move(r);
  return result;
}

int RecordingReader::stream_index(std::string_view name, StreamKind kind) const noexcept {
  for (std::size_t i = 0; i < streams_.size(); ++i) {
    if (streams_[i].name == name && streams_[i].kind == kind) return static_cast<int>(i);
  }
  return -1;
}

std::optional<Event> RecordingReader::next() {
  Source* best = nullptr;
  for (auto& s : sources_) {
    if (s->has && (best == nullptr || s->event.time_ns < best->event.time_ns)) best = s.get();
  }
  if (best == nullptr) return std::nullopt;
  // Hand out the event, then let its source read ahead into its other buffer.
  current_ = best->event;
  current_bytes_.assign(best->event.payload.begin(), best->event.payload.end());
  current_.payload = current_bytes_;  // (an image's pixels too: they stay valid until the next call)
  if (best->event.can != nullptr) {
    current_can_ = *best->event.can;
    current_.can = &current_can_;
  }
  best->has = best->advance(*this);
  ++counters_.events;
  return current_;
}

std::uint64_t RecordingReader::position() const noexcept {
  std::uint64_t p = 0;
  for (const auto& s : sources_) p += s->position();
  return p;
}

std::uint64_t RecordingReader::size() const noexcept {
  std::uint64_t p = 0;
  for (const auto& s : sources_) p += s->size();
  return p;
}

// ---------------------------------------------------------------- writer

struct RecordingWriter::Pcap {
  pcap_t* dead = nullptr;
  pcap_dumper_t* dumper = nullptr;
  std::vector<std::uint8_t> frame;
  std::uint16_t ip_id = 0;
  ~Pcap() {
    if (dumper != nullptr) pcap_dump_close(dumper);
    if (dead != nullptr) pcap_close(dead);
  }
};

RecordingWriter::Created RecordingWriter::create(const std::string& directory, const std::string& description) {
  Created result;
  std::error_code ec;
  fs::create_directories(fs::path(directory) / "serial", ec);
  if (!ec) fs::create_directories(fs::path(directory) / "gpio", ec);
  if (ec) {
    result.error = "cannot create " + directory + ": " + ec.message();
    return result;
  }
  std::unique_ptr<RecordingWriter> w(new RecordingWriter());
  w->directory_ = directory;
  w->manifest_.description = description;
  result.writer = std::move(w);
  return result;
}

RecordingWriter::~RecordingWriter() {
  if (!closed_) (void)close();
}

int RecordingWriter::add_stream(StreamInfo info) {
  if (info.kind == StreamKind::serial || info.kind == StreamKind::gpio || info.kind == StreamKind::image) {
    serial_.push_back(std::fopen((fs::path(directory_) / info.file).c_str(), "w"));
  } else {
    serial_.push_back(nullptr);
  }
  manifest_.streams.push_back(std::move(info));
  return static_cast<int>(manifest_.streams.size() - 1);
}

int RecordingWriter::add_udp_stream(const std::string& name, std::uint16_t port, const std::string& description) {
  StreamInfo s;
  s.name = name;
  s.kind = StreamKind::udp;
  s.file = "udp.pcap";
  s.port = port;
  s.description = description;
  return add_stream(std::move(s));
}

int RecordingWriter::add_can_stream(const std::string& name, const std::string& interface,
                                    const std::string& description) {
  StreamInfo s;
  s.name = name;
  s.kind = StreamKind::can;
  s.file = "can.log";
  s.interface = interface;
  s.description = description;
  return add_stream(std::move(s));
}

int RecordingWriter::add_serial_stream(const std::string& name, int baud, const std::string& description) {
  StreamInfo s;
  s.name = name;
  s.kind = StreamKind::serial;
  s.file = "serial/" + name + ".log";
  s.baud = baud;
  s.description = description;
  return add_stream(std::move(s));
}

int RecordingWriter::add_gpio_stream(const std::string& name, const std::string& description) {
  StreamInfo s;
  s.name = name;
  s.kind = StreamKind::gpio;
  s.file = "gpio/" + name + ".log";
  s.description = description;
  return add_stream(std::move(s));
}

Status RecordingWriter::write_udp(int stream, std::int64_t time_ns, std::span<const std::uint8_t> payload,
                                  std::uint32_t source_ip, std::uint16_t source_port) {
  if (stream < 0 || static_cast<std::size_t>(stream) >= manifest_.streams.size() ||
      manifest_.streams[static_cast<std::size_t>(stream)].kind != StreamKind::udp) {
    return Status::error("write_udp: stream " + std::to_string(stream) + " is not a UDP stream");
  }
  if (payload.size() > 65507) return Status::error("write_udp: datagram too large");
  if (!pcap_) {
    pcap_ = std::make_unique<Pcap>();
    pcap_->dead = pcap_open_dead_with_tstamp_precision(DLT_EN10MB, 65535, PCAP_TSTAMP_PRECISION_NANO);
    const std::string file = (fs::path(directory_) / "udp.pcap").string();
    pcap_->dumper = pcap_dump_open(pcap_->dead, file.c_str());
    if (pcap_->dumper == nullptr) return Status::error("cannot write " + file + ": " + pcap_geterr(pcap_->dead));
  }
  const std::uint16_t port = manifest_.streams[static_cast<std::size_t>(stream)].port;
  // Ethernet, IPv4 (no options), UDP: the sensor's address to 127.0.0.1.
  std::vector<std::uint8_t>& f = pcap_->frame;
  f.assign(14 + 20 + 8 + payload.size(), 0);
  const std::uint8_t mac_dst[6] = {0xff, 0xff, 0xff, 0xff, 0xff, 0xff};
  const std::uint8_t mac_src[6] = {0x60, 0x76, 0x88, 0x00, 0x00, 0x01};
  std::memcpy(f.data(), mac_dst, 6);
  std::memcpy(f.data() + 6, mac_src, 6);
  f[12] = 0x08;
  f[13] = 0x00;
  std::uint8_t* ip = f.data() + 14;
  const auto total = static_cast<std::uint16_t>(20 + 8 + payload.size());
  ip[0] = 0x45;
  ip[2] = static_cast<std::uint8_t>(total >> 8);
  ip[3] = static_cast<std::uint8_t>(total);
  ip[4] = static_cast<std::uint8_t>(pcap_->ip_id >> 8);
  ip[5] = static_cast<std::uint8_t>(pcap_->ip_id);
  ++pcap_->ip_id;
  ip[6] = 0x40;  // don't fragment
  ip[8] = 64;
  ip[9] = 17;
  const std::uint32_t dst = 0x7F000001u;
  for (int i = 0; i < 4; ++i) {
    ip[12 + i] = static_cast<std::uint8_t>(source_ip >> (24 - 8 * i));
    ip[16 + i] = static_cast<std::uint8_t>(dst >> (24 - 8 * i));
  }
  std::uint32_t sum = 0;
  for (int i = 0; i < 20; i += 2) sum += static_cast<std::uint32_t>(ip[i] << 8 | ip[i + 1]);
  while (sum >> 16) sum = (sum & 0xFFFF) + (sum >> 16);
  const auto checksum = static_cast<std::uint16_t>(~sum);
  ip[10] = static_cast<std::uint8_t>(checksum >> 8);
  ip[11] = static_cast<std::uint8_t>(checksum);
  std::uint8_t* udp = ip + 20;
  udp[0] = static_cast<std::uint8_t>(source_port >> 8);
  udp[1] = static_cast<std::uint8_t>(source_port);
  udp[2] = static_cast<std::uint8_t>(port >> 8);
  udp[3] = static_cast<std::uint8_t>(port);
  const auto udp_length = static_cast<std::uint16_t>(8 + payload.size());
  udp[4] = static_cast<std::uint8_t>(udp_length >> 8);
  udp[5] = static_cast<std::uint8_t>(udp_length);
  std::memcpy(udp + 8, payload.data(), payload.size());  // UDP checksum 0: none

  pcap_pkthdr header{};
  header.ts.tv_sec = static_cast<time_t>(time_ns / 1'000'000'000);
  header.ts.tv_usec = static_cast<suseconds_t>(time_ns % 1'000'000'000);  // nanoseconds: nano precision file
  header.caplen = static_cast<bpf_u_int32>(f.size());
  header.len = header.caplen;
  pcap_dump(reinterpret_cast<u_char*>(pcap_->dumper), &header, f.data());
  return Status::ok();
}

Status RecordingWriter::write_can(int stream, const CanFrame& frame) {
  if (stream < 0 || static_cast<std::size_t>(stream) >= manifest_.streams.size() ||
      manifest_.streams[static_cast<std::size_t>(stream)].kind != StreamKind::can) {
    return Status::error("write_can: stream " + std::to_string(stream) + " is not a CAN stream");
  }
  if (can_ == nullptr) {
    const std::string file = (fs::path(directory_) / "can.log").string();
    can_ = std::fopen(file.c_str(), "w");
    if (can_ == nullptr) return Status::error("cannot write " + file + ": " + std::strerror(errno));
  }
  const std::string line = format_candump_line(frame, manifest_.streams[static_cast<std::size_t>(stream)].interface);
  std::fprintf(can_, "%s\n", line.c_str());
  return Status::ok();
}

Status RecordingWriter::write_serial(int stream, std::int64_t time_ns, std::span<const std::uint8_t> bytes) {
  if (stream < 0 || static_cast<std::size_t>(stream) >= manifest_.streams.size() ||
      manifest_.streams[static_cast<std::size_t>(stream)].kind != StreamKind::serial) {
    return Status::error("write_serial: stream " + std::to_string(stream) + " is not a serial stream");
  }
  std::FILE* f = serial_[static_cast<std::size_t>(stream)];
  if (f == nullptr) return Status::error("cannot write the serial log of stream " + std::to_string(stream));
  if (bytes.empty()) return Status::ok();
  const std::string line = format_serial_line(time_ns, bytes);
  std::fprintf(f, "%s\n", line.c_str());
  return Status::ok();
}

Status RecordingWriter::write_gpio(int stream, std::int64_t time_ns, std::string_view line, bool value) {
  if (stream < 0 || static_cast<std::size_t>(stream) >= manifest_.streams.size() ||
      manifest_.streams[static_cast<std::size_t>(stream)].kind != StreamKind::gpio) {
    return Status::error("write_gpio: stream " + std::to_string(stream) + " is not a GPIO stream");
  }
  if (!gpio::valid_line_name(line)) return Status::error("write_gpio: invalid line name '" + std::string(line) + "'");
  std::FILE* f = serial_[static_cast<std::size_t>(stream)];
  if (f == nullptr) return Status::error("cannot write the GPIO log of stream " + std::to_string(stream));
  std::fprintf(f, "%s\n", format_gpio_line(time_ns, line, value).c_str());
  return Status::ok();
}

int RecordingWriter::add_image_stream(const std::string& name, const std::string& description) {
  std::error_code ec;
  fs::create_directories(fs::path(directory_) / "images" / name, ec);
  StreamInfo s;
  s.name = name;
  s.kind = StreamKind::image;
  s.file = "images/" + name + ".log";
  s.description = description;
  return add_stream(std::move(s));
}

Status RecordingWriter::write_image(int stream, std::int64_t time_ns, std::uint32_t sequence,
                                    std::span<const std::uint8_t> grey, int width, int height) {
  if (stream < 0 || static_cast<std::size_t>(stream) >= manifest_.streams.size() ||
      manifest_.streams[static_cast<std::size_t>(stream)].kind != StreamKind::image) {
    return Status::error("write_image: stream " + std::to_string(stream) + " is not an image stream");
  }
  std::FILE* f = serial_[static_cast<std::size_t>(stream)];
  if (f == nullptr) return Status::error("cannot write the image log of stream " + std::to_string(stream));
  const StreamInfo& info = manifest_.streams[static_cast<std::size_t>(stream)];
  char name[32];
  std::snprintf(name, sizeof name, "%010u.png", sequence);
  const std::string e =
      camera::write_grey_png((fs::path(directory_) / "images" / info.name / name).string(), grey, width, height);
  if (!e.empty()) return Status::error("write_image: " + e);
  std::fprintf(f, "%s\n", format_image_line(time_ns, sequence, name).c_str());
  return Status::ok();
}

Status RecordingWriter::close() {
  if (closed_) return Status::ok();
  closed_ = true;
  pcap_.reset();
  if (can_ != nullptr) std::fclose(can_);
  can_ = nullptr;
  for (std::FILE*& f : serial_) {
    if (f != nullptr) std::fclose(f);
    f = nullptr;
  }
  // Streams whose files were never written still need them: empty files.
  for (const StreamInfo& s : manifest_.streams) {
    const fs::path file = fs::path(directory_) / s.file;
    if (!fs::exists(file)) {
      if (s.kind == StreamKind::udp) {
        pcap_t* dead = pcap_open_dead_with_tstamp_precision(DLT_EN10MB, 65535, PCAP_TSTAMP_PRECISION_NANO);
        pcap_dumper_t* d = pcap_dump_open(dead, file.c_str());
        if (d != nullptr) pcap_dump_close(d);
        pcap_close(dead);
      } else {
        std::ofstream(file.string()).flush();
      }
    }
  }
  return write_manifest((fs::path(directory_) / kManifestName).string(), manifest_);
}

}  // namespace trailnav::recording
