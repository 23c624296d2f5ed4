#include "replayer.hpp"

#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>

namespace trailnav::replay {
namespace {

using recording::CanFrame;
using recording::StreamKind;

std::int64_t monotonic_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// Sleeps to an absolute CLOCK_MONOTONIC time; the last 100 us are spun for
// accuracy (the kernel's wake-up alone is late by 50 us or more).
void wait_until(std::int64_t target) noexcept {
  constexpr std::int64_t kSpin = 100'000;
  if (target - monotonic_ns() > kSpin) {
    const std::int64_t wake = target - kSpin;
    timespec ts{static_cast<time_t>(wake / 1'000'000'000), static_cast<long>(wake % 1'000'000'000)};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    }
  }
  while (monotonic_ns() < target) {
  }
}

}  // namespace

struct Replayer::Output {
  virtual ~Output() = default;
  // False when the frame or bytes could not be delivered.
  virtual bool send(const recording::Event& event) = 0;
};

namespace {

struct UdpOutput final : Replayer::Output {
  std::unique_ptr<udp::UdpSender> sender;
  bool send(const recording::Event& e) override { return sender->send(e.payload); }
};

struct GpioTunnelOutput final : Replayer::Output {
  std::shared_ptr<udp::UdpSender> sender;
  bool send(const recording::Event& e) override {
    const std::string_view line(reinterpret_cast<const char*>(e.payload.data()), e.payload.size());
    const gpio::TunnelDatagram d = gpio::encode_tunnel(line, e.gpio_value, e.time_ns);
    return d.size > 0 && sender->send(d.view());
  }
};

// A camera frame as the image tunnel's fragments, back to back.
struct ImageTunnelOutput final : Replayer::Output {
  std::shared_ptr<udp::UdpSender> sender;
  bool send(const recording::Event& e) override {
    const std::size_t n = drivers::camera::fragment_count(e.image_width, e.image_height);
    if (n == 0) return false;
    for (std::size_t i = 0; i < n; ++i) {
      const drivers::camera::TunnelFragment f = drivers::camera::encode_fragment(
          e.payload, e.image_width, e.image_height, e.image_sequence, e.time_ns, i);
      if (f.size == 0 || !sender->send(f.view())) return false;
    }
    return true;
  }
};

struct CanTunnelOutput final : Replayer::Output {
  std::shared_ptr<udp::UdpSender> sender;
  bool send(const recording::Event& e) override { return sender->send(can::encode_tunnel(*e.can).view()); }
};

struct SocketCanOutput final : Replayer::Output {
  int fd = -1;
  ~SocketCanOutput() override {
    if (fd >= 0) close(fd);
  }
  bool send(const recording::Event& e) override {
    const CanFrame& f = *e.can;
    if (f.fd) {
      canfd_frame frame{};
      frame.can_id = f.id;
      frame.len = f.length;
      frame.flags = f.fd_flags;
      std::memcpy(frame.data, f.data.data(), f.length);
      return write(fd, &frame, sizeof frame) == static_cast<ssize_t>(sizeof frame);
    }
    can_frame frame{};
    frame.can_id = f.id;
    frame.len = f.length;
    std::memcpy(frame.data, f.data.data(), f.length);
    return write(fd, &frame, sizeof frame) == static_cast<ssize_t>(sizeof frame);
  }
};

struct PtyOutput final : Replayer::Output {
  int master = -1;
  int slave = -1;  // held open so the terminal lives while nobody has opened it
  std::string path;
  std::string link;
  ~PtyOutput() override {
    if (!link.empty()) unlink(link.c_str());
    if (slave >= 0) close(slave);
    if (master >= 0) close(master);
  }
  bool send(const recording::Event& e) override {
    const ssize_t n = write(master, e.payload.data(), e.payload.size());
    return n == static_cast<ssize_t>(e.payload.size());
  }
};

std::string open_pty(PtyOutput& pty, int baud) {
  pty.master = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (pty.master < 0 || grantpt(pty.master) != 0 || unlockpt(pty.master) != 0) {
    return std::string("cannot create a pseudo-terminal: ") + std::strerror(errno);
  }
  char name[128] = {};
  if (ptsname_r(pty.master, name, sizeof name) != 0) return std::string("ptsname: ") + std::strerror(errno);
  pty.path = name;
  pty.slave = ::open(name, O_RDWR | O_NOCTTY | O_CLOEXEC);
  if (pty.slave < 0) return "cannot open " + pty.path + ": " + std::strerror(errno);
  // Raw bytes, no echo, no line editing: what a serial device gives.
  termios t{};
  tcgetattr(pty.slave, &t);
  cfmakeraw(&t);
  speed_t speed = B115200;
  switch (baud) {
    case 9600: speed = B9600; break;
    case 19200: speed = B19200; break;
    case 38400: speed = B38400; break;
    case 57600: speed = B57600; break;
    case 230400: speed = B230400; break;
    case 460800: speed = B460800; break;
    case 921600: speed = B921600; break;
    default: break;
  }
  cfsetspeed(&t, speed);
  tcsetattr(pty.slave, TCSANOW, &t);
  return "";
}

}  // namespace

Replayer::~Replayer() = default;

std::string Replayer::pty_path(const std::string& stream) const {
  for (const StreamReport& s : report_.streams) {
    // A serial stream sent as UDP datagrams has no pseudo-terminal.
    if (s.name == stream && s.kind == StreamKind::serial) return options_.udp_targets.count(stream) != 0 ? "" : s.target;
  }
  return "";
}

Replayer::Created Replayer::create(const std::string& path, const ReplayOptions& options) {
  Created result;
  if (!(options.rate > 0.0) && !options.max_rate) {
    result.error = "the rate must be positive";
    return result;
  }
  auto opened = recording::RecordingReader::open(path);
  if (!opened.reader) {
    result.error = opened.error;
    return result;
  }
  std::unique_ptr<Replayer> r(new Replayer());
  r->path_ = path;
  r->options_ = options;
  r->reader_ = std::move(opened.reader);

  // Every stream an option names must exist, with the kind the option is for.
  auto has = [&](const std::string& name, StreamKind kind) {
    for (const auto& s : r->reader_->streams()) {
      if (s.name == name && s.kind == kind) return true;
    }
    return false;
  };
  auto missing = [&](const std::string& name, StreamKind kind) {
    if (has(name, kind)) return false;
    result.error = std::string("no ") + (kind == StreamKind::udp ? "UDP" : "serial") + " stream '" + name + "' in " + path;
    return true;
  };
  for (const auto& target : options.udp_targets) {
    // A serial stream may go out as UDP datagrams too: its bytes as a serial
    // device server on the robot's network would send them.
    const bool serial = has(target.first, StreamKind::serial);
    if (serial && options.serial_links.count(target.first) != 0) {
      result.error = "stream '" + target.first + "': both a UDP destination and a pseudo-terminal link; give one";
      return result;
    }
    if (!serial && missing(target.first, StreamKind::udp)) return result;
  }
  for (const auto& link : options.serial_links) {
    if (missing(link.first, StreamKind::serial)) return result;
  }

  std::shared_ptr<udp::UdpSender> tunnel;
  std::shared_ptr<udp::UdpSender> gpio_tunnel;
  std::shared_ptr<udp::UdpSender> image_tunnel;
  for (const recording::StreamInfo& s : r->reader_->streams()) {
    StreamReport report;
    report.name = s.name;
    report.kind = s.kind;
    // A UDP stream, or a serial stream sent as datagrams (one per recorded read).
    const bool serial_as_udp = s.kind == StreamKind::serial && options.udp_targets.count(s.name) != 0;
    if (s.kind == StreamKind::udp || serial_as_udp) {
      udp::Endpoint target{0x7F000001u, s.port};
      if (auto it = options.udp_targets.find(s.name); it != options.udp_targets.end()) target = it->second;
      auto sender = udp::UdpSender::open(target);
      if (!sender.sender) {
        result.error = "stream '" + s.name + "': " + sender.error;
        return result;
      }
      auto out = std::make_unique<UdpOutput>();
      out->sender = std::move(sender.sender);
      report.target = "udp " + udp::format_endpoint(target) + (serial_as_udp ? " (serial bytes)" : "");
      r->outputs_.push_back(std::move(out));
    } else if (s.kind == StreamKind::can) {
      if (!options.can_interface.empty()) {
        auto out = std::make_unique<SocketCanOutput>();
        out->fd = socket(PF_CAN, SOCK_RAW | SOCK_CLOEXEC, CAN_RAW);
        if (out->fd < 0) {
          result.error = "SocketCAN is not available here (" + std::string(std::strerror(errno)) +
                         "): leave out --can-interface to use the UDP tunnel";
          return result;
        }
        ifreq ifr{};
        std::strncpy(ifr.ifr_name, options.can_interface.c_str(), IFNAMSIZ - 1);
        if (ioctl(out->fd, SIOCGIFINDEX, &ifr) != 0) {
          result.error = "no CAN interface '" + options.can_interface + "': " + std::strerror(errno);
          return result;
        }
        const int on = 1;
        setsockopt(out->fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on);
        sockaddr_can address{};
        address.can_family = AF_CAN;
        address.can_ifindex = ifr.ifr_ifindex;
        if (bind(out->fd, reinterpret_cast<sockaddr*>(&address), sizeof address) != 0) {
          result.error = "cannot bind to " + options.can_interface + ": " + std::strerror(errno);
          return result;
        }
        report.target = "socketcan " + options.can_interface;
        r->outputs_.push_back(std::move(out));
      } else {
        if (!tunnel) {
          auto sender = udp::UdpSender::open(options.can_tunnel);
          if (!sender.sender) {
            result.error = "CAN tunnel: " + sender.error;
            return result;
          }
          tunnel = std::move(sender.sender);
        }
        auto out = std::make_unique<CanTunnelOutput>();
        out->sender = tunnel;
        report.target = "can-tunnel udp " + udp::format_endpoint(options.can_tunnel);
        r->outputs_.push_back(std::move(out));
      }
    } else if (s.kind == StreamKind::gpio) {
      if (!gpio_tunnel) {
        auto sender = udp::UdpSender::open(options.gpio_tunnel);
        if (!sender.sender) {
          result.error = "GPIO tunnel: " + sender.error;
          return result;
        }
        gpio_tunnel = std::move(sender.sender);
      }
      auto out = std::make_unique<GpioTunnelOutput>();
      out->sender = gpio_tunnel;
      report.target = "gpio-tunnel udp " + udp::format_endpoint(options.gpio_tunnel);
      r->outputs_.push_back(std::move(out));
    } else if (s.kind == StreamKind::image) {
      if (!image_tunnel) {
        auto sender = udp::UdpSender::open(options.image_tunnel);
        if (!sender.sender) {
          result.error = "image tunnel: " + sender.error;
          return result;
        }
        image_tunnel = std::move(sender.sender);
      }
      auto out = std::make_unique<ImageTunnelOutput>();
      out->sender = image_tunnel;
      report.target = "image-tunnel udp " + udp::format_endpoint(options.image_tunnel);
      r->outputs_.push_back(std::move(out));
    } else {
      auto out = std::make_unique<PtyOutput>();
      if (std::string error = open_pty(*out, s.baud); !error.empty()) {
        result.error = "stream '" + s.name + "': " + error;
        return result;
      }
      if (auto it = options.serial_links.find(s.name); it != options.serial_links.end()) {
        std::error_code ec;
        if (std::filesystem::exists(std::filesystem::symlink_status(it->second)) &&
            !std::filesystem::is_symlink(std::filesystem::symlink_status(it->second))) {
          result.error = "stream '" + s.name + "': " + it->second + " exists and is not a symlink; not replacing it";
          return result;
        }
        std::filesystem::remove(it->second, ec);
        std::filesystem::create_symlink(out->path, it->second, ec);
        if (ec) {
          result.error = "stream '" + s.name + "': cannot link " + it->second + ": " + ec.message();
          return result;
        }
        out->link = it->second;
      }
      report.target = out->path;
      r->outputs_.push_back(std::move(out));
    }
    r->report_.streams.push_back(report);
  }
  if (!options.faults.empty()) {
    auto made = FaultInjector::create(options.faults, r->reader_->streams(), options.fault_seed);
    if (!made.injector) {
      result.error = made.error;
      return result;
    }
    r->faults_ = std::move(made.injector);
  }
  result.replayer = std::move(r);
  return result;
}

ReplayReport Replayer::run() {
  DurationHistogram errors;
  const std::int64_t skip_ns = static_cast<std::int64_t>(options_.skip_s * 1e9);
  const std::int64_t limit_ns = options_.duration_s > 0.0 ? static_cast<std::int64_t>(options_.duration_s * 1e9) : -1;
  if (options_.started) options_.started();
  const std::int64_t wall_start = monotonic_ns();
  std::int64_t schedule_base = wall_start;  // wall time of the current loop's first event
  std::int64_t covered_ns = 0;
  int loop = 0;
  auto stopped = [&] { return options_.stop != nullptr && options_.stop->load(std::memory_order_relaxed); };
  const FaultInjector::Emit emit = [this](const recording::Event& e) {
    Output& out = *outputs_[static_cast<std::size_t>(e.stream)];
    StreamReport& report = report_.streams[static_cast<std::size_t>(e.stream)];
    if (out.send(e)) {
      ++report.sent;
      report.bytes += e.kind == StreamKind::can ? e.can->length : e.payload.size();
    } else {
      ++report.failures;
    }
  };

  while (!stopped() && (options_.loops == 0 || loop < options_.loops)) {
    if (loop > 0) {
      auto opened = recording::RecordingReader::open(path_);
      if (!opened.reader) break;
      reader_ = std::move(opened.reader);
    }
    std::int64_t first = -1;
    std::int64_t last_offset = 0;
    std::uint64_t events = 0;
    while (!stopped()) {
      auto event = reader_->next();
      if (!event) break;
      if (first < 0) first = event->time_ns;
      const std::int64_t offset = event->time_ns - first;
      if (offset < skip_ns) continue;
      if (limit_ns >= 0 && offset - skip_ns > limit_ns) break;
      last_offset = offset - skip_ns;
      const std::int64_t target =
          schedule_base + static_cast<std::int64_t>(static_cast<double>(last_offset) / options_.rate);
      if (!options_.max_rate) wait_until(target);
      if (faults_) {
        faults_->process(*event, last_offset, emit);
      } else {
        emit(*event);
      }
      if (!options_.max_rate) {
        const std::int64_t error = monotonic_ns() - target;
        errors.record(error);
        if (error > 1'000'000) ++report_.late_over_1ms;
      }
      if (options_.progress && (++events % 512) == 0 && reader_->size() > 0) {
        const double part = static_cast<double>(reader_->position()) / static_cast<double>(reader_->size());
        options_.progress(options_.loops > 0 ? (loop + part) / options_.loops : part);
      }
    }
    if (faults_) {
      faults_->flush(emit);
      faults_->restart_loop();
    }
    report_.bad_lines += reader_->counters().bad_lines;
    report_.unassigned_udp += reader_->counters().unassigned_udp;
    covered_ns += last_offset;
    ++loop;
    // The next loop starts one typical gap after this one's last event.
    schedule_base = options_.max_rate ? monotonic_ns()
                                      : schedule_base + static_cast<std::int64_t>(static_cast<double>(last_offset) / options_.rate) +
                                            1'000'000;
  }
  if (options_.progress) options_.progress(1.0);
  report_.loops = loop;
  report_.recording_s = static_cast<double>(covered_ns) * 1e-9;
  report_.wall_s = static_cast<double>(monotonic_ns() - wall_start) * 1e-9;
  report_.send_error = errors.summary();
  if (faults_) report_.faults = faults_->counters();
  return report_;
}

}  // namespace trailnav::replay
