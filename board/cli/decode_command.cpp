// `trailnav decode`: dump the points of a Velodyne capture as CSV or PLY.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include "commands.hpp"
#include "terminal.hpp"
#include "trailnav/drivers/capture/capture_reader.hpp"
#include "trailnav/drivers/recording/recording.hpp"
#include "trailnav/drivers/velodyne/decoder.hpp"
#include "trailnav/drivers/velodyne/revolution_cut.hpp"

namespace trailnav::cli {
namespace {

using namespace trailnav::velodyne;

struct DecodeOptions {
  std::string input;
  std::string calibration;
  std::string model = "auto";
  std::string returns = "dual";
  std::string format = "csv";
  std::string out;
  int revolutions = 0;  // 0: all
  int port = 2368;
  double cut_deg = 0.0;
  bool hold_last_group = false;
};

struct OutputPoint {
  int revolution;
  Point point;
  double time_s;
};

// Finds the model from the first data packet on the port.
std::optional<Model> sniff_model(const std::string& path, int port, std::string& error) {
  auto opened = capture::open_capture(path);
  if (!opened.reader) {
    error = opened.error;
    return std::nullopt;
  }
  while (auto d = opened.reader->next()) {
    if (d->destination_port != port || d->payload.size() != kDataPacketSize) continue;
    if (auto m = detect_model(d->payload)) return m;
  }
  error = path + ": no data packet on port " + std::to_string(port) + " names its model; give --model";
  return std::nullopt;
}

// A recording directory's lidar stream: its capture file and port.
bool resolve_recording(DecodeOptions& o, std::string& error) {
  if (!std::filesystem::is_directory(o.input)) return true;
  const auto manifest = recording::load_manifest((std::filesystem::path(o.input) / recording::kManifestName).string());
  if (!manifest.manifest) {
    error = manifest.error;
    return false;
  }
  for (const recording::StreamInfo& s : manifest.manifest->streams) {
    if (s.kind == recording::StreamKind::udp && (s.name == "lidar" || s.port == o.port)) {
      o.input = (std::filesystem::path(o.input) / s.file).string();
      o.port = s.port;
      return true;
    }
  }
  error = o.input + ": the recording has no UDP stream named 'lidar' or on port " + std::to_string(o.port);
  return false;
}

int run_decode(DecodeOptions o) {
  std::string error;
  if (!resolve_recording(o, error)) {
    std::fprintf(stderr, "trailnav decode: %s\n", error.c_str());
    return 2;
  }
  std::optional<Model> model;
  if (o.model == "auto") {
    model = sniff_model(o.input, o.port, error);
  } else {
    model = parse_model(o.model);
    if (!model) error = "unknown model '" + o.model + "'; allowed: auto, VLP-16, VLP-16-HiRes, VLP-32C, HDL-32E, HDL-64E";
  }
  if (!model) {
    std::fprintf(stderr, "trailnav decode: %s\n", error.c_str());
    return 2;
  }
  std::optional<Calibration> calibration;
  if (!o.calibration.empty()) {
    CalibrationResult loaded = load_calibration(o.calibration);
    if (!loaded.calibration) {
      std::fprintf(stderr, "trailnav decode: %s\n", loaded.error.c_str());
      return 2;
    }
    calibration = std::move(loaded.calibration);
  } else {
    calibration = builtin_calibration(*model);
    if (!calibration) {
      std::fprintf(stderr, "trailnav decode: the %s needs its unit's calibration: give --calibration FILE\n",
                   std::string(model_info(*model).name).c_str());
      return 2;
    }
  }
  const ReturnSelection selection = o.returns == "strongest" ? ReturnSelection::strongest
                                    : o.returns == "last"    ? ReturnSelection::last
                                                             : ReturnSelection::all;
  DecoderOptions options;
  options.selection = selection;
  options.last_group = o.hold_last_group ? LastGroupAzimuth::hold : LastGroupAzimuth::extrapolate;
  auto created = PacketDecoder::create(*model, *calibration, options);
  if (!created.decoder) {
    std::fprintf(stderr, "trailnav decode: %s\n", created.error.c_str());
    return 2;
  }
  const PacketDecoder& decoder = *created.decoder;

  auto opened = capture::open_capture(o.input);
  if (!opened.reader) {
    std::fprintf(stderr, "trailnav decode: %s\n", opened.error.c_str());
    return 2;
  }
  std::FILE* out = o.out.empty() ? stdout : std::fopen(o.out.c_str(), "w");
  if (out == nullptr) {
    std::fprintf(stderr, "trailnav decode: cannot write %s\n", o.out.c_str());
    return 2;
  }

  std::vector<Point> points(kMaxPointsPerPacket);
  std::vector<OutputPoint> ply_points;
  RevolutionCut cut(o.cut_deg * std::numbers::pi / 180.0);
  int revolution = 0;
  double revolution_start = -1.0;
  std::uint64_t packets = 0;
  std::uint64_t malformed = 0;
  std::uint64_t written = 0;
  if (o.format == "csv") std::fprintf(out, "revolution,ring,azimuth_deg,distance_m,x,y,z,intensity,time_s,return\n");
  ProgressBar progress("decode", static_cast<double>(opened.reader->size()) / 1e6, "MB");

  while (auto d = opened.reader->next()) {
    if (d->destination_port != o.port) continue;
    ++packets;
    const PacketInfo info = decoder.decode(d->payload, points);
    if (info.error != PacketError::none) {
      ++malformed;
      continue;
    }
    if (packets % 256 == 0) progress.update(static_cast<double>(opened.reader->position()) / 1e6);
    const double packet_time = info.timestamp_us * 1e-6;
    if (revolution_start < 0.0) revolution_start = packet_time;
    auto emit = [&](const Point& p) {
      double since = packet_time + static_cast<double>(p.time) - revolution_start;
      if (since < -1800.0) since += 3600.0;  // the packet clock wrapped at the top of the hour
      if (o.format == "csv") {
        std::fprintf(out, "%d,%u,%.3f,%.3f,%.4f,%.4f,%.4f,%.0f,%.6f,%d\n", revolution, p.ring,
                     static_cast<double>(p.azimuth) * 180.0 / std::numbers::pi, static_cast<double>(p.distance),
                     static_cast<double>(p.x), static_cast<double>(p.y), static_cast<double>(p.z),
                     static_cast<double>(p.intensity), since, static_cast<int>(p.kind));
      } else {
        ply_points.push_back({revolution, p, since});
      }
      ++written;
    };
    // The firings before the cut, then (when the packet crosses it) the rest
    // in the next revolution: the same cut as the driver's range images.
    const int first_new = cut.first_new_sequence(info);
    for (int i = 0; i < info.points; ++i) {
      if (points[static_cast<std::size_t>(i)].sequence < first_new) emit(points[static_cast<std::size_t>(i)]);
    }
    if (first_new == info.sequences) continue;
    ++revolution;
    revolution_start = packet_time + static_cast<double>(info.sequence_time_us[static_cast<std::size_t>(first_new)]) * 1e-6;
    if (o.revolutions > 0 && revolution >= o.revolutions) break;
    for (int i = 0; i < info.points; ++i) {
      if (points[static_cast<std::size_t>(i)].sequence >= first_new) emit(points[static_cast<std::size_t>(i)]);
    }
  }
  progress.finish();
  if (o.format == "ply") {
    std::fprintf(out,
                 "ply\nformat ascii 1.0\ncomment trailnav decode %s\nelement vertex %zu\nproperty float x\n"
                 "property float y\nproperty float z\nproperty float intensity\nproperty ushort ring\n"
                 "property float time\nproperty int revolution\nend_header\n",
                 o.input.c_str(), ply_points.size());
    for (const OutputPoint& q : ply_points) {
      std::fprintf(out, "%.4f %.4f %.4f %.0f %u %.6f %d\n", static_cast<double>(q.point.x), static_cast<double>(q.point.y),
                   static_cast<double>(q.point.z), static_cast<double>(q.point.intensity), q.point.ring, q.time_s,
                   q.revolution);
    }
  }
  if (out != stdout) std::fclose(out);
  std::fprintf(stderr, "trailnav decode: %s, %s calibration; %llu packets, %llu malformed, %llu points, %d revolution cut(s)\n",
               std::string(model_info(*model).name).c_str(), calibration->source.c_str(),
               static_cast<unsigned long long>(packets), static_cast<unsigned long long>(malformed),
               static_cast<unsigned long long>(written), revolution);
  return malformed == 0 ? 0 : 1;
}

}  // namespace

void add_decode_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "decode",
      "Decode a Velodyne capture (pcap, pcapng, raw back-to-back 1206-byte payloads, or a bench\n"
      "recording directory, whose 'lidar' stream is read) into points.\n"
      "CSV columns: revolution,ring,azimuth_deg,distance_m,x,y,z,intensity,time_s,return\n"
      "  ring: laser index sorted by elevation (0 = lowest); x forward, y left, z up (m);\n"
      "  time_s: since the revolution's first firing; return: 0 strongest, 1 last, 2 dual-last,\n"
      "  3 dual-strongest, 4 dual with both returns identical (one point).\n"
      "Exit code 1 when any packet on the port was malformed.");
  static DecodeOptions o;
  cmd->add_option("input", o.input, "Capture file or recording directory")->required()->check(CLI::ExistingPath);
  cmd->add_option("--calibration", o.calibration,
                  "Calibration: ROS velodyne_pointcloud YAML or Velodyne db.xml (default: the model's built-in table)")
      ->check(CLI::ExistingFile);
  cmd->add_option("--model", o.model, "auto (from the packets' factory bytes), VLP-16, VLP-16-HiRes, VLP-32C, HDL-32E, HDL-64E")
      ->capture_default_str();
  cmd->add_option("--return", o.returns, "Returns to keep from dual-return packets")
      ->check(CLI::IsMember({"strongest", "last", "dual"}))
      ->capture_default_str();
  cmd->add_option("--revolutions", o.revolutions, "Stop after this many revolutions (0: all)")->check(CLI::NonNegativeNumber);
  cmd->add_option("--cut", o.cut_deg, "Azimuth (degrees) where one revolution ends and the next begins")
      ->check(CLI::Range(0.0, 360.0))
      ->capture_default_str();
  cmd->add_option("--port", o.port, "UDP destination port of the data packets")->check(CLI::Range(1, 65535))->capture_default_str();
  cmd->add_option("--format", o.format, "csv or ply")->check(CLI::IsMember({"csv", "ply"}))->capture_default_str();
  cmd->add_flag("--hold-last-group", o.hold_last_group,
               "Do not interpolate the azimuth of a packet's last firing group (tier4/nebula's convention)");
  cmd->add_option("--out", o.out, "Output file (default: standard output)");
  cmd->callback([] {
    const int code = run_decode(o);
    if (code != 0) throw CLI::RuntimeError(code);
  });
}

}  // namespace trailnav::cli
