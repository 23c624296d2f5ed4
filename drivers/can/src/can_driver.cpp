#include "trailnav/drivers/can/can_driver.hpp"

#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <ctime>

#include "trailnav/runtime/host_clock.hpp"

namespace trailnav::can {

const char* can_transport_name(CanTransport t) noexcept { return t == CanTransport::socketcan ? "socketcan" : "tunnel"; }

const char* can_health_name(CanHealth h) noexcept {
  switch (h) {
    case CanHealth::no_link: return "no_link";
    case CanHealth::no_data: return "no_data";
    case CanHealth::bus_error: return "bus_error";
    case CanHealth::ok: return "ok";
  }
  return "unknown";
}

CanDriver::Created CanDriver::create(const Dbc& dbc, const CanDriverOptions& options) {
  Created r;
  auto odo = WheelOdometry::create(dbc, options.odometry);
  if (!odo.odometry) {
    r.error = options.name + ": " + odo.error;
    return r;
  }
  if (!(options.backoff > 0.0) || !(options.max_backoff >= options.backoff) || !(options.data_timeout > 0.0) ||
      options.max_frames_per_run < 1) {
    r.error = options.name + ": backoff, max_backoff, data_timeout and max_frames_per_run must be positive";
    return r;
  }
  std::unique_ptr<CanDriver> d(new CanDriver(options, std::move(odo.odometry)));
  d->filter_count_ = d->odometry_->ids(d->filter_ids_.data(), d->filter_ids_.size());
  if (options.transport == CanTransport::tunnel) {
    udp::ReceiverOptions u;
    u.bind = options.tunnel;
    u.batch = 64;
    u.max_datagram_bytes = static_cast<int>(kTunnelHeader + 64);
    auto opened = udp::UdpReceiver::open(u);
    if (!opened.receiver) {
      r.error = options.name + ": CAN tunnel " + udp::format_endpoint(options.tunnel) + ": " + opened.error;
      return r;
    }
    d->tunnel_ = std::move(opened.receiver);
    d->local_.open = true;
    d->local_.opens = 1;
  } else if (options.interface.empty() || options.interface.size() >= IFNAMSIZ) {
    r.error = options.name + ": CAN interface name '" + options.interface + "' is empty or too long";
    return r;
  }
  r.driver = std::move(d);
  return r;
}

CanDriver::CanDriver(const CanDriverOptions& options, std::unique_ptr<WheelOdometry> odometry)
    : options_(options), odometry_(std::move(odometry)), current_backoff_(options.backoff) {}

CanDriver::~CanDriver() {
  if (fd_ >= 0) ::close(fd_);
}

udp::Endpoint CanDriver::tunnel_endpoint() const noexcept { return tunnel_ ? tunnel_->local() : udp::Endpoint{}; }

void CanDriver::fail(Nanos now, const char* what, int err) noexcept {
  if (err != 0) {
    std::snprintf(local_.last_error.data(), local_.last_error.size(), "%s %s: %s", what, options_.interface.c_str(),
                  strerrordesc_np(err));
  } else {
    std::snprintf(local_.last_error.data(), local_.last_error.size(), "%s %s", what, options_.interface.c_str());
  }
  // An open that failed half-way (a socket made, the interface missing) is
  // an open failure, not a close: only a socket that was open is closed.
  if (local_.open) {
    ++local_.closes;
  } else {
    ++local_.open_failures;
  }
  if (fd_ >= 0) {
    ::close(fd_);
    fd_ = -1;
  }
  local_.open = false;
  next_attempt_ = now + seconds_to_nanos(current_backoff_);
  current_backoff_ = std::min(current_backoff_ * 2.0, options_.max_backoff);
}

void CanDriver::open_socketcan(Nanos now) noexcept {
  fd_ = ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
  if (fd_ < 0) {
    const int err = errno;
    if (err == EAFNOSUPPORT) {
      std::snprintf(local_.last_error.data(), local_.last_error.size(),
                    "SocketCAN is not available on this machine (no CAN support in the kernel): "
                    "use transport tunnel for %s",
                    options_.interface.c_str());
      ++local_.open_failures;
      next_attempt_ = now + seconds_to_nanos(options_.max_backoff);
      return;
    }
    return fail(now, "socket for", err);
  }
  const unsigned index = if_nametoindex(options_.interface.c_str());
  if (index == 0) return fail(now, "no CAN interface", errno == ENODEV ? 0 : errno);
  // The kernel hands over only the odometry's frames, and every error class.
  std::array<can_filter, 4> filters{};
  for (std::size_t i = 0; i < filter_count_; ++i) {
    const bool eff = (filter_ids_[i] & kEffFlag) != 0;
    filters[i].can_id = filter_ids_[i];
    filters[i].can_mask = (eff ? CAN_EFF_MASK : CAN_SFF_MASK) | CAN_EFF_FLAG | CAN_RTR_FLAG;
  }
  const can_err_mask_t errors = CAN_ERR_MASK;
  const int one = 1;
  if (setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_FILTER, filters.data(),
                 static_cast<socklen_t>(filter_count_ * sizeof(can_filter))) != 0 ||
      setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &errors, sizeof errors) != 0) {
    return fail(now, "receive filters on", errno);
  }
  setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &one, sizeof one);  // fails harmlessly on old kernels
  setsockopt(fd_, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof one);
  setsockopt(fd_, SOL_SOCKET, SO_RXQ_OVFL, &one, sizeof one);
  sockaddr_can a{};
  a.can_family = AF_CAN;
  a.can_ifindex = static_cast<int>(index);
  if (::bind(fd_, reinterpret_cast<const sockaddr*>(&a), sizeof a) != 0) return fail(now, "bind", errno);
  local_.open = true;
  ++local_.opens;
  last_overflow_ = 0;
  local_.last_error[0] = '\0';
}

void CanDriver::read_socketcan(Nanos now) noexcept {
  // The kernel stamps on CLOCK_REALTIME; host time is that minus the steps
  // of the system clock (runtime/host_clock.hpp), read once per run.
  std::int64_t step = 0;
  bool have_step = false;
  for (int k = 0; k < options_.max_frames_per_run; ++k) {
    canfd_frame raw{};
    alignas(cmsghdr) std::array<std::uint8_t, CMSG_SPACE(sizeof(timespec)) + CMSG_SPACE(sizeof(std::uint32_t)) + 32> control{};
    iovec io{&raw, sizeof raw};
    msghdr m{};
    m.msg_iov = &io;
    m.msg_iovlen = 1;
    m.msg_control = control.data();
    m.msg_controllen = control.size();
    const ssize_t n = ::recvmsg(fd_, &m, MSG_DONTWAIT);
    if (n < 0) {
      if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) return;
      // ENETDOWN: `ip link set can0 down`; ENODEV: the adapter was unplugged.
      return fail(now, errno == ENETDOWN ? "interface down:" : "receive from", errno == ENETDOWN ? 0 : errno);
    }
    if (n != CAN_MTU && n != CANFD_MTU) {
      ++local_.malformed;
      continue;
    }
    Frame f;  // time_ns 0 until the kernel's timestamp is found
    for (cmsghdr* c = CMSG_FIRSTHDR(&m); c; c = CMSG_NXTHDR(&m, c)) {
      if (c->cmsg_level != SOL_SOCKET) continue;
      if (c->cmsg_type == SO_TIMESTAMPNS) {
        timespec ts{};
        std::memcpy(&ts, CMSG_DATA(c), sizeof ts);
        if (!have_step) {
          step = host_clock_step_ns();
          have_step = true;
        }
        f.time_ns = static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec - step;
      } else if (c->cmsg_type == SO_RXQ_OVFL) {
        std::uint32_t dropped = 0;
        std::memcpy(&dropped, CMSG_DATA(c), sizeof dropped);
        local_.kernel_drops += dropped - last_overflow_;
        last_overflow_ = dropped;
      }
    }
    if (f.time_ns == 0) f.time_ns = host_now_ns();  // no kernel timestamp: when it was read
    f.id = raw.can_id;
    f.fd = n == CANFD_MTU;
    f.fd_flags = f.fd ? static_cast<std::uint8_t>(raw.flags & 0x3) : 0;
    f.length = std::min<std::uint8_t>(raw.len, f.fd ? 64 : 8);
    std::memcpy(f.data.data(), raw.data, f.length);
    on_frame(f, now);
  }
}

void CanDriver::on_error_frame(const Frame& f, Nanos now) noexcept {
  ++local_.error_frames;
  const std::uint32_t cls = f.id & CAN_ERR_MASK;
  if (cls & CAN_ERR_TX_TIMEOUT) ++local_.tx_timeouts;
  if (cls & CAN_ERR_BUSOFF) {
    ++local_.bus_off;
    last_bus_error_ = now;
  }
  if (cls & CAN_ERR_RESTARTED) ++local_.restarted;
  if ((cls & CAN_ERR_CRTL) && f.length > 1) {
    const std::uint8_t c = f.data[1];
    if (c & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE)) {
      ++local_.error_passive;
      last_bus_error_ = now;
    }
    if (c & (CAN_ERR_CRTL_RX_WARNING | CAN_ERR_CRTL_TX_WARNING)) ++local_.error_warning;
  }
}

void CanDriver::on_frame(const Frame& f, Nanos now) noexcept {
  ++local_.frames;
  if (f.error()) return on_error_frame(f, now);
  if (!odometry_->on_frame(f)) return;
  last_reading_ = now;
  OdometryState& slot = latest_.write_slot();
  slot = odometry_->state();
  if (!queue_.try_push(slot)) ++local_.queue_drops;
  latest_.publish();
}

void CanDriver::run(const TaskTick& tick) {
  const Nanos now = tick.started;
  if (options_.transport == CanTransport::tunnel) {
    for (int b = 0; b * 64 < options_.max_frames_per_run; ++b) {
      const auto batch = tunnel_->receive();
      for (const udp::Datagram& d : batch) {
        Frame f;
        if (!decode_tunnel(d.payload, f)) {
          ++local_.malformed;
          continue;
        }
        if (!options_.tunnel_recorded_time) f.time_ns = d.receive_ns;  // as a bus would time it
        on_frame(f, now);
      }
      if (batch.size() < 64) break;
    }
    local_.kernel_drops = tunnel_->counters().kernel_drops;
  } else {
    if (fd_ < 0 && now >= next_attempt_) open_socketcan(now);
    if (fd_ >= 0 && local_.open) read_socketcan(now);
  }
  publish_status(now);
}

void CanDriver::publish_status(Nanos now) noexcept {
  local_.odometry_counters = odometry_->counters();
  local_.odometry = odometry_->state();
  if (!local_.open) {
    local_.health = CanHealth::no_link;
  } else if (last_bus_error_ >= 0 && now - last_bus_error_ <= seconds_to_nanos(options_.bus_error_hold)) {
    local_.health = CanHealth::bus_error;
  } else if (last_reading_ < 0 || now - last_reading_ > seconds_to_nanos(options_.data_timeout)) {
    local_.health = CanHealth::no_data;
  } else {
    local_.health = CanHealth::ok;
  }
  if (last_reading_ >= 0 && local_.open) current_backoff_ = options_.backoff;
  shared_.post(local_);
}

CanDriverStatus CanDriver::status() const noexcept { return shared_.read(); }

}  // namespace trailnav::can
