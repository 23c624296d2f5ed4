#include "trailnav/drivers/gps/gps_driver.hpp"

#include <cmath>
#include <cstring>

namespace trailnav::gps {

const char* gps_health_name(GpsHealth h) noexcept {
  switch (h) {
    case GpsHealth::no_link: return "no_link";
    case GpsHealth::no_data: return "no_data";
    case GpsHealth::no_fix: return "no_fix";
    case GpsHealth::fix: return "fix";
  }
  return "unknown";
}

GpsDriver::Created GpsDriver::create(const GpsDriverOptions& options) {
  Created r;
  if (!(options.epoch_gap > 0.0) || !(options.fix_timeout > 0.0)) {
    r.error = options.name + ": epoch_gap and fix_timeout must be positive";
    return r;
  }
  auto made = link::ByteLink::create(options.link);
  if (!made.link) {
    r.error = options.name + ": " + made.error;
    return r;
  }
  r.driver.reset(new GpsDriver(options, std::move(made.link)));
  return r;
}

GpsDriver::GpsDriver(const GpsDriverOptions& options, std::unique_ptr<link::ByteLink> link)
    : options_(options), link_(std::move(link)) {}

void GpsDriver::publish(const GpsFix& fix, Nanos now) noexcept {
  GpsReading& slot = fixes_.write_slot();
  slot.receive_ns = last_receive_ns_;
  slot.fix = fix;
  fixes_.publish();
  ++local_.published;
  if (fix.has_fix()) last_fix_ = now;
}

void GpsDriver::run(const TaskTick& tick) {
  const Nanos now = tick.started;
  const auto bytes = link_->poll(now);
  if (!bytes.empty()) {
    last_receive_ns_ = link_->receive_ns();
    framer_.feed(bytes, [&](std::string_view line) {
      if (assembler_.add_line(line, completed_)) publish(completed_, now);
      epoch_open_ = true;
    });
  } else if (epoch_open_ && now - link_->last_byte() > seconds_to_nanos(options_.epoch_gap)) {
    // The burst is over: the epoch is complete.
    if (assembler_.flush(completed_)) publish(completed_, now);
    epoch_open_ = false;
  }
  publish_status(now);
}

void GpsDriver::publish_status(Nanos now) noexcept {
  local_.link_state = link_->state();
  local_.link = link_->counters();
  local_.udp_port = link_->bound_port();
  local_.gps = assembler_.counters();
  local_.overlong_lines = framer_.overlong();
  local_.last_fix_age = last_fix_ < 0 ? -1.0 : nanos_to_seconds(now - last_fix_);
  std::memcpy(local_.last_link_error.data(), link_->last_error(), local_.last_link_error.size());
  local_.last_link_error.back() = '\0';
  if (link_->state() != link::LinkState::open) {
    local_.health = GpsHealth::no_link;
  } else if (local_.gps.lines == 0 ||
             now - link_->last_byte() > seconds_to_nanos(std::max(options_.fix_timeout, options_.link.silence_timeout))) {
    local_.health = GpsHealth::no_data;
  } else if (last_fix_ >= 0 && now - last_fix_ <= seconds_to_nanos(options_.fix_timeout)) {
    local_.health = GpsHealth::fix;
  } else {
    local_.health = GpsHealth::no_fix;
  }
  shared_.post(local_);
}

GpsDriverStatus GpsDriver::status() const noexcept { return shared_.read(); }

}  // namespace trailnav::gps
