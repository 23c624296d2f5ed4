#include "trailnav/drivers/gpio/gpio_driver.hpp"

#include <gpiod.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <string_view>
#include <vector>

#include "trailnav/drivers/udp/udp_sender.hpp"
#include "trailnav/runtime/host_clock.hpp"

namespace trailnav::gpio {
namespace {

namespace fs = std::filesystem;

constexpr std::size_t kEventBatch = 16;

// "gpiochip0 [pinctrl-bcm2711], gpiochip1 [raspberrypi-exp-gpio]" or "none".
std::string list_chips() {
  std::vector<std::string> names;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator("/dev", ec)) {
    const std::string n = entry.path().filename().string();
    if (n.rfind("gpiochip", 0) == 0) names.push_back(n);
  }
  std::sort(names.begin(), names.end());
  std::string out;
  for (const std::string& n : names) {
    if (!out.empty()) out += ", ";
    out += n;
    if (gpiod_chip* c = gpiod_chip_open_by_name(n.c_str())) {
      out += std::string(" [") + gpiod_chip_label(c) + "]";
      gpiod_chip_close(c);
    }
  }
  return out.empty() ? "none (this machine has no /dev/gpiochip*; use transport tunnel on a bench)" : out;
}

// The chip's named lines, for an error message.
std::string list_lines(gpiod_chip* chip) {
  std::string out;
  int shown = 0;
  const unsigned n = gpiod_chip_num_lines(chip);
  for (unsigned i = 0; i < n; ++i) {
    gpiod_line* line = gpiod_chip_get_line(chip, i);
    const char* name = line != nullptr ? gpiod_line_name(line) : nullptr;
    if (name == nullptr || *name == '\0') continue;
    if (shown == 48) {
      out += ", ...";
      break;
    }
    if (!out.empty()) out += ", ";
    out += name;
    ++shown;
  }
  return out.empty() ? "none of its " + std::to_string(n) + " lines has a name" : "its named lines: " + out;
}

int bias_flags(LineBias b) noexcept {
  switch (b) {
    case LineBias::as_is: return 0;
    case LineBias::disable: return GPIOD_LINE_REQUEST_FLAG_BIAS_DISABLE;
    case LineBias::pull_up: return GPIOD_LINE_REQUEST_FLAG_BIAS_PULL_UP;
    case LineBias::pull_down: return GPIOD_LINE_REQUEST_FLAG_BIAS_PULL_DOWN;
  }
  return 0;
}

}  // namespace

const char* gpio_transport_name(GpioTransport t) noexcept { return t == GpioTransport::chip ? "chip" : "tunnel"; }

const char* line_bias_name(LineBias b) noexcept {
  switch (b) {
    case LineBias::as_is: return "as-is";
    case LineBias::disable: return "disable";
    case LineBias::pull_up: return "pull-up";
    case LineBias::pull_down: return "pull-down";
  }
  return "?";
}

const char* gpio_health_name(GpioHealth h) noexcept { return h == GpioHealth::ok ? "ok" : "failed"; }

GpioDriver::GpioDriver(const GpioDriverOptions& options)
    : options_(options), debouncer_(options.estop_release_debounce) {}

GpioDriver::~GpioDriver() {
  // Releasing the lines returns the outputs to the chip; closing releases all.
  if (chip_ != nullptr) gpiod_chip_close(chip_);
}

GpioDriver::Created GpioDriver::create(const GpioDriverOptions& options) {
  Created r;
  const std::string who = options.name + ": ";
  if (!(options.estop_release_debounce >= 0.0 && options.estop_release_debounce <= 10.0)) {
    r.error = who + "estop_release_debounce must be between 0 and 10 s";
    return r;
  }
  if (!options.heartbeat_line.empty() && !(options.heartbeat_period >= 0.001 && options.heartbeat_period <= 60.0)) {
    r.error = who + "heartbeat_period must be between 0.001 and 60 s";
    return r;
  }
  std::vector<std::string_view> names;
  for (const std::string* n : {&options.estop_line, &options.heartbeat_line, &options.status_line}) {
    if (n->empty()) continue;
    if (!valid_line_name(*n)) {
      r.error = who + "line name '" + *n + "' must be 1 to 31 printable characters without spaces";
      return r;
    }
    if (std::find(names.begin(), names.end(), *n) != names.end()) {
      r.error = who + "line '" + *n + "' is configured for two functions";
      return r;
    }
    names.push_back(*n);
  }
  std::unique_ptr<GpioDriver> d(new GpioDriver(options));

  if (options.transport == GpioTransport::tunnel) {
    udp::ReceiverOptions u;
    u.bind = options.tunnel;
    u.batch = 16;
    u.max_datagram_bytes = 64;  // the receiver's smallest; longer than any line level
    auto opened = udp::UdpReceiver::open(u);
    if (!opened.receiver) {
      r.error = who + "GPIO tunnel " + udp::format_endpoint(options.tunnel) + ": " + opened.error;
      return r;
    }
    d->tunnel_ = std::move(opened.receiver);
    d->wake_fd_ = d->tunnel_->fd();
    if (options.tunnel_outputs) {
      auto sender = udp::UdpSender::open(*options.tunnel_outputs, 1 << 16);
      if (!sender.sender) {
        r.error = who + "GPIO output mirror " + udp::format_endpoint(*options.tunnel_outputs) + ": " + sender.error;
        return r;
      }
      d->mirror_ = std::move(sender.sender);
    }
    r.driver = std::move(d);
    return r;
  }

  d->chip_ = gpiod_chip_open_lookup(options.chip.c_str());
  if (d->chip_ == nullptr) {
    const int err = errno;
    r.error = who + "GPIO chip '" + options.chip + "' not found (" + std::strerror(err) + "); chips here: " + list_chips();
    return r;
  }
  const std::string chip_text =
      std::string("GPIO chip '") + options.chip + "' (" + gpiod_chip_name(d->chip_) + " [" + gpiod_chip_label(d->chip_) + "])";
  auto find = [&](const std::string& name, gpiod_line*& line) {
    if (name.empty()) return true;
    line = gpiod_chip_find_line(d->chip_, name.c_str());
    if (line == nullptr) {
      r.error = who + chip_text + " has no line named '" + name + "'; " + list_lines(d->chip_);
      return false;
    }
    return true;
  };
  if (!find(options.estop_line, d->estop_line_) || !find(options.heartbeat_line, d->heartbeat_line_) ||
      !find(options.status_line, d->status_line_)) {
    return r;
  }
  auto request_failed = [&](const std::string& name, const char* as) {
    const int err = errno;
    r.error = who + "cannot request line '" + name + "' of " + chip_text + " as " + as + ": " + std::strerror(err) +
              (err == EBUSY ? " (another program holds it; see gpioinfo)" : "");
  };
  if (d->estop_line_ != nullptr) {
    const int flags = (options.estop_active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0) | bias_flags(options.estop_bias);
    if (gpiod_line_request_both_edges_events_flags(d->estop_line_, options.consumer.c_str(), flags) != 0) {
      request_failed(options.estop_line, "an edge-event input");
      return r;
    }
    const int level = gpiod_line_get_value(d->estop_line_);
    if (level < 0) {
      request_failed(options.estop_line, "a readable input");
      return r;
    }
  }
  const int out_flags = options.outputs_active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
  for (auto [line, name] : {std::pair{d->heartbeat_line_, &options.heartbeat_line},
                            std::pair{d->status_line_, &options.status_line}}) {
    if (line != nullptr && gpiod_line_request_output_flags(line, options.consumer.c_str(), out_flags, 0) != 0) {
      request_failed(*name, "an output");
      return r;
    }
  }
  if (d->estop_line_ != nullptr) d->wake_fd_ = gpiod_line_event_get_fd(d->estop_line_);
  r.driver = std::move(d);
  return r;
}

udp::Endpoint GpioDriver::tunnel_endpoint() const noexcept { return tunnel_ ? tunnel_->local() : udp::Endpoint{}; }

void GpioDriver::fail(const char* what, int err) noexcept {
  local_.health = GpioHealth::failed;
  std::snprintf(local_.last_error.data(), local_.last_error.size(), "%s: %s on %s: %s", options_.name.c_str(), what,
                options_.chip.c_str(), std::strerror(err));
}

void GpioDriver::read_chip(Nanos now) noexcept {
  if (estop_line_ == nullptr || local_.health == GpioHealth::failed) return;
  const timespec zero{0, 0};
  const int ready = gpiod_line_event_wait(estop_line_, &zero);
  if (ready < 0) {
    ++local_.read_errors;
    fail("waiting for e-stop events", errno);
    debouncer_.lost();
    return;
  }
  if (ready > 0) {
    std::array<gpiod_line_event, kEventBatch> events{};
    const int n = gpiod_line_event_read_multiple(estop_line_, events.data(), static_cast<unsigned>(events.size()));
    if (n < 0) {
      ++local_.read_errors;
      fail("reading e-stop events", errno);
      debouncer_.lost();
      return;
    }
    if (n > 0) {
      local_.edges += static_cast<std::uint64_t>(n);
      // An edge means the line was active at some moment: engage at the
      // first edge's time (kernel monotonic stamp when it is plausible).
      const Nanos t = static_cast<Nanos>(events[0].ts.tv_sec) * kNanosPerSecond + events[0].ts.tv_nsec;
      debouncer_.input(true, t <= now && now - t < kNanosPerSecond ? t : now);
    }
  }
  // A released stop with no edge since is still released: no level read
  // needed. Otherwise the level now decides when the release may come.
  if (ready == 0 && debouncer_.state() == EstopState::released) return;
  const int level = gpiod_line_get_value(estop_line_);
  if (level < 0) {
    ++local_.read_errors;
    fail("reading the e-stop level", errno);
    debouncer_.lost();
    return;
  }
  debouncer_.input(level == 1, now);
}

void GpioDriver::read_tunnel(Nanos now) noexcept {
  for (int round = 0; round < 8; ++round) {
    const auto batch = tunnel_->receive();
    for (const udp::Datagram& d : batch) {
      LineLevel level;
      if (!decode_tunnel(d.payload, level)) {
        ++local_.malformed;
        continue;
      }
      if (level.line() != options_.estop_line) {
        ++local_.unknown_lines;
        continue;
      }
      ++local_.tunnel_levels;
      debouncer_.input(level.value, now);
    }
    if (batch.size() < 16) break;
  }
}

void GpioDriver::set_output(gpiod_line* line, const std::string& name, bool value) noexcept {
  if (line != nullptr && gpiod_line_set_value(line, value ? 1 : 0) != 0) {
    ++local_.write_errors;
    fail("writing an output line", errno);
  }
  if (mirror_ && !name.empty()) {
    const TunnelDatagram d = encode_tunnel(name, value, host_now_ns());
    if (!mirror_->send(d.view())) ++local_.write_errors;
  }
}

void GpioDriver::drive_outputs(Nanos now) noexcept {
  if (!options_.heartbeat_line.empty() && now >= next_toggle_) {
    local_.heartbeat = !local_.heartbeat;
    ++local_.heartbeat_toggles;
    set_output(heartbeat_line_, options_.heartbeat_line, local_.heartbeat);
    const Nanos period = seconds_to_nanos(options_.heartbeat_period);
    next_toggle_ = next_toggle_ < 0 || now - next_toggle_ > period ? now + period : next_toggle_ + period;
  }
  local_.ready = ready_.load(std::memory_order_relaxed);
  const bool status = local_.ready && !debouncer_.engaged() && local_.health == GpioHealth::ok;
  if (!options_.status_line.empty() && (status != local_.status_output || !status_written_)) {
    status_written_ = true;
    set_output(status_line_, options_.status_line, status);
  }
  local_.status_output = status;
}

Nanos GpioDriver::rest() noexcept {
  const Nanos most = seconds_to_nanos(options_.max_rest);
  if (most <= 0 || local_.health == GpioHealth::failed) return 0;
  Nanos until = last_run_ + most;
  if (!options_.heartbeat_line.empty() && next_toggle_ >= 0) until = std::min(until, next_toggle_);
  if (const Nanos release = debouncer_.release_due(); release >= 0) until = std::min(until, release);
  return std::max<Nanos>(0, until - last_run_);
}

void GpioDriver::run(const TaskTick& tick) {
  const Nanos now = tick.started;
  last_run_ = now;
  if (options_.transport == GpioTransport::tunnel) {
    read_tunnel(now);
  } else {
    read_chip(now);
  }
  const EstopState state = options_.estop_line.empty() ? EstopState::released : debouncer_.update(now);
  drive_outputs(now);
  if (!published_once_ || state != published_state_) {
    EstopReading& slot = estop_.write_slot();
    slot.state = state;
    slot.since = options_.estop_line.empty() ? now : debouncer_.since();
    slot.engagements = debouncer_.counters().engagements;
    estop_.publish();
    published_state_ = state;
    published_once_ = true;
  }
  local_.estop = state;
  local_.estop_counters = debouncer_.counters();
  shared_.post(local_);
}

}  // namespace trailnav::gpio
