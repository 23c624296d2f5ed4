#include "trailnav/drivers/velodyne/driver.hpp"

#include <algorithm>
#include <cstring>

#include "trailnav/runtime/host_clock.hpp"

namespace trailnav::velodyne {

VelodyneDriver::Created VelodyneDriver::create(PacketDecoder decoder, const DriverOptions& options) {
  Created result;
  if (std::string error = RevolutionAssembler::check_options(options.assembler); !error.empty()) {
    result.error = options.name + ": " + error;
    return result;
  }
  if (options.revolution_readers < 1 || options.revolution_readers > 8) {
    result.error = options.name + ": revolution_readers must be 1 to 8";
    return result;
  }
  const RangeImageShape shape = RevolutionAssembler::shape_for(decoder.model(), options.assembler);
  std::unique_ptr<VelodyneDriver> d(new VelodyneDriver(std::move(decoder), options, shape));
  // The assembler refers to the decoder: built on the driver's own.
  d->assembler_.emplace(std::move(*RevolutionAssembler::create(d->decoder_, options.assembler).assembler));
  d->sink_.assembler = &*d->assembler_;

  auto data = udp::UdpReceiver::open(options.data);
  if (!data.receiver) {
    result.error = options.name + ": data packets: " + data.error;
    return result;
  }
  d->data_ = std::move(data.receiver);
  if (options.position) {
    auto position = udp::UdpReceiver::open(*options.position);
    if (!position.receiver) {
      result.error = options.name + ": position packets: " + position.error;
      return result;
    }
    d->position_ = std::move(position.receiver);
  }
  result.driver = std::move(d);
  return result;
}

VelodyneDriver::VelodyneDriver(PacketDecoder decoder, const DriverOptions& options, RangeImageShape shape)
    : options_(options),
      decoder_(std::move(decoder)),
      shape_(shape),
      revolutions_(static_cast<std::size_t>(std::max(1, options.revolution_readers)), shape),
      sink_(revolutions_),
      clock_(options.clock),
      reference_(options.reference) {
  sink_.reference = &reference_;
}

std::optional<udp::Endpoint> VelodyneDriver::position_endpoint() const noexcept {
  if (!position_) return std::nullopt;
  return position_->local();
}

void VelodyneDriver::Sink::complete(RangeImage& image) noexcept {
  image.completed_receive_ns = receive_ns;
  // A revolution followed while it arrived keeps the offset it was followed
  // with (publish_progress()).
  if (assembler == nullptr || assembler->generation() != offset_generation) {
    image.clock_offset_ns = reference != nullptr ? reference->offset_ns() : 0;
  }
  mailbox.publish();
  if (event != nullptr) event->signal(run_started);
}

void VelodyneDriver::handle_position(std::span<const std::uint8_t> payload, std::int64_t receive_ns) noexcept {
  PositionPacket packet;
  if (decode_position_packet(payload, packet) != PositionError::none) {
    ++local_.position_malformed;
    return;
  }
  ++local_.position_packets;
  clock_.on_position_packet(packet);
  PositionSnapshot& s = positions_.write_slot();
  s.receive_ns = receive_ns;
  s.timestamp_us = packet.timestamp_us;
  s.pps = packet.pps;
  s.time_source = clock_.source();
  s.nmea_length = static_cast<std::uint16_t>(std::min(packet.nmea.size(), s.nmea.size()));
  std::memcpy(s.nmea.data(), packet.nmea.data(), s.nmea_length);
  positions_.publish();
}

void VelodyneDriver::run(const TaskTick& tick) {
  sink_.run_started = tick.started;
  if (position_) {
    for (int b = 0; b < options_.max_batches_per_run; ++b) {
      const auto batch = position_->receive();
      for (const udp::Datagram& d : batch) handle_position(d.payload, d.receive_ns);
      if (batch.size() < static_cast<std::size_t>(position_->options().batch)) break;
    }
  }
  for (int b = 0; b < options_.max_batches_per_run; ++b) {
    const auto batch = data_->receive();
    for (const udp::Datagram& d : batch) {
      if (d.payload.size() == kPositionPacketSize) {
        handle_position(d.payload, d.receive_ns);
        continue;
      }
      if (d.payload.size() != kDataPacketSize) {
        ++local_.wrong_size;
        continue;
      }
      const std::int64_t t = clock_.resolve(read_u32(d.payload.data() + kTimestampOffset), d.receive_ns);
      sink_.receive_ns = d.receive_ns;
      assembler_->add_packet(d.payload, t, sink_);
      // The packet leaves the sensor after its last firing.
      reference_.add(assembler_->last_firing_ns(), d.receive_ns);
      local_.last_packet_ns = d.receive_ns;
    }
    if (batch.size() < static_cast<std::size_t>(data_->options().batch)) break;
  }
  publish_progress(tick.started);
  publish_counters();
}

void VelodyneDriver::publish_progress(Nanos started) noexcept {
  if (options_.progress_signals <= 0) return;
  const RevolutionAssembler::Filling f = assembler_->filling();
  if (f.image == nullptr || f.partial || f.final_columns <= 0) return;
  if (f.generation != sink_.offset_generation) {
    // A revolution begun: the clock offset it is read with, before the first
    // word that vouches for it.
    sink_.offset_generation = f.generation;
    revolutions_.write_slot().clock_offset_ns = reference_.offset_ns();
    next_signal_columns_ = 0;
  }
  const std::uint64_t word = revolution_progress(f.generation, f.final_columns);
  if (word == progress_word_) return;
  progress_word_ = word;
  revolutions_.progress(word);
  if (sink_.event != nullptr && f.final_columns >= next_signal_columns_) {
    if (next_signal_columns_ > 0) sink_.event->signal(started);
    // Every 1/progress_signals of a turn, and every 1/32 turn in the last
    // such part: what is left for the reader when the revolution completes
    // is then what arrived since its last wake-up, the lidar task reading
    // every period near the end (rest()).
    const int columns = f.image->columns();
    const int step = std::max(1, columns / options_.progress_signals);
    const int fine = std::max(1, std::min(step, columns / 32));
    next_signal_columns_ = f.final_columns < columns - step ? (f.final_columns / step + 1) * step
                                                           : (f.final_columns / fine + 1) * fine;
  }
}

Nanos VelodyneDriver::to_predicted_end(Nanos now) const noexcept {
  const std::int64_t newest = local_.last_packet_ns;
  const double left = assembler_->turn_to_cut();
  if (newest == 0 || left < 0.0 || !(assembler_->rpm() > 0.0)) return kNoPrediction;  // no stream yet
  // The packet that completes the revolution leaves the sensor after the
  // firing at the cut.
  const double to_cut_ns = left * 60e9 / assembler_->rpm();
  return newest + static_cast<Nanos>(to_cut_ns) - now;
}

Nanos VelodyneDriver::rest() noexcept {
  const Nanos most = options_.max_rest_ns;
  if (most <= 0) return 0;
  const Nanos now = host_now_ns();
  const Nanos to_end = to_predicted_end(now);
  if (to_end == kNoPrediction) return most;
  if (now - local_.last_packet_ns >= most) return most;  // the stream has stopped
  // Wake ahead of the predicted end by 2 ms and 5 % of the time to it (the
  // rate may change by a few per cent within a turn), then every period.
  const Nanos to_cut_from_newest = to_end + (now - local_.last_packet_ns);
  const Nanos ahead = 2 * kNanosPerMilli + static_cast<Nanos>(0.05 * static_cast<double>(to_cut_from_newest));
  return std::clamp<Nanos>(to_end - ahead, 0, most);
}

int VelodyneDriver::wake_fd() const noexcept { return options_.watch_before_end_ns > 0 ? data_->fd() : -1; }

bool VelodyneDriver::watching() noexcept {
  if (options_.watch_before_end_ns <= 0) return false;
  const Nanos now = host_now_ns();
  const Nanos to_end = to_predicted_end(now);
  if (to_end == kNoPrediction || now - local_.last_packet_ns >= options_.max_rest_ns) return false;
  // Past the predicted end and still not complete: watch on (the rate
  // slowed); the revolution's completion moves the prediction a turn on.
  return to_end <= options_.watch_before_end_ns;
}

void VelodyneDriver::publish_counters() noexcept {
  local_.data = data_->counters();
  if (position_) local_.position = position_->counters();
  local_.assembler = assembler_->counters();
  local_.time_source = clock_.source();
  local_.time_steps = clock_.steps();
  local_.time_clamped = clock_.clamped();
  local_.time_steps_back = clock_.steps_back();
  local_.reference = reference_.state();
  shared_.post(local_);
}

DriverCounters VelodyneDriver::counters() const noexcept { return shared_.read(); }

}  // namespace trailnav::velodyne
