#include "trailnav/drivers/udp/udp_sender.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace trailnav::udp {

UdpSender::Opened UdpSender::open(const Endpoint& destination, int send_buffer_bytes) {
  Opened result;
  if (!is_loopback(destination.ip)) {
    result.error = "refusing to send to " + format_endpoint(destination) +
                   ": bench tools send only to loopback addresses (127.0.0.0/8)";
    return result;
  }
  if (destination.port == 0) {
    result.error = "destination " + format_endpoint(destination) + " has no port";
    return result;
  }
  std::unique_ptr<UdpSender> s(new UdpSender());
  s->destination_ = destination;
  s->fd_ = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (s->fd_ < 0) {
    result.error = std::string("socket: ") + std::strerror(errno);
    return result;
  }
  setsockopt(s->fd_, SOL_SOCKET, SO_SNDBUF, &send_buffer_bytes, sizeof send_buffer_bytes);
  // Not connected: a connected socket reports the ICMP "port unreachable"
  // of a destination nobody listens on as a failure of the next send.
  s->address_.sin_family = AF_INET;
  s->address_.sin_port = htons(destination.port);
  s->address_.sin_addr.s_addr = htonl(destination.ip);
  result.sender = std::move(s);
  return result;
}

UdpSender::~UdpSender() {
  if (fd_ >= 0) close(fd_);
}

bool UdpSender::send(std::span<const std::uint8_t> payload) noexcept {
  const ssize_t n = ::sendto(fd_, payload.data(), payload.size(), 0, reinterpret_cast<const sockaddr*>(&address_),
                             sizeof address_);
  if (n != static_cast<ssize_t>(payload.size())) {
    ++failures_;
    return false;
  }
  ++sent_;
  bytes_ += payload.size();
  return true;
}

}  // namespace trailnav::udp
