#include "trailnav/drivers/imu/imu_driver.hpp"

#include <cstring>

namespace trailnav::imu {

const char* imu_health_name(ImuHealth h) noexcept {
  switch (h) {
    case ImuHealth::no_link: return "no_link";
    case ImuHealth::no_data: return "no_data";
    case ImuHealth::device_error: return "device_error";
    case ImuHealth::ok: return "ok";
  }
  return "unknown";
}

ImuDriver::Created ImuDriver::create(const ImuDriverOptions& options) {
  Created r;
  if (std::string e = check_attitude_options(options.attitude); !e.empty()) {
    r.error = options.name + ": attitude: " + e;
    return r;
  }
  if (!(options.data_timeout > 0.0)) {
    r.error = options.name + ": data_timeout must be positive";
    return r;
  }
  if (options.xsens_output_count > options.xsens_outputs.size()) {
    r.error = options.name + ": at most 8 Xsens output items";
    return r;
  }
  auto made = link::ByteLink::create(options.link);
  if (!made.link) {
    r.error = options.name + ": " + made.error;
    return r;
  }
  r.driver.reset(new ImuDriver(options, std::move(made.link)));
  return r;
}

ImuDriver::ImuDriver(const ImuDriverOptions& options, std::unique_ptr<link::ByteLink> link)
    : options_(options), link_(std::move(link)), decoder_(options.protocol), filter_(options.attitude) {}

void ImuDriver::start_device() noexcept {
  std::size_t n = encode_xbus(mid::kGoToConfig, {}, command_);
  link_->write({command_.data(), n});
  if (options_.xsens_output_count > 0) {
    std::array<std::uint8_t, 8 * 4 + 8> config{};
    n = encode_output_configuration({options_.xsens_outputs.data(), options_.xsens_output_count}, config);
    link_->write({config.data(), n});
  }
  n = encode_xbus(mid::kGoToMeasurement, {}, command_);
  link_->write({command_.data(), n});
}

void ImuDriver::on_sample(const ImuSample& s, Nanos now) noexcept {
  ImuReading& slot = latest_.write_slot();
  slot.sample = s;
  if (s.has(kSampleTimeFine)) {
    // 10 kHz ticks in 32 bits, unwrapped (wraps every 4.97 days). The
    // reading is stamped on the device's clock put on the host's (one time
    // base, docs/dds.md): bytes the kernel held back and handed over in a
    // burst keep the times they were measured at, not the time of the read.
    if (have_ticks_) device_ns_ += static_cast<std::int64_t>(static_cast<std::uint32_t>(s.sample_time_fine - last_ticks_)) * 100'000;
    have_ticks_ = true;
    last_ticks_ = s.sample_time_fine;
    device_clock_.add(device_ns_, s.time_ns);
    local_.device_clock = device_clock_.state();
    slot.sample.time_ns = device_clock_.to_reference(device_ns_);
  }
  slot.attitude = filter_.update(slot.sample);
  if (!queue_.try_push(slot)) ++local_.queue_drops;
  latest_.publish();
  last_sample_ = now;
}

void ImuDriver::run(const TaskTick& tick) {
  const Nanos now = tick.started;
  const auto bytes = link_->poll(now);
  if (link_->just_opened() && options_.protocol == ImuProtocol::xsens && options_.xsens_start) start_device();
  if (!bytes.empty()) {
    const std::uint64_t device_errors = decoder_.counters().device_errors;
    decoder_.feed(bytes, link_->receive_ns(), [&](const ImuSample& s) { on_sample(s, now); });
    if (decoder_.counters().device_errors != device_errors) last_device_error_ = now;
  }
  publish_status(now);
}

void ImuDriver::publish_status(Nanos now) noexcept {
  local_.link_state = link_->state();
  local_.link = link_->counters();
  local_.udp_port = link_->bound_port();
  local_.stream = decoder_.counters();
  local_.attitude_counters = filter_.counters();
  local_.attitude = filter_.attitude();
  std::memcpy(local_.last_link_error.data(), link_->last_error(), local_.last_link_error.size());
  local_.last_link_error.back() = '\0';
  const Nanos timeout = seconds_to_nanos(options_.data_timeout);
  if (link_->state() != link::LinkState::open) {
    local_.health = ImuHealth::no_link;
  } else if (last_sample_ < 0 || now - last_sample_ > timeout) {
    local_.health = ImuHealth::no_data;
  } else if (last_device_error_ >= 0 && now - last_device_error_ <= timeout) {
    local_.health = ImuHealth::device_error;
  } else {
    local_.health = ImuHealth::ok;
  }
  shared_.post(local_);
}

ImuDriverStatus ImuDriver::status() const noexcept { return shared_.read(); }

}  // namespace trailnav::imu
