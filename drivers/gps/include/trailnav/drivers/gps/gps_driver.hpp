// The GPS driver task: reads NMEA 0183 from a serial port, UDP or TCP (see
// link::ByteLink), frames and assembles it into fixes and publishes each
// fix through a Mailbox, with health and counters readable from any thread.
// Runs periodically on the scheduler (50-100 Hz is plenty); everything is
// allocated by create().
//
// An epoch's fix is published as soon as its burst of sentences has ended
// (no byte for epoch_gap) instead of when the next epoch's first sentence
// arrives, so a 1 Hz receiver's fix is not a second late.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>

#include "trailnav/drivers/gps/fix.hpp"
#include "trailnav/drivers/link/byte_link.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/status_board.hpp"

namespace trailnav::gps {

struct GpsDriverOptions {
  std::string name = "gps";
  link::LinkOptions link;
  double epoch_gap = 0.04;    // s of quiet that ends an epoch's burst of sentences
  double fix_timeout = 2.0;   // s without a 2D/3D fix before health drops to no_fix
};

enum class GpsHealth : std::uint8_t {
  no_link,   // the port cannot be opened / the server is not there
  no_data,   // open, but no sentence for the link's silence timeout
  no_fix,    // sentences arrive, none with a usable position lately
  fix,       // a 2D or 3D fix within fix_timeout
};
const char* gps_health_name(GpsHealth h) noexcept;

struct GpsReading {
  std::int64_t receive_ns = 0;  // host time (runtime/host_clock.hpp) when the epoch's last bytes arrived
  GpsFix fix;
};

struct GpsDriverStatus {
  GpsHealth health = GpsHealth::no_link;
  link::LinkState link_state = link::LinkState::closed;
  link::LinkCounters link;
  std::uint16_t udp_port = 0;  // udp links: the port bound (chosen by the kernel when 0)
  GpsCounters gps;
  std::uint64_t overlong_lines = 0;
  std::uint64_t published = 0;
  double last_fix_age = -1.0;  // s since the last fix with a position; -1 before the first
  std::array<char, 160> last_link_error{};
};

class GpsDriver final : public Task {
 public:
  struct Created;
  static Created create(const GpsDriverOptions& options);
  GpsDriver(const GpsDriver&) = delete;
  GpsDriver& operator=(const GpsDriver&) = delete;

  void run(const TaskTick& tick) override;

  Mailbox<GpsReading>& fixes() noexcept { return fixes_; }
  GpsDriverStatus status() const noexcept;
  const GpsDriverOptions& options() const noexcept { return options_; }

 private:
  GpsDriver(const GpsDriverOptions& options, std::unique_ptr<link::ByteLink> link);
  void publish(const GpsFix& fix, Nanos now) noexcept;
  void publish_status(Nanos now) noexcept;

  GpsDriverOptions options_;
  std::unique_ptr<link::ByteLink> link_;
  LineFramer framer_;
  FixAssembler assembler_;
  GpsFix completed_;
  Mailbox<GpsReading> fixes_;
  bool epoch_open_ = false;
  Nanos last_fix_ = -1;
  std::int64_t last_receive_ns_ = 0;
  GpsDriverStatus local_;
  StatusBoard<GpsDriverStatus> shared_;
};

struct GpsDriver::Created {
  std::unique_ptr<GpsDriver> driver;
  std::string error;
};

}  // namespace trailnav::gps
