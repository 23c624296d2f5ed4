// The bench replayer: re-sends a recording with its original timing — UDP
// streams to loopback ports, serial streams into pseudo-terminals, CAN frames
// onto a SocketCAN interface or, where there is none, into a UDP tunnel on
// loopback, GPIO levels into the GPIO tunnel on loopback (format in docs/recording.md). Measures how far each send is from
// its schedule.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "faults.hpp"
#include "trailnav/drivers/camera/image_tunnel.hpp"
#include "trailnav/drivers/gpio/line_tunnel.hpp"
#include "trailnav/drivers/recording/recording.hpp"
#include "trailnav/drivers/udp/udp_sender.hpp"
#include "trailnav/runtime/histogram.hpp"

namespace trailnav::replay {

// CAN frames go out as trailnav's tunnel datagrams (trailnav/drivers/can/frame.hpp),
// GPIO levels as GPIO tunnel datagrams (trailnav/drivers/gpio/line_tunnel.hpp),
// camera frames as image tunnel fragments (trailnav/drivers/camera/image_tunnel.hpp).
inline constexpr std::uint16_t kDefaultCanTunnelPort = can::kDefaultTunnelPort;
inline constexpr std::uint16_t kDefaultGpioTunnelPort = gpio::kDefaultTunnelPort;

struct ReplayOptions {
  double rate = 1.0;       // speed-up over the recorded timing
  bool max_rate = false;   // no waiting at all
  int loops = 1;           // 0: until stopped
  // Per stream name; default 127.0.0.1:<recorded port>. A serial stream named
  // here goes out as UDP datagrams (a serial device server) instead of into a
  // pseudo-terminal.
  std::map<std::string, udp::Endpoint> udp_targets;
  std::string can_interface;                          // SocketCAN interface; empty: the UDP tunnel
  udp::Endpoint can_tunnel{0x7F000001u, kDefaultCanTunnelPort};
  udp::Endpoint gpio_tunnel{0x7F000001u, kDefaultGpioTunnelPort};
  udp::Endpoint image_tunnel{0x7F000001u, drivers::camera::kDefaultImageTunnelPort};  // camera frames (image streams)
  std::map<std::string, std::string> serial_links;    // per stream name: a symlink to its pseudo-terminal
  double skip_s = 0.0;      // start this far into the recording
  double duration_s = 0.0;  // replay only this much (0: all)
  std::vector<FaultSpec> faults;  // injected on the way out (faults.hpp)
  std::uint64_t fault_seed = 1;   // the same seed, the same faults
  const std::atomic<bool>* stop = nullptr;
  std::function<void(double fraction)> progress;  // called now and then with the part done
  std::function<void()> started;  // called once, just before the first event's schedule is fixed
};

struct StreamReport {
  std::string name;
  recording::StreamKind kind;
  std::string target;  // where it goes: address, pseudo-terminal, interface
  std::uint64_t sent = 0;
  std::uint64_t bytes = 0;
  std::uint64_t failures = 0;  // refused by the kernel or a full pseudo-terminal
};

struct ReplayReport {
  std::vector<StreamReport> streams;
  DurationSummary send_error;    // actual minus scheduled send time
  std::uint64_t late_over_1ms = 0;
  double recording_s = 0.0;      // recorded time covered (all loops)
  double wall_s = 0.0;
  int loops = 0;
  std::uint64_t bad_lines = 0;
  std::uint64_t unassigned_udp = 0;
  std::vector<FaultCounters> faults;  // per stream, when faults were injected
};

class Replayer {
 public:
  struct Created;
  // Opens the recording, every socket and every pseudo-terminal.
  static Created create(const std::string& path, const ReplayOptions& options);
  ~Replayer();

  // Where each stream goes (pseudo-terminal paths are known from here on).
  const std::vector<StreamReport>& streams() const noexcept { return report_.streams; }
  std::string pty_path(const std::string& stream) const;  // "" for a serial stream sent as UDP

  // Replays; returns when done or stopped.
  ReplayReport run();

  struct Output;  // one destination (defined in the implementation)

 private:
  Replayer() = default;
  std::string path_;
  ReplayOptions options_;
  std::unique_ptr<recording::RecordingReader> reader_;
  std::vector<std::unique_ptr<Output>> outputs_;  // per stream
  std::unique_ptr<FaultInjector> faults_;
  ReplayReport report_;
};

struct Replayer::Created {
  std::unique_ptr<Replayer> replayer;
  std::string error;
};

}  // namespace trailnav::replay
