#include "trailnav/drivers/link/byte_link.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/uio.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <ctime>

#include "trailnav/runtime/host_clock.hpp"

namespace trailnav::link {
namespace {

speed_t baud_constant(int baud) noexcept {
  switch (baud) {
    case 50: return B50;
    case 75: return B75;
    case 110: return B110;
    case 134: return B134;
    case 150: return B150;
    case 200: return B200;
    case 300: return B300;
    case 600: return B600;
    case 1200: return B1200;
    case 1800: return B1800;
    case 2400: return B2400;
    case 4800: return B4800;
    case 9600: return B9600;
    case 19200: return B19200;
    case 38400: return B38400;
    case 57600: return B57600;
    case 115200: return B115200;
    case 230400: return B230400;
    case 460800: return B460800;
    case 500000: return B500000;
    case 576000: return B576000;
    case 921600: return B921600;
    case 1000000: return B1000000;
    case 1152000: return B1152000;
    case 1500000: return B1500000;
    case 2000000: return B2000000;
    case 2500000: return B2500000;
    case 3000000: return B3000000;
    case 3500000: return B3500000;
    case 4000000: return B4000000;
  }
  return B0;
}

}  // namespace

const char* link_kind_name(LinkKind kind) noexcept {
  switch (kind) {
    case LinkKind::serial: return "serial";
    case LinkKind::udp: return "udp";
    case LinkKind::tcp: return "tcp";
  }
  return "unknown";
}

const char* link_state_name(LinkState state) noexcept {
  switch (state) {
    case LinkState::closed: return "closed";
    case LinkState::connecting: return "connecting";
    case LinkState::open: return "open";
  }
  return "unknown";
}

bool supported_baud(int baud) noexcept { return baud_constant(baud) != B0; }

std::optional<LinkOptions> parse_link(std::string_view text, std::string& error) {
  LinkOptions o;
  const std::size_t colon = text.find(':');
  if (colon == std::string_view::npos) {
    error = "'" + std::string(text) + "' is not serial:DEVICE@BAUD, udp:ADDRESS:PORT or tcp:ADDRESS:PORT";
    return std::nullopt;
  }
  const std::string_view kind = text.substr(0, colon);
  const std::string_view rest = text.substr(colon + 1);
  if (kind == "serial") {
    o.kind = LinkKind::serial;
    const std::size_t at = rest.rfind('@');
    o.device = std::string(rest.substr(0, at));
    if (at != std::string_view::npos) {
      const std::string_view b = rest.substr(at + 1);
      int baud = 0;
      const auto [end, ec] = std::from_chars(b.data(), b.data() + b.size(), baud);
      if (ec != std::errc{} || end != b.data() + b.size() || !supported_baud(baud)) {
        error = "baud rate '" + std::string(b) + "' is not one the serial driver supports (4800, 9600, ..., 115200, ..., 4000000)";
        return std::nullopt;
      }
      o.baud = baud;
    }
    if (o.device.empty()) {
      error = "serial link without a device path";
      return std::nullopt;
    }
    return o;
  }
  if (kind == "udp" || kind == "tcp") {
    o.kind = kind == "udp" ? LinkKind::udp : LinkKind::tcp;
    auto e = udp::parse_endpoint(rest, error);
    if (!e) return std::nullopt;
    if (o.kind == LinkKind::tcp && (e->ip == 0 || e->port == 0)) {
      error = "tcp link needs the server's address and port, not '" + std::string(rest) + "'";
      return std::nullopt;
    }
    o.endpoint = *e;
    return o;
  }
  error = "link kind '" + std::string(kind) + "' is not serial, udp or tcp";
  return std::nullopt;
}

std::string format_link(const LinkOptions& o) {
  switch (o.kind) {
    case LinkKind::serial: return "serial:" + o.device + "@" + std::to_string(o.baud);
    case LinkKind::udp: return "udp:" + udp::format_endpoint(o.endpoint);
    case LinkKind::tcp: return "tcp:" + udp::format_endpoint(o.endpoint);
  }
  return "?";
}

ByteLink::Created ByteLink::create(const LinkOptions& options) {
  Created r;
  if (options.kind == LinkKind::serial && !supported_baud(options.baud)) {
    r.error = "serial " + options.device + ": baud rate " + std::to_string(options.baud) + " is not supported";
    return r;
  }
  if (options.kind == LinkKind::serial && options.device.empty()) {
    r.error = "serial link without a device path";
    return r;
  }
  if (!(options.silence_timeout >= 0.0) || !(options.backoff > 0.0) || !(options.max_backoff >= options.backoff)) {
    r.error = format_link(options) + ": silence_timeout must be >= 0 and 0 < backoff <= max_backoff";
    return r;
  }
  if (options.buffer_bytes < 64 || options.buffer_bytes > (1u << 20)) {
    r.error = format_link(options) + ": buffer_bytes must be within 64 .. 1048576";
    return r;
  }
  if (options.kind == LinkKind::udp && (options.max_datagram_bytes < 1 || options.max_datagram_bytes > options.buffer_bytes)) {
    r.error = format_link(options) + ": max_datagram_bytes must be within 1 .. buffer_bytes";
    return r;
  }
  r.link.reset(new ByteLink(options));
  return r;
}

ByteLink::ByteLink(const LinkOptions& options)
    : options_(options), current_backoff_(options.backoff), buffer_(new std::uint8_t[options.buffer_bytes]) {}

ByteLink::~ByteLink() { close(); }

void ByteLink::close() noexcept {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  state_ = LinkState::closed;
}

void ByteLink::set_error(const char* what, int err) noexcept {
  const char* target = options_.kind == LinkKind::serial ? options_.device.c_str() : nullptr;
  char endpoint[32] = "";
  if (!target) {
    const std::uint32_t ip = options_.endpoint.ip;
    std::snprintf(endpoint, sizeof endpoint, "%u.%u.%u.%u:%u", ip >> 24, (ip >> 16) & 255u, (ip >> 8) & 255u, ip & 255u,
                  options_.endpoint.port);
    target = endpoint;
  }
  if (err != 0) {
    std::snprintf(error_.data(), error_.size(), "%s %s: %s", what, target, strerrordesc_np(err));
  } else {
    std::snprintf(error_.data(), error_.size(), "%s %s", what, target);
  }
}

void ByteLink::fail(Nanos now, const char* what, int err) noexcept {
  set_error(what, err);
  if (state_ == LinkState::open) {
    ++counters_.closes;
  } else {
    ++counters_.open_failures;
  }
  close();
  next_attempt_ = now + seconds_to_nanos(current_backoff_);
  current_backoff_ = std::min(current_backoff_ * 2.0, options_.max_backoff);
}

void ByteLink::try_open(Nanos now) noexcept {
  opened_at_ = now;
  if (options_.kind == LinkKind::serial) {
    fd_ = ::open(options_.device.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (fd_ < 0) return fail(now, "open", errno);
    termios t{};
    if (tcgetattr(fd_, &t) != 0) return fail(now, "not a serial port (tcgetattr):", errno);
    cfmakeraw(&t);
    t.c_cflag |= CLOCAL | CREAD;
    t.c_cc[VMIN] = 0;
    t.c_cc[VTIME] = 0;
    const speed_t speed = baud_constant(options_.baud);
    if (cfsetispeed(&t, speed) != 0 || cfsetospeed(&t, speed) != 0 || tcsetattr(fd_, TCSANOW, &t) != 0) {
      return fail(now, "configure", errno);
    }
    state_ = LinkState::open;
  } else {
    const int type = options_.kind == LinkKind::udp ? SOCK_DGRAM : SOCK_STREAM;
    fd_ = ::socket(AF_INET, type | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd_ < 0) return fail(now, "socket for", errno);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(options_.endpoint.ip);
    a.sin_port = htons(options_.endpoint.port);
    if (options_.kind == LinkKind::udp) {
      const int one = 1;
      setsockopt(fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
      // The kernel stamps each datagram as it arrives, so a task that reads
      // late (a busy core, a stall) still learns when its bytes came.
      if (setsockopt(fd_, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof one) != 0) return fail(now, "SO_TIMESTAMPNS for", errno);
      if (::bind(fd_, reinterpret_cast<const sockaddr*>(&a), sizeof a) != 0) return fail(now, "bind", errno);
      sockaddr_in bound{};
      socklen_t len = sizeof bound;
      getsockname(fd_, reinterpret_cast<sockaddr*>(&bound), &len);
      bound_port_ = ntohs(bound.sin_port);
      state_ = LinkState::open;
    } else {
      const int one = 1;
      setsockopt(fd_, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
      if (::connect(fd_, reinterpret_cast<const sockaddr*>(&a), sizeof a) == 0) {
        state_ = LinkState::open;
      } else if (errno == EINPROGRESS) {
        state_ = LinkState::connecting;
        return;
      } else {
        return fail(now, "connect", errno);
      }
    }
  }
  ++counters_.opens;
  just_opened_ = true;
}

std::span<const std::uint8_t> ByteLink::poll(Nanos now) noexcept {
  just_opened_ = false;
  if (state_ == LinkState::closed) {
    if (now < next_attempt_) return {};
    try_open(now);
  }
  if (state_ == LinkState::connecting) {
    pollfd p{fd_, POLLOUT, 0};
    if (::poll(&p, 1, 0) == 0) {
      if (options_.silence_timeout > 0.0 && now - opened_at_ > seconds_to_nanos(options_.silence_timeout)) {
        fail(now, "connect timed out:", 0);
      }
      return {};
    }
    int err = 0;
    socklen_t len = sizeof err;
    getsockopt(fd_, SOL_SOCKET, SO_ERROR, &err, &len);
    if (err != 0) {
      fail(now, "connect", err);
      return {};
    }
    state_ = LinkState::open;
    opened_at_ = now;
    ++counters_.opens;
    just_opened_ = true;
  }
  if (state_ != LinkState::open) return {};
  std::size_t got = 0;
  std::int64_t kernel_receive_ns = 0;  // udp: the kernel's stamp of the newest datagram read
  while (got < options_.buffer_bytes) {
    ssize_t n = 0;
    if (options_.kind == LinkKind::udp) {
      // Datagrams are read whole: only while a largest one still fits. MSG_TRUNC
      // returns the real length, so a datagram that was cut is known and counted.
      const std::size_t limit = options_.max_datagram_bytes;
      if (options_.buffer_bytes - got < limit) break;
      iovec iov{buffer_.get() + got, limit};
      alignas(cmsghdr) std::array<std::uint8_t, CMSG_SPACE(sizeof(timespec))> control{};
      msghdr m{};
      m.msg_iov = &iov;
      m.msg_iovlen = 1;
      m.msg_control = control.data();
      m.msg_controllen = control.size();
      n = ::recvmsg(fd_, &m, MSG_TRUNC | MSG_DONTWAIT);
      if (n > 0 && static_cast<std::size_t>(n) > limit) {
        ++counters_.truncated;
        n = static_cast<ssize_t>(limit);
      }
      if (n >= 0) {
        // The newest datagram's arrival: no byte returned arrived later.
        for (cmsghdr* c = CMSG_FIRSTHDR(&m); c != nullptr; c = CMSG_NXTHDR(&m, c)) {
          if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SO_TIMESTAMPNS) {
            timespec ts{};
            std::memcpy(&ts, CMSG_DATA(c), sizeof ts);
            kernel_receive_ns = static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec - host_clock_step_ns();
          }
        }
      }
    } else if (options_.kind == LinkKind::serial) {
      // Only what the line discipline already holds. A read (or poll) of an
      // empty tty first waits for the kernel worker that moves bytes from the
      // driver into it (n_tty's flush of the port's buffer work); a CPU that
      // keeps that worker waiting kept this task in read() for seconds
      // (docs/imu.md, "Byte links"). FIONREAD does not wait, and on a hung-up
      // tty (the pseudo-terminal's master closed, a USB adapter unplugged) it
      // fails with EIO.
      int available = 0;
      if (::ioctl(fd_, FIONREAD, &available) != 0) {
        const int err = errno;
        if (err == EIO) {
          fail(now, "hung up:", 0);
        } else {
          ++counters_.read_errors;
          fail(now, "read", err);
        }
        break;
      }
      if (available <= 0) break;
      n = ::read(fd_, buffer_.get() + got,
                 std::min(options_.buffer_bytes - got, static_cast<std::size_t>(available)));
    } else {
      n = ::read(fd_, buffer_.get() + got, options_.buffer_bytes - got);
    }
    if (n > 0) {
      got += static_cast<std::size_t>(n);
      continue;
    }
    if (n == 0 && options_.kind == LinkKind::tcp) {
      fail(now, "connection closed by", 0);
      break;
    }
    if (n == 0 && options_.kind == LinkKind::serial) break;  // FIONREAD said more was there
    if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) {
      ++counters_.read_errors;
      fail(now, "read", errno);  // EIO: the pseudo-terminal's other end or the USB adapter went away
    }
    break;
  }
  if (got > 0) {
    counters_.bytes += got;
    last_byte_ = now;
    receive_ns_ = kernel_receive_ns != 0 ? kernel_receive_ns : host_now_ns();
    current_backoff_ = options_.backoff;
    return {buffer_.get(), got};
  }
  if (state_ == LinkState::open && options_.silence_timeout > 0.0 &&
      now - std::max(last_byte_, opened_at_) > seconds_to_nanos(options_.silence_timeout)) {
    ++counters_.silences;
    fail(now, "no bytes for the silence timeout from", 0);
  }
  return {};
}

bool ByteLink::write(std::span<const std::uint8_t> bytes) noexcept {
  if (state_ != LinkState::open || options_.kind == LinkKind::udp) return false;
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd_, bytes.data() + done, bytes.size() - done);
    if (n > 0) {
      done += static_cast<std::size_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    ++counters_.write_errors;
    set_error("write", errno);
    return false;
  }
  ++counters_.writes;
  return true;
}

}  // namespace trailnav::link
