// The Velodyne driver task: receives data and position packets over UDP,
// times them, assembles revolutions and publishes each one through a
// Broadcast (one reader per consuming thread). Runs periodically on the scheduler (1 kHz is typical) and drains
// its sockets each run; everything is allocated by create().
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "trailnav/drivers/udp/udp_receiver.hpp"
#include "trailnav/drivers/velodyne/range_image.hpp"
#include "trailnav/drivers/velodyne/sensor_clock.hpp"
#include "trailnav/runtime/broadcast.hpp"
#include "trailnav/runtime/clock_relation.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/status_board.hpp"

namespace trailnav::velodyne {

struct DriverOptions {
  std::string name = "lidar";
  udp::ReceiverOptions data;                     // bind port 2368 by default
  std::optional<udp::ReceiverOptions> position;  // 8308; none: no position packets
  AssemblerOptions assembler;
  SensorClockOptions clock;
  ClockRelationOptions reference;  // the sensor clock against the host's (runtime/clock_relation.hpp)
  int max_batches_per_run = 32;  // bounds one run's work; the rest waits for the next run
  int revolution_readers = 1;    // threads that read revolutions (obstacles, terrain): one slot each
  // Reads at most this far apart while a revolution is in progress, and
  // every period of the task from shortly before its predicted end (rest());
  // 0: every period. The packets wait in the socket meanwhile (HDL-64E: 36
  // packets, about 80 kB of buffer in 10 ms).
  Nanos max_rest_ns = 10 * kNanosPerMilli;
  // From this long before the revolution's predicted end the task wakes as
  // each packet arrives (the data socket readable, Task::watching) as well
  // as every period, so the packet that completes the revolution is read at
  // once instead of at the next period (half a period later on average).
  // 0: every period only.
  Nanos watch_before_end_ns = 0;
  // Follow-up for a reader that works on a revolution while it arrives
  // (trailnavd's obstacle thread, Broadcast::Reader::follow()): the driver
  // stores each run how far the revolution in progress is (the word of
  // revolution_progress(): the assembler's generation, columns final), and
  // signals the revolutions' event this many times a turn (every 1/32 turn
  // in the last of these parts) as well as at the end. 0: only at the end,
  // no progress stored.
  int progress_signals = 0;

  DriverOptions() {
    data.bind.port = 2368;
  }
};

// The newest position packet.
struct PositionSnapshot {
  std::int64_t receive_ns = 0;
  std::uint32_t timestamp_us = 0;
  PpsStatus pps = PpsStatus::absent;
  TimeSource time_source = TimeSource::none;
  std::uint16_t nmea_length = 0;
  std::array<char, kPositionPacketSize> nmea{};
  std::string_view sentence() const noexcept { return {nmea.data(), nmea_length}; }
};

// Everything the driver counts, readable from any thread.
struct DriverCounters {
  udp::ReceiverCounters data;
  udp::ReceiverCounters position;
  AssemblerCounters assembler;
  std::uint64_t wrong_size = 0;           // datagrams neither 1206 nor 512 bytes long
  std::uint64_t position_packets = 0;
  std::uint64_t position_malformed = 0;
  std::uint64_t time_steps = 0;
  std::uint64_t time_clamped = 0;
  std::uint64_t time_steps_back = 0;  // the sensor's clock set back by over 0.5 s (SensorClock::steps_back)
  TimeSource time_source = TimeSource::none;
  std::int64_t last_packet_ns = 0;        // receive time of the newest data packet
  // The packets' times (last firing of each) against their host receive
  // times: the offset that puts revolutions on the reference clock.
  ClockRelationState reference;
};

class VelodyneDriver final : public Task {
 public:
  struct Created;
  // Takes the decoder; opens the sockets and allocates every image.
  static Created create(PacketDecoder decoder, const DriverOptions& options);
  VelodyneDriver(const VelodyneDriver&) = delete;
  VelodyneDriver& operator=(const VelodyneDriver&) = delete;

  void run(const TaskTick& tick) override;
  // How long the task can rest after a run: until shortly before the
  // revolution in progress is predicted to end (from the newest packet's
  // receive time, its azimuth and the rotation rate), at most
  // options().max_rest_ns; once the stream has been quiet that long, the
  // whole of it (no revolution can end without packets).
  Nanos rest() noexcept override;
  // The data socket, and whether the coming sleep ends when a packet
  // arrives: from options().watch_before_end_ns before the revolution's
  // predicted end until it is complete.
  int wake_fd() const noexcept override;
  bool watching() noexcept override;

  // Reader i of the revolutions (i < options().revolution_readers), one per thread.
  Broadcast<RangeImage>::Reader& revolutions(std::size_t reader = 0) noexcept { return revolutions_.reader(reader); }
  RangeImageShape revolution_shape() const noexcept { return shape_; }
  // Signalled after each revolution is published (an event-driven obstacle
  // task waits on it). Before the scheduler starts.
  void set_revolution_event(TaskEvent* event) noexcept { sink_.event = event; }
  Mailbox<PositionSnapshot>& positions() noexcept { return positions_; }
  DriverCounters counters() const noexcept;
  const DriverOptions& options() const noexcept { return options_; }
  udp::Endpoint data_endpoint() const noexcept { return data_->local(); }
  std::optional<udp::Endpoint> position_endpoint() const noexcept;
  const PacketDecoder& decoder() const noexcept { return decoder_; }

 private:
  static constexpr Nanos kNoPrediction = INT64_MIN;
  // Time from `now` to the revolution's predicted end (negative once past
  // it); kNoPrediction before the stream has a rate and a cut.
  Nanos to_predicted_end(Nanos now) const noexcept;
  VelodyneDriver(PacketDecoder decoder, const DriverOptions& options, RangeImageShape shape);
  void handle_position(std::span<const std::uint8_t> payload, std::int64_t receive_ns) noexcept;
  void publish_counters() noexcept;
  void publish_progress(Nanos started) noexcept;

  DriverOptions options_;
  PacketDecoder decoder_;
  std::optional<RevolutionAssembler> assembler_;
  // Publishes each revolution with its completing packet's receive time.
  struct Sink final : RevolutionSink {
    explicit Sink(Broadcast<RangeImage>& m) noexcept : mailbox(m) {}
    RangeImage& next_image() noexcept override { return mailbox.write_slot(); }
    RangeImage& restart_image(RangeImage&) noexcept override { return mailbox.refill(); }
    void complete(RangeImage& image) noexcept override;
    Broadcast<RangeImage>& mailbox;
    const RevolutionAssembler* assembler = nullptr;
    std::uint32_t offset_generation = 0;  // the generation whose image has its clock offset (0: none)
    TaskEvent* event = nullptr;
    const ClockRelation* reference = nullptr;
    std::int64_t receive_ns = 0;  // of the packet being added
    Nanos run_started = 0;        // the driver's current run (scheduler clock)
  };

  RangeImageShape shape_;
  Broadcast<RangeImage> revolutions_;
  Sink sink_;
  Mailbox<PositionSnapshot> positions_;
  SensorClock clock_;
  ClockRelation reference_;
  std::unique_ptr<udp::UdpReceiver> data_;
  std::unique_ptr<udp::UdpReceiver> position_;
  DriverCounters local_;  // the task thread's own
  std::uint64_t progress_word_ = 0;  // the last one stored (DriverOptions::progress_signals)
  int next_signal_columns_ = 0;      // signal the readers once this many columns are final

  StatusBoard<DriverCounters> shared_;  // the published copy
};

struct VelodyneDriver::Created {
  std::unique_ptr<VelodyneDriver> driver;
  std::string error;
};

}  // namespace trailnav::velodyne
