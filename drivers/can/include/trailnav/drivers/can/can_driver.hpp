// The CAN driver task: receives frames from a SocketCAN interface (raw
// socket, kernel receive filters for the odometry's ids, kernel timestamps,
// error frames) or, on machines without CAN, from trailnav's UDP tunnel
// (what `trailnav replay` sends), turns the robot's wheel frames into
// odometry and publishes it. A bus that goes off or an interface that goes
// down is counted and reopened after a back-off. Everything is allocated by
// create().
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>

#include "trailnav/drivers/can/wheel_odometry.hpp"
#include "trailnav/drivers/udp/udp_receiver.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/status_board.hpp"
#include "trailnav/runtime/spsc_queue.hpp"

namespace trailnav::can {

enum class CanTransport : std::uint8_t { socketcan, tunnel };
const char* can_transport_name(CanTransport t) noexcept;

struct CanDriverOptions {
  std::string name = "can";
  CanTransport transport = CanTransport::tunnel;
  std::string interface = "can0";                     // socketcan
  udp::Endpoint tunnel{0x7F000001u, kDefaultTunnelPort};  // tunnel: address to listen on
  // Tunnel: time frames by the recording's timestamps in the datagrams rather
  // than on arrival (replays faster or slower than real time).
  bool tunnel_recorded_time = false;
  WheelOdometryOptions odometry;
  double backoff = 0.5;       // s before reopening a failed interface, doubling ...
  double max_backoff = 8.0;   // ... up to this
  double data_timeout = 0.5;  // s without an odometry reading before health drops to no_data
  double bus_error_hold = 2.0;  // s health stays bus_error after a bus-off or error-passive report
  int max_frames_per_run = 512;
};

enum class CanHealth : std::uint8_t { no_link, no_data, bus_error, ok };
const char* can_health_name(CanHealth h) noexcept;

inline constexpr std::size_t kOdometryQueueCapacity = 512;

struct CanDriverStatus {
  CanHealth health = CanHealth::no_link;
  bool open = false;
  std::uint64_t opens = 0, open_failures = 0, closes = 0;
  std::uint64_t frames = 0;          // received, all ids
  std::uint64_t malformed = 0;       // tunnel datagrams or socket reads that are not frames
  std::uint64_t error_frames = 0;
  std::uint64_t bus_off = 0, error_passive = 0, error_warning = 0, restarted = 0, tx_timeouts = 0;
  std::uint64_t kernel_drops = 0;    // frames the kernel dropped (socket buffer full)
  std::uint64_t queue_drops = 0;
  OdometryCounters odometry_counters;
  OdometryState odometry;
  std::array<char, 160> last_error{};
};

class CanDriver final : public Task {
 public:
  struct Created;
  // Loads nothing itself: takes the robot's DBC, already parsed.
  static Created create(const Dbc& dbc, const CanDriverOptions& options);
  ~CanDriver() override;
  CanDriver(const CanDriver&) = delete;
  CanDriver& operator=(const CanDriver&) = delete;

  void run(const TaskTick& tick) override;

  Mailbox<OdometryState>& latest() noexcept { return latest_; }
  SpscQueue<OdometryState, kOdometryQueueCapacity>& readings() noexcept { return queue_; }
  CanDriverStatus status() const noexcept;
  const CanDriverOptions& options() const noexcept { return options_; }
  udp::Endpoint tunnel_endpoint() const noexcept;

 private:
  CanDriver(const CanDriverOptions& options, std::unique_ptr<WheelOdometry> odometry);
  void on_frame(const Frame& frame, Nanos now) noexcept;
  void on_error_frame(const Frame& frame, Nanos now) noexcept;
  void open_socketcan(Nanos now) noexcept;
  void fail(Nanos now, const char* what, int err) noexcept;
  void read_socketcan(Nanos now) noexcept;
  void publish_status(Nanos now) noexcept;

  CanDriverOptions options_;
  std::unique_ptr<WheelOdometry> odometry_;
  std::unique_ptr<udp::UdpReceiver> tunnel_;
  int fd_ = -1;
  std::array<std::uint32_t, 4> filter_ids_{};
  std::size_t filter_count_ = 0;
  Nanos next_attempt_ = 0;
  double current_backoff_ = 0.0;
  Nanos last_reading_ = -1;
  Nanos last_bus_error_ = -1;
  std::uint32_t last_overflow_ = 0;
  Mailbox<OdometryState> latest_;
  SpscQueue<OdometryState, kOdometryQueueCapacity> queue_;
  CanDriverStatus local_;
  StatusBoard<CanDriverStatus> shared_;
};

struct CanDriver::Created {
  std::unique_ptr<CanDriver> driver;
  std::string error;
};

}  // namespace trailnav::can
