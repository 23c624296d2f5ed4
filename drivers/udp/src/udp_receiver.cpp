#include "trailnav/drivers/udp/udp_receiver.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cstring>
#include <ctime>

#include "trailnav/runtime/host_clock.hpp"

namespace trailnav::udp {
namespace {

std::string errno_text(const char* what) { return std::string(what) + ": " + std::strerror(errno); }

// Room for an SO_TIMESTAMPNS and an SO_RXQ_OVFL control message.
constexpr std::size_t kControlBytes = CMSG_SPACE(sizeof(timespec)) + CMSG_SPACE(sizeof(std::uint32_t)) + 64;

}  // namespace

std::optional<Endpoint> parse_endpoint(std::string_view text, std::string& error) {
  const std::size_t colon = text.rfind(':');
  if (colon == std::string_view::npos) {
    error = "'" + std::string(text) + "' is not ADDRESS:PORT";
    return std::nullopt;
  }
  Endpoint e;
  const std::string address(text.substr(0, colon));
  if (!address.empty()) {
    in_addr a{};
    if (inet_pton(AF_INET, address.c_str(), &a) != 1) {
      error = "'" + address + "' is not an IPv4 address";
      return std::nullopt;
    }
    e.ip = ntohl(a.s_addr);
  }
  const std::string_view port = text.substr(colon + 1);
  unsigned value = 0;
  const auto [end, ec] = std::from_chars(port.data(), port.data() + port.size(), value);
  if (ec != std::errc{} || end != port.data() + port.size() || value > 65535) {
    error = "'" + std::string(port) + "' is not a port number (0..65535)";
    return std::nullopt;
  }
  e.port = static_cast<std::uint16_t>(value);
  return e;
}

std::string format_endpoint(const Endpoint& endpoint) {
  in_addr a{};
  a.s_addr = htonl(endpoint.ip);
  char text[INET_ADDRSTRLEN] = {};
  inet_ntop(AF_INET, &a, text, sizeof text);
  return std::string(text) + ":" + std::to_string(endpoint.port);
}

bool is_loopback(std::uint32_t ip) noexcept { return (ip >> 24) == 127; }

struct UdpReceiver::Buffers {
  Buffers(int batch, int datagram_bytes)
      : data(static_cast<std::size_t>(batch) * static_cast<std::size_t>(datagram_bytes)),
        control(static_cast<std::size_t>(batch) * kControlBytes),
        iov(static_cast<std::size_t>(batch)),
        names(static_cast<std::size_t>(batch)),
        messages(static_cast<std::size_t>(batch)) {}
  std::vector<std::uint8_t> data;
  std::vector<std::uint8_t> control;
  std::vector<iovec> iov;
  std::vector<sockaddr_in> names;
  std::vector<mmsghdr> messages;
};

UdpReceiver::Opened UdpReceiver::open(const ReceiverOptions& options) {
  Opened result;
  if (options.batch < 1 || options.batch > 1024) {
    result.error = "batch must be 1..1024, not " + std::to_string(options.batch);
    return result;
  }
  if (options.max_datagram_bytes < 64 || options.max_datagram_bytes > 65536) {
    result.error = "max_datagram_bytes must be 64..65536, not " + std::to_string(options.max_datagram_bytes);
    return result;
  }
  std::unique_ptr<UdpReceiver> r(new UdpReceiver());
  r->options_ = options;
  const std::string where = format_endpoint(options.bind);
  r->fd_ = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  if (r->fd_ < 0) {
    result.error = errno_text("socket");
    return result;
  }
  const int one = 1;
  if (options.reuse_port) setsockopt(r->fd_, SOL_SOCKET, SO_REUSEPORT, &one, sizeof one);
  if (options.receive_buffer_bytes > 0) {
    // SO_RCVBUFFORCE passes the rmem_max limit when we have CAP_NET_ADMIN.
    const int size = options.receive_buffer_bytes;
    if (setsockopt(r->fd_, SOL_SOCKET, SO_RCVBUFFORCE, &size, sizeof size) != 0) {
      setsockopt(r->fd_, SOL_SOCKET, SO_RCVBUF, &size, sizeof size);
    }
  }
  int granted = 0;
  socklen_t length = sizeof granted;
  getsockopt(r->fd_, SOL_SOCKET, SO_RCVBUF, &granted, &length);
  r->granted_buffer_ = granted / 2;  // the kernel reports double, counting its bookkeeping
  if (options.kernel_timestamps && setsockopt(r->fd_, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof one) != 0) {
    result.error = errno_text("SO_TIMESTAMPNS");
    return result;
  }
  setsockopt(r->fd_, SOL_SOCKET, SO_RXQ_OVFL, &one, sizeof one);

  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(options.bind.port);
  address.sin_addr.s_addr = htonl(options.bind.ip);
  if (bind(r->fd_, reinterpret_cast<const sockaddr*>(&address), sizeof address) != 0) {
    result.error = "cannot listen on " + where + ": " + std::strerror(errno);
    return result;
  }
  sockaddr_in bound{};
  socklen_t bound_length = sizeof bound;
  getsockname(r->fd_, reinterpret_cast<sockaddr*>(&bound), &bound_length);
  r->local_ = {ntohl(bound.sin_addr.s_addr), ntohs(bound.sin_port)};

  r->buffers_ = std::make_unique<Buffers>(options.batch, options.max_datagram_bytes);
  r->out_.resize(static_cast<std::size_t>(options.batch));
  Buffers& b = *r->buffers_;
  for (std::size_t i = 0; i < static_cast<std::size_t>(options.batch); ++i) {
    b.iov[i].iov_base = b.data.data() + i * static_cast<std::size_t>(options.max_datagram_bytes);
    b.iov[i].iov_len = static_cast<std::size_t>(options.max_datagram_bytes);
  }
  result.receiver = std::move(r);
  return result;
}

UdpReceiver::~UdpReceiver() {
  if (fd_ >= 0) close(fd_);
}

std::span<const Datagram> UdpReceiver::receive(int timeout_ms) noexcept {
  if (timeout_ms > 0) {
    pollfd p{fd_, POLLIN, 0};
    if (poll(&p, 1, timeout_ms) <= 0) return {};
  }
  Buffers& b = *buffers_;
  const auto batch = static_cast<std::size_t>(options_.batch);
  for (std::size_t i = 0; i < batch; ++i) {
    msghdr& h = b.messages[i].msg_hdr;
    h.msg_name = &b.names[i];
    h.msg_namelen = sizeof(sockaddr_in);
    h.msg_iov = &b.iov[i];
    h.msg_iovlen = 1;
    h.msg_control = b.control.data() + i * kControlBytes;
    h.msg_controllen = kControlBytes;
    h.msg_flags = 0;
    b.messages[i].msg_len = 0;
  }
  const int n = recvmmsg(fd_, b.messages.data(), static_cast<unsigned>(batch), MSG_DONTWAIT, nullptr);
  if (n < 0) {
    if (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) ++counters_.errors;
    return {};
  }
  ++counters_.calls;
  std::int64_t now = 0;  // read only for datagrams without a kernel timestamp
  const std::int64_t step = host_clock_step_ns();
  std::size_t kept = 0;
  for (std::size_t i = 0; i < static_cast<std::size_t>(n); ++i) {
    const msghdr& h = b.messages[i].msg_hdr;
    std::int64_t stamp = 0;
    for (cmsghdr* c = CMSG_FIRSTHDR(&h); c != nullptr; c = CMSG_NXTHDR(const_cast<msghdr*>(&h), c)) {
      if (c->cmsg_level != SOL_SOCKET) continue;
      if (c->cmsg_type == SO_TIMESTAMPNS) {
        timespec ts{};
        std::memcpy(&ts, CMSG_DATA(c), sizeof ts);
        // The kernel's CLOCK_REALTIME, in host time (runtime/host_clock.hpp).
        stamp = static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec - step;
      } else if (c->cmsg_type == SO_RXQ_OVFL) {
        std::uint32_t overflow = 0;
        std::memcpy(&overflow, CMSG_DATA(c), sizeof overflow);
        counters_.kernel_drops += overflow - last_overflow_;  // the kernel's count is cumulative
        last_overflow_ = overflow;
      }
    }
    if (stamp == 0) {
      if (now == 0) now = host_now_ns();
      stamp = now;
    }
    if ((h.msg_flags & MSG_TRUNC) != 0) {
      ++counters_.truncated;
      continue;
    }
    const sockaddr_in& from = b.names[i];
    const Endpoint source{ntohl(from.sin_addr.s_addr), ntohs(from.sin_port)};
    if ((options_.source_ip && *options_.source_ip != source.ip) ||
        (options_.source_port && *options_.source_port != source.port)) {
      ++counters_.foreign;
      continue;
    }
    const std::size_t length = b.messages[i].msg_len;
    ++counters_.datagrams;
    counters_.bytes += length;
    out_[kept++] = Datagram{{static_cast<const std::uint8_t*>(b.iov[i].iov_base), length}, stamp, source};
  }
  return {out_.data(), kept};
}

}  // namespace trailnav::udp
