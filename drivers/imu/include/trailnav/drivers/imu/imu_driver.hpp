// The IMU driver task: reads an Xsens MTi (MT binary protocol) or a device
// speaking trailnav's $TNIMU lines over a serial port, UDP or TCP, decodes
// every sample, runs the attitude filter and publishes
//   - every sample with its attitude into a queue (for pose estimation), and
//   - the newest one through a Mailbox (for gravity alignment),
// with health and counters readable from any thread. Periodic on the
// scheduler (at least the IMU's rate / 8: the queue takes the rest); all
// memory is allocated by create().
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>

#include "trailnav/drivers/imu/attitude.hpp"
#include "trailnav/drivers/imu/stream_decoder.hpp"
#include "trailnav/drivers/link/byte_link.hpp"
#include "trailnav/runtime/clock_relation.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/status_board.hpp"
#include "trailnav/runtime/spsc_queue.hpp"

namespace trailnav::imu {

struct ImuDriverOptions {
  std::string name = "imu";
  link::LinkOptions link;
  ImuProtocol protocol = ImuProtocol::xsens;
  AttitudeOptions attitude;
  // Xsens: on every (re)connection put the device into measurement mode,
  // first writing this output configuration when it is not empty.
  bool xsens_start = false;
  std::array<OutputItem, 8> xsens_outputs{};
  std::size_t xsens_output_count = 0;
  double data_timeout = 0.5;  // s without a sample before health drops to no_data
};

enum class ImuHealth : std::uint8_t {
  no_link,
  no_data,       // open, but no decodable sample within data_timeout
  device_error,  // the device reported an error in the last data_timeout
  ok,
};
const char* imu_health_name(ImuHealth h) noexcept;

struct ImuReading {
  ImuSample sample;
  Attitude attitude;
};

inline constexpr std::size_t kImuQueueCapacity = 1024;  // 2.5 s at 400 Hz

struct ImuDriverStatus {
  ImuHealth health = ImuHealth::no_link;
  link::LinkState link_state = link::LinkState::closed;
  link::LinkCounters link;
  std::uint16_t udp_port = 0;  // udp links: the port bound (chosen by the kernel when 0)
  ImuStreamCounters stream;  // bytes to samples: messages, rejections by reason, device errors
  std::uint64_t queue_drops = 0;  // samples the consumer did not take in time
  AttitudeCounters attitude_counters;
  Attitude attitude;
  // The device's sample clock (Xsens SampleTimeFine, 10 kHz) against the
  // host receive times of its bytes. Readings are stamped on it (put on the
  // host clock); the spread is how late their bytes typically arrived
  // (docs/dds.md, "One clock"). Not valid without a sample counter (the
  // line protocol: readings keep their receive times).
  ClockRelationState device_clock;
  std::array<char, 160> last_link_error{};
};

class ImuDriver final : public Task {
 public:
  struct Created;
  static Created create(const ImuDriverOptions& options);
  ImuDriver(const ImuDriver&) = delete;
  ImuDriver& operator=(const ImuDriver&) = delete;

  void run(const TaskTick& tick) override;

  Mailbox<ImuReading>& latest() noexcept { return latest_; }
  SpscQueue<ImuReading, kImuQueueCapacity>& readings() noexcept { return queue_; }
  AttitudeFilter& filter() noexcept { return filter_; }  // for odometry hints, from the driver's thread only
  ImuDriverStatus status() const noexcept;
  const ImuDriverOptions& options() const noexcept { return options_; }

 private:
  ImuDriver(const ImuDriverOptions& options, std::unique_ptr<link::ByteLink> link);
  void on_sample(const ImuSample& s, Nanos now) noexcept;
  void start_device() noexcept;
  void publish_status(Nanos now) noexcept;

  ImuDriverOptions options_;
  std::unique_ptr<link::ByteLink> link_;
  ImuStreamDecoder decoder_;
  AttitudeFilter filter_;
  Mailbox<ImuReading> latest_;
  SpscQueue<ImuReading, kImuQueueCapacity> queue_;
  std::array<std::uint8_t, 64> command_{};
  Nanos last_sample_ = -1;
  ClockRelation device_clock_;
  bool have_ticks_ = false;
  std::uint32_t last_ticks_ = 0;
  std::int64_t device_ns_ = 0;  // the sample counter unwrapped, ns
  Nanos last_device_error_ = -1;
  ImuDriverStatus local_;
  StatusBoard<ImuDriverStatus> shared_;
};

struct ImuDriver::Created {
  std::unique_ptr<ImuDriver> driver;
  std::string error;
};

}  // namespace trailnav::imu
