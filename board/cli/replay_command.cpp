// `trailnav replay`: re-send a bench recording (or a bare capture) with its
// original timing, to loopback.
#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "cloud_sender.hpp"
#include "commands.hpp"
#include "dds.hpp"
#include "replayer.hpp"
#include "terminal.hpp"
#include "trailnav/drivers/cloud/cloud_file.hpp"

namespace trailnav::cli {
namespace {

struct ReplayCliOptions {
  std::string input;
  double rate = 1.0;
  bool max_rate = false;
  int loops = 1;
  bool forever = false;
  std::string lidar_to;
  std::string position_to;
  std::vector<std::string> to;
  std::string can_interface;
  std::string can_tunnel = "127.0.0.1:29536";
  std::string gpio_tunnel = "127.0.0.1:29537";
  std::string image_tunnel = "127.0.0.1:29538";
  std::vector<std::string> serial_links;
  double skip = 0.0;
  double duration = 0.0;
  bool quiet = false;
  std::vector<std::string> faults;
  std::uint64_t fault_seed = 1;
  // --clouds: point-cloud files as sensor_msgs/PointCloud2 over DDS.
  bool clouds = false;
  std::string topic = "points";
  std::uint32_t domain = 0;
  std::string cyclone_config;
  std::string frame = "lidar";
};

std::atomic<bool> g_stop{false};

void on_signal(int) { g_stop.store(true); }

bool split_assignment(const std::string& text, std::string& name, std::string& value) {
  const std::size_t eq = text.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == text.size()) return false;
  name = text.substr(0, eq);
  value = text.substr(eq + 1);
  return true;
}

double us(Nanos ns) { return static_cast<double>(ns) / 1000.0; }

// Point-cloud files (a file, or every .bin, .pcd and .ply of a directory in
// name order) sent as sensor_msgs/PointCloud2, one every 0.1 s / rate.
int run_cloud_replay(const ReplayCliOptions& o) {
  namespace fs = std::filesystem;
  std::vector<std::string> files;
  std::error_code ec;
  if (fs::is_directory(o.input, ec)) {
    for (const auto& e : fs::directory_iterator(o.input, ec)) {
      if (e.is_regular_file() && cloud::cloud_format_of(e.path().string())) files.push_back(e.path().string());
    }
    std::sort(files.begin(), files.end());
  } else if (cloud::cloud_format_of(o.input)) {
    files.push_back(o.input);
  }
  if (files.empty()) {
    std::fprintf(stderr, "trailnav replay: %s: no point-cloud file (.bin KITTI, .pcd, .ply) to send\n", o.input.c_str());
    return 2;
  }
  std::string xml = dds::loopback_config();
  if (!o.cyclone_config.empty()) {
    const dds::ConfigText c = dds::read_cyclone_config(o.cyclone_config);
    if (!c.error.empty()) {
      std::fprintf(stderr, "trailnav replay: %s\n", c.error.c_str());
      return 2;
    }
    xml = c.xml;
  }
  auto domain = dds::Domain::create(o.domain, xml);
  if (!domain.domain) {
    std::fprintf(stderr, "trailnav replay: %s\n", domain.error.c_str());
    return 2;
  }
  auto sender = dds::CloudSender::create(*domain.domain, o.topic, o.frame);
  if (!sender.sender) {
    std::fprintf(stderr, "trailnav replay: %s\n", sender.error.c_str());
    return 2;
  }
  char rate[32];
  std::snprintf(rate, sizeof rate, "%g Hz", 10.0 * o.rate);
  std::fprintf(stderr, "trailnav replay: %zu point-cloud file%s to %s on DDS domain %u at %s%s\n", files.size(),
               files.size() == 1 ? "" : "s", sender.sender->topic().c_str(), o.domain, o.max_rate ? "maximum rate" : rate,
               o.forever ? ", looping until stopped" : "");
  if (!sender.sender->wait_for_reader(5.0)) {
    std::fprintf(stderr, "trailnav replay: no reader of %s after 5 s; sending anyway\n", sender.sender->topic().c_str());
  }
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  cloud::PointCloud c;
  cloud::CloudScratch scratch;
  const auto period = std::chrono::duration<double>(0.1 / o.rate);
  const int loops = o.forever ? 0 : o.loops;
  const double total = static_cast<double>(files.size()) * (loops == 0 ? 1 : loops);
  ProgressBar progress("clouds", total, "");
  std::uint64_t sent = 0, refused = 0, points = 0;
  auto next = std::chrono::steady_clock::now();
  for (int loop = 0; (loops == 0 || loop < loops) && !g_stop.load(); ++loop) {
    for (const std::string& f : files) {
      if (g_stop.load()) break;
      if (Status st = cloud::load_cloud(f, c, scratch); !st) {
        std::fprintf(stderr, "trailnav replay: %s\n", st.message().c_str());
        ++refused;
        continue;
      }
      if (!o.max_rate) std::this_thread::sleep_until(next);
      next += std::chrono::duration_cast<std::chrono::steady_clock::duration>(period);
      const auto stamp = std::chrono::duration_cast<std::chrono::nanoseconds>(
                             std::chrono::system_clock::now().time_since_epoch()).count();
      if (Status st = sender.sender->send(c, stamp); !st) {
        std::fprintf(stderr, "trailnav replay: %s\n", st.message().c_str());
        ++refused;
        continue;
      }
      ++sent;
      points += c.size;
      if (!o.quiet) progress.update(static_cast<double>(sent + refused));
    }
  }
  if (!o.quiet) progress.finish();
  // The last clouds delivered (acknowledged) before the domain goes.
  if (sent > 0 && !sender.sender->wait_for_acks(2.0)) {
    std::fprintf(stderr, "trailnav replay: the last clouds were not acknowledged within 2 s\n");
  }
  std::fprintf(stderr, "trailnav replay: %llu clouds sent (%llu points), %llu files not sent%s\n",
               static_cast<unsigned long long>(sent), static_cast<unsigned long long>(points),
               static_cast<unsigned long long>(refused), g_stop.load() ? ", stopped" : "");
  return refused > 0 ? 1 : 0;
}

int run_replay(const ReplayCliOptions& o) {
  if (o.clouds) return run_cloud_replay(o);
  replay::ReplayOptions options;
  options.rate = o.rate;
  options.max_rate = o.max_rate;
  options.loops = o.forever ? 0 : o.loops;
  options.skip_s = o.skip;
  options.duration_s = o.duration;
  options.can_interface = o.can_interface;
  options.stop = &g_stop;
  std::string error;
  auto target = [&](const std::string& stream, const std::string& text) {
    auto endpoint = udp::parse_endpoint(text, error);
    if (!endpoint) {
      std::fprintf(stderr, "trailnav replay: %s\n", error.c_str());
      return false;
    }
    options.udp_targets[stream] = *endpoint;
    return true;
  };
  if (!o.lidar_to.empty() && !target("lidar", o.lidar_to)) return 2;
  if (!o.position_to.empty() && !target("lidar-position", o.position_to)) return 2;
  for (const std::string& t : o.to) {
    std::string name, value;
    if (!split_assignment(t, name, value)) {
      std::fprintf(stderr, "trailnav replay: --to wants STREAM=ADDRESS:PORT, not '%s'\n", t.c_str());
      return 2;
    }
    if (!target(name, value)) return 2;
  }
  for (const std::string& l : o.serial_links) {
    std::string name, value;
    if (!split_assignment(l, name, value)) {
      std::fprintf(stderr, "trailnav replay: --serial-link wants STREAM=PATH, not '%s'\n", l.c_str());
      return 2;
    }
    options.serial_links[name] = value;
  }
  auto tunnel = udp::parse_endpoint(o.can_tunnel, error);
  if (!tunnel) {
    std::fprintf(stderr, "trailnav replay: --can-tunnel: %s\n", error.c_str());
    return 2;
  }
  options.can_tunnel = *tunnel;
  auto gpio_tunnel = udp::parse_endpoint(o.gpio_tunnel, error);
  if (!gpio_tunnel) {
    std::fprintf(stderr, "trailnav replay: --gpio-tunnel: %s\n", error.c_str());
    return 2;
  }
  options.gpio_tunnel = *gpio_tunnel;
  auto image_tunnel = udp::parse_endpoint(o.image_tunnel, error);
  if (!image_tunnel) {
    std::fprintf(stderr, "trailnav replay: --image-tunnel: %s\n", error.c_str());
    return 2;
  }
  options.image_tunnel = *image_tunnel;
  for (const std::string& f : o.faults) {
    const replay::FaultSpecResult parsed = replay::parse_fault_spec(f);
    if (!parsed.spec) {
      std::fprintf(stderr, "trailnav replay: --fault: %s\n", parsed.error.c_str());
      return 2;
    }
    options.faults.push_back(*parsed.spec);
  }
  options.fault_seed = o.fault_seed;

  ProgressBar progress("replay", 100.0, "%");
  if (!o.quiet) options.progress = [&](double part) { progress.update(part * 100.0); };

  auto created = replay::Replayer::create(o.input, options);
  if (!created.replayer) {
    std::fprintf(stderr, "trailnav replay: %s\n", created.error.c_str());
    return 2;
  }
  char speed[32];
  std::snprintf(speed, sizeof speed, "%gx speed", o.rate);
  std::fprintf(stderr, "trailnav replay: %s at %s%s\n", o.input.c_str(), o.max_rate ? "maximum rate" : speed,
               o.forever ? ", looping until stopped" : "");
  for (const auto& s : created.replayer->streams()) {
    std::fprintf(stderr, "  %-16s %-6s -> %s\n", s.name.c_str(), recording::stream_kind_name(s.kind), s.target.c_str());
  }
  std::fflush(stderr);

  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  const replay::ReplayReport report = created.replayer->run();
  if (!o.quiet) progress.finish();

  std::uint64_t failures = 0;
  std::fprintf(stderr, "trailnav replay: %.3f s of recording in %.3f s (%d loop%s)%s\n", report.recording_s, report.wall_s,
               report.loops, report.loops == 1 ? "" : "s", g_stop.load() ? ", stopped" : "");
  std::fprintf(stderr, "  %-16s %10s %12s %9s\n", "stream", "sent", "bytes", "failed");
  for (const auto& s : report.streams) {
    std::fprintf(stderr, "  %-16s %10llu %12llu %9llu\n", s.name.c_str(), static_cast<unsigned long long>(s.sent),
                 static_cast<unsigned long long>(s.bytes), static_cast<unsigned long long>(s.failures));
    failures += s.failures;
  }
  if (report.send_error.count > 0) {
    std::fprintf(stderr, "  send-time error: p50 %.1f us, p99 %.1f us, max %.1f us; %llu sends over 1 ms late\n",
                 us(report.send_error.p50), us(report.send_error.p99), us(report.send_error.max),
                 static_cast<unsigned long long>(report.late_over_1ms));
  }
  if (!report.faults.empty()) {
    std::fprintf(stderr, "  faults (seed %llu): %s", static_cast<unsigned long long>(o.fault_seed), "");
    for (const auto& f : o.faults) std::fprintf(stderr, " %s", f.c_str());
    std::fprintf(stderr, "\n  %-16s %9s %9s %8s %8s %9s %9s %9s %9s %8s %8s %8s\n", "stream", "events", "sent", "lost",
                 "silenced", "reordered", "duplicated", "truncated", "corrupted", "shifted", "stepped", "injected");
    for (const auto& c : report.faults) {
      if (c.events == c.sent && c.lost + c.silenced + c.reordered + c.duplicated + c.truncated + c.corrupted + c.shifted +
                                        c.stepped + c.injected == 0) {
        continue;
      }
      auto u = [](std::uint64_t v) { return static_cast<unsigned long long>(v); };
      std::fprintf(stderr, "  %-16s %9llu %9llu %8llu %8llu %9llu %9llu %9llu %9llu %8llu %8llu %8llu\n", c.stream.c_str(),
                   u(c.events), u(c.sent), u(c.lost), u(c.silenced), u(c.reordered), u(c.duplicated), u(c.truncated),
                   u(c.corrupted), u(c.shifted), u(c.stepped), u(c.injected));
    }
  }
  if (report.bad_lines > 0) {
    std::fprintf(stderr, "  %llu unparsable log lines skipped\n", static_cast<unsigned long long>(report.bad_lines));
  }
  if (failures > 0) {
    std::fprintf(stderr,
                 "  failed sends: datagrams the kernel refused (send buffer full), or bytes for a\n"
                 "  pseudo-terminal whose buffer was full because nobody read it\n");
  }
  return 0;
}

}  // namespace

void add_replay_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "replay",
      "Re-send a bench recording with its original timing: UDP streams to loopback ports, serial\n"
      "streams into pseudo-terminals (their paths are printed), CAN frames onto a SocketCAN\n"
      "interface (--can-interface) or into the UDP tunnel on loopback. The input is a recording\n"
      "directory (docs/recording.md) or a bare pcap, pcapng or raw Velodyne file, whose UDP streams\n"
      "are named by port: 2368 lidar, 8308 lidar-position, others udp-<port>.\n"
      "Destinations must be loopback addresses (127.0.0.0/8).");
  static ReplayCliOptions o;
  cmd->add_option("input", o.input, "Recording directory, or pcap/pcapng/raw file; with --clouds point-cloud files")->required();
  auto* rate = cmd->add_option("--rate", o.rate, "Speed-up over the recorded timing")->capture_default_str()->check(
      CLI::PositiveNumber);
  cmd->add_flag("--max-rate", o.max_rate, "Send as fast as possible (no timing)")->excludes(rate);
  auto* loops = cmd->add_option("--loops", o.loops, "Play the recording this many times")->capture_default_str()->check(
      CLI::PositiveNumber);
  cmd->add_flag("--loop", o.forever, "Play it again and again until Ctrl-C")->excludes(loops);
  cmd->add_option("--lidar-to", o.lidar_to, "Destination of the 'lidar' stream (default 127.0.0.1:<recorded port>)");
  cmd->add_option("--position-to", o.position_to, "Destination of the 'lidar-position' stream");
  cmd->add_option("--to", o.to,
                  "STREAM=ADDRESS:PORT for any UDP stream; for a serial stream, its bytes go there as UDP\n"
                  "datagrams instead of into a pseudo-terminal, as a serial device server sends them\n"
                  "(the driver's link: udp:ADDRESS:PORT) (repeatable)");
  cmd->add_option("--can-interface", o.can_interface, "Send CAN frames onto this SocketCAN interface (e.g. vcan0)");
  cmd->add_option("--can-tunnel", o.can_tunnel, "Where the CAN tunnel sends when there is no --can-interface")
      ->capture_default_str();
  cmd->add_option("--gpio-tunnel", o.gpio_tunnel, "Where GPIO streams (e-stop levels) are sent, as GPIO tunnel datagrams")
      ->capture_default_str();
  cmd->add_option("--image-tunnel", o.image_tunnel,
                  "Where image streams (camera frames) are sent, as image tunnel fragments (trailnavd's camera.input: "
                  "tunnel)")
      ->capture_default_str();
  cmd->add_option("--serial-link", o.serial_links, "STREAM=PATH: a symlink to the stream's pseudo-terminal (repeatable)");
  cmd->add_option("--skip", o.skip, "Start this many seconds into the recording")->check(CLI::NonNegativeNumber);
  cmd->add_option("--duration", o.duration, "Replay only this many seconds (0: all)")->check(CLI::NonNegativeNumber);
  cmd->add_option("--fault", o.faults,
                  "STREAM:FAULT[=VALUE][,OPTION=VALUE]...[@FROM[+FOR]]: inject a fault into a stream on its way\n"
                  "out (repeatable; docs/recording.md#faults). FAULT: loss=P[,burst=N], reorder=P[,depth=N],\n"
                  "duplicate=P, truncate=P, corrupt=P[,bytes=K], silence=S, outage=S[,jump=M] and jump=M\n"
                  "(NMEA), bus-off=S (CAN), clock-step=S (Velodyne). P a probability, S seconds, M metres\n"
                  "north; FROM/FOR seconds from the replay's start. E.g. --fault lidar:loss=0.05,burst=10@5+10\n"
                  "--fault gps:outage=10,jump=50@8 --fault wheels:bus-off=3@12");
  cmd->add_option("--fault-seed", o.fault_seed, "Seed of the random faults: the same seed, the same faults")
      ->capture_default_str();
  cmd->add_flag("--quiet", o.quiet, "No progress bar");
  cmd->add_flag("--clouds", o.clouds,
                "The input is a point-cloud file or a directory of them (.bin KITTI, .pcd, .ply, in name order):\n"
                "send each as a sensor_msgs/PointCloud2 over DDS, 10 per second times --rate, to a trailnavd\n"
                "whose lidar section says `input: pointcloud2` (docs/pointcloud.md)");
  cmd->add_option("--topic", o.topic, "With --clouds: the topic (DDS rt/<topic>)")->capture_default_str();
  cmd->add_option("--domain", o.domain, "With --clouds: the DDS domain")->capture_default_str();
  cmd->add_option("--cyclone-config", o.cyclone_config,
                  "With --clouds: a Cyclone DDS XML file (default: loopback only, no multicast)");
  cmd->add_option("--frame", o.frame, "With --clouds: the clouds' header.frame_id")->capture_default_str();
  cmd->callback([] {
    const int code = run_replay(o);
    if (code != 0) throw CLI::RuntimeError(code);
  });
}

}  // namespace trailnav::cli
