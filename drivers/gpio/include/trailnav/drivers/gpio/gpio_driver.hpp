// The GPIO driver task: the emergency-stop input and the heartbeat and status
// outputs of the robot PC.
//
// On the robot the lines are found by name on a GPIO chip through libgpiod
// (chip given as name, path, label or number, as gpiodetect shows them); the
// e-stop line is requested for edge events, the outputs as outputs. Every
// edge engages the stop at once (a press too short to be seen as a level
// still stops the robot), and the level read after the edges decides when the
// debounced release may come (estop.hpp). On the bench, without a chip, the
// line levels come through trailnav's UDP tunnel (line_tunnel.hpp) from the
// replayer, and output changes can be mirrored to a loopback address.
//
// Outputs: the heartbeat toggles every `heartbeat_period` while the task
// runs, so an external watchdog sees a stalled scheduler; the status line is
// on while the system reports ready (set_ready) and the e-stop is released.
// Chip, lines and sockets are opened and everything is allocated by create();
// a chip that fails later is reported (health `failed`, e-stop unknown, which
// counts as engaged) and not reopened: the service restarts.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "trailnav/drivers/gpio/estop.hpp"
#include "trailnav/drivers/gpio/line_tunnel.hpp"
#include "trailnav/drivers/udp/udp_receiver.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/status_board.hpp"

struct gpiod_chip;
struct gpiod_line;

namespace trailnav::udp {
class UdpSender;
}

namespace trailnav::gpio {

enum class GpioTransport : std::uint8_t { chip, tunnel };
const char* gpio_transport_name(GpioTransport t) noexcept;

enum class LineBias : std::uint8_t { as_is, disable, pull_up, pull_down };
const char* line_bias_name(LineBias b) noexcept;

struct GpioDriverOptions {
  std::string name = "gpio";
  GpioTransport transport = GpioTransport::chip;
  std::string chip = "gpiochip0";   // chip: name, /dev path, label or number
  std::string consumer = "trailnav";  // shown by gpioinfo as the lines' user
  std::string estop_line = "ESTOP";   // empty: no e-stop input
  bool estop_active_low = false;      // a pressed e-stop pulls the line low
  LineBias estop_bias = LineBias::as_is;
  double estop_release_debounce = 0.2;  // s the line must stay inactive before the stop is released
  std::string heartbeat_line;           // empty: no heartbeat output
  double heartbeat_period = 0.5;        // s between toggles
  // While nothing happens on the e-stop line, the task sleeps up to this
  // long between runs (Task::rest), woken at once by an edge (chip) or a
  // datagram (tunnel), and in time for the heartbeat and a debounced
  // release. The status output follows set_ready within it. 0: run every
  // period of the task (each wake-up costs CPU: docs/performance.md).
  double max_rest = 0.05;
  std::string status_line;              // empty: no status output
  bool outputs_active_low = false;
  udp::Endpoint tunnel{0x7F000001u, kDefaultTunnelPort};  // tunnel: address to listen on
  std::optional<udp::Endpoint> tunnel_outputs;            // tunnel: mirror output changes here (loopback)
};

enum class GpioHealth : std::uint8_t { ok, failed };
const char* gpio_health_name(GpioHealth h) noexcept;

struct EstopReading {
  EstopState state = EstopState::unknown;
  Nanos since = -1;  // runtime clock; -1 while unknown
  std::uint64_t engagements = 0;
};

struct GpioDriverStatus {
  GpioHealth health = GpioHealth::ok;
  EstopState estop = EstopState::unknown;
  EstopCounters estop_counters;
  std::uint64_t edges = 0;            // chip: edge events read
  std::uint64_t tunnel_levels = 0;    // tunnel: level datagrams for the e-stop line
  std::uint64_t malformed = 0;        // tunnel: datagrams that are not line levels
  std::uint64_t unknown_lines = 0;    // tunnel: levels for lines this driver does not read
  std::uint64_t read_errors = 0;
  std::uint64_t write_errors = 0;
  std::uint64_t heartbeat_toggles = 0;
  bool heartbeat = false;
  bool status_output = false;
  bool ready = false;
  std::array<char, 200> last_error{};
};

class GpioDriver final : public Task {
 public:
  struct Created;
  // Errors name the chip and the line (and list what the chip has).
  static Created create(const GpioDriverOptions& options);
  ~GpioDriver() override;
  GpioDriver(const GpioDriver&) = delete;
  GpioDriver& operator=(const GpioDriver&) = delete;

  void run(const TaskTick& tick) override;
  // Until the next heartbeat toggle or debounced release, at most
  // options().max_rest; 0 once the chip failed (its descriptor is not read).
  Nanos rest() noexcept override;
  // The e-stop line's event descriptor (chip) or the tunnel's socket.
  int wake_fd() const noexcept override { return wake_fd_; }

  // The rest of the system says whether it is ready to drive (any thread).
  void set_ready(bool ready) noexcept { ready_.store(ready, std::memory_order_relaxed); }

  Mailbox<EstopReading>& estop() noexcept { return estop_; }
  GpioDriverStatus status() const noexcept { return shared_.read(); }
  const GpioDriverOptions& options() const noexcept { return options_; }
  udp::Endpoint tunnel_endpoint() const noexcept;

 private:
  explicit GpioDriver(const GpioDriverOptions& options);
  void read_chip(Nanos now) noexcept;
  void read_tunnel(Nanos now) noexcept;
  void drive_outputs(Nanos now) noexcept;
  void set_output(gpiod_line* line, const std::string& name, bool value) noexcept;
  void fail(const char* what, int err) noexcept;

  GpioDriverOptions options_;
  EstopDebouncer debouncer_;
  gpiod_chip* chip_ = nullptr;
  gpiod_line* estop_line_ = nullptr;
  gpiod_line* heartbeat_line_ = nullptr;
  gpiod_line* status_line_ = nullptr;
  std::unique_ptr<udp::UdpReceiver> tunnel_;
  std::unique_ptr<udp::UdpSender> mirror_;
  std::atomic<bool> ready_{false};
  Nanos next_toggle_ = -1;
  Nanos last_run_ = 0;
  int wake_fd_ = -1;
  bool status_written_ = false;
  EstopState published_state_ = EstopState::unknown;
  bool published_once_ = false;
  Mailbox<EstopReading> estop_;
  GpioDriverStatus local_;
  StatusBoard<GpioDriverStatus> shared_;
};

struct GpioDriver::Created {
  std::unique_ptr<GpioDriver> driver;
  std::string error;
};

}  // namespace trailnav::gpio
